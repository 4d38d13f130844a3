"""Long commands say what they are doing before their slow part, on a terminal.

No wall time is asserted (the machine is shared): the order is. A command's first line must
come before the heavy imports (numba, scipy.optimize, pydantic: seconds on a cold start),
as ``python -X importtime`` reports them on the same terminal. ``make demo`` says what each
install and compile step is doing before it starts.
"""

from __future__ import annotations

import re
import subprocess
import sys
from pathlib import Path

import numpy as np

from tests.support.paths import REPO
from tests.support.terminal import run_on_terminal

ENTRY = "import sys; from fresco_bridge.entry import main; sys.exit(main(sys.argv[1:]))"


def _first_import(text: str, modules: tuple[str, ...]) -> int:
    """Where the first of ``modules`` finished importing in ``-X importtime`` output."""
    hits = [m.start() for m in re.finditer(r"import time:[^\n]*\| +(\S+)", text)
            if m.group(1) in modules]
    assert hits, f"none of {modules} imported:\n{text[-2000:]}"
    return min(hits)


def _csv(path: Path) -> Path:
    t = np.arange(300) * 0.01
    cmd = 2.0 * np.sin(2.0 * np.pi * t)
    rows = [f"{a},{b},{b},{3.0 * b}" for a, b in zip(t.tolist(), cmd.tolist(), strict=True)]
    path.write_text("time,cmd_disp,meas_disp,meas_force\n" + "\n".join(rows) + "\n")
    return path


def test_diagnose_says_what_it_reads_before_the_numerics_load(tmp_path: Path) -> None:
    record = _csv(tmp_path / "r.csv")
    rc, out = run_on_terminal([sys.executable, "-X", "importtime", "-c", ENTRY, "diagnose",
                               str(record)], timeout=300)
    text = out.decode(errors="replace")
    assert rc == 0, text[-3000:]
    status = text.index(f"diagnose: reading {record}")
    assert status < _first_import(text, ("numba", "scipy.optimize")), text[-3000:]
    assert "diagnose: 300 samples; choosing the baseline law by BIC" in text
    assert "━" in text  # the rich bar, on a terminal
    # the bar's first draw: 0 of its total, before the first fit ends
    first = re.search(r"\D(\d+)/(\d+)\D", text[text.index("diagnose: 300 samples"):])
    assert first and first.group(1) == "0", text[-3000:]
    assert f"{first.group(2)}/{first.group(2)}" in text, text[-3000:]


def test_the_full_parser_commands_say_they_start_before_loading_it(tmp_path: Path) -> None:
    rc, out = run_on_terminal([sys.executable, "-X", "importtime", "-c", ENTRY, "study",
                               "paper", "--cases", "nope", "-o", str(tmp_path / "s")])
    text = out.decode(errors="replace")
    assert rc == 2 and "--cases: unknown case(s) nope" in text, text[-3000:]
    status = text.index("fresco-bridge study paper: starting...")
    assert status < _first_import(text, ("pydantic", "fresco_bridge.cli")), text[-3000:]


def test_status_lines_stay_off_pipes(tmp_path: Path) -> None:
    proc = subprocess.run([sys.executable, "-c", ENTRY, "study", "paper", "--cases", "nope",
                           "-o", str(tmp_path / "s")], cwd=REPO, capture_output=True,
                          text=True, timeout=120)
    assert proc.returncode == 2
    assert proc.stderr.splitlines() == ["error: --cases: unknown case(s) nope; known: "
                                        + proc.stderr.split("known: ")[1].strip()]


def test_make_says_what_each_install_and_compile_step_does() -> None:
    proc = subprocess.run(["make", "-n", "-B", "demo", "test"], cwd=REPO, capture_output=True,
                          text=True, timeout=60)
    assert proc.returncode == 0, proc.stderr
    lines = proc.stdout.splitlines()
    pip = [i for i, line in enumerate(lines) if " install " in line and "/pip " in line
           and "--upgrade pip" not in line]
    assert len(pip) >= 3, lines  # the runtime, the test extras, the compiled build
    for i in pip:
        said = lines[i - 1]
        assert said.startswith('echo "make: '), (lines[i], said)
        assert ("installing" in said) != ("compiling" in said), said
        if "--no-deps" in lines[i]:
            assert "compiling the step path with mypyc" in said, said
        else:
            assert "min" in said, said  # how long the first run takes
