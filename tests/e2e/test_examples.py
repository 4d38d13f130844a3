"""The examples run as a newcomer runs them after ``make demo``: each OpenSeesPy example (short)
against a real bridge serving the example's own config, in a fresh interpreter with no
``LD_LIBRARY_PATH``; without a bridge each says so and exits 1 (OpenSees never starts, so it
cannot crash); the data they use ships in ``examples/data`` and works with the commands.
"""

from __future__ import annotations

import hashlib
import json
import os
import re
import subprocess
import sys
import tomllib
from pathlib import Path
from typing import Any

import pytest

from fresco_bridge.cli import main as cli_main
from fresco_bridge.updating.histories import read_history
from tests.support.bridge import RunningBridge
from tests.support.net import free_ports
from tests.support.paths import EXAMPLES, REPO

DATA = EXAMPLES / "data"
STEPS = 150
EXAMPLE_RUNS = [
    # script, the config its docstring serves, its two sites (story 1, story 2)
    ("opensees_two_story.py", "lab.toml", ("damper", "story2")),
    ("opensees_updatable_frame.py", "updatable_twin.toml", ("damper", "twin1")),
]


def example_config(name: str) -> str:
    """The example's config as shipped, but on free ports (``port = 0``: other sessions may hold
    8090-8093); its data paths resolve against ``examples/`` (``RunningBridge(base=...)``)."""
    text = (EXAMPLES / name).read_text(encoding="utf-8")
    text, ports = re.subn(r"(?m)^port = \d+", "port = 0", text)
    assert ports == 2, f"{name}: expected two sites with a port"
    return text


def run_example(script: str, *args: str) -> subprocess.CompletedProcess[str]:
    """``python examples/SCRIPT ARGS`` as the README runs it: a fresh interpreter, no
    ``LD_LIBRARY_PATH`` (the example finds OpenSeesPy's BLAS itself), this checkout importable
    (as ``make demo``'s editable install makes it)."""
    env = {k: v for k, v in os.environ.items() if k != "LD_LIBRARY_PATH"}
    env["PYTHONPATH"] = str(REPO)
    return subprocess.run([sys.executable, str(EXAMPLES / script), *args], cwd=REPO, env=env,
                          capture_output=True, text=True, timeout=300)


@pytest.mark.opensees
@pytest.mark.parametrize(("script", "config", "sites"), EXAMPLE_RUNS)
def test_the_example_runs_against_a_bridge_serving_its_config(
        script: str, config: str, sites: tuple[str, str], tmp_path: Path) -> None:
    pytest.importorskip("openseespy")
    with RunningBridge(example_config(config), tmp_path, base=EXAMPLES) as bridge:
        ports = [str(bridge.ports[site]) for site in sites]
        proc = run_example(script, "--steps", str(STEPS), "--ports", *ports)
        run_dir = bridge.run_dir
    assert proc.returncode == 0, f"stdout: {proc.stdout[-2000:]}\nstderr: {proc.stderr[-2000:]}"
    assert f"RSN960_NORTHR_LOS270.AT2 scaled to PGA 3 m/s², {STEPS} steps of 0.01 s" in proc.stdout
    found = re.search(r"peak story-1 drift ([0-9.]+) mm", proc.stdout)
    assert found is not None and float(found[1]) > 0.1  # the record moved the frame
    assert "next: .venv/bin/fresco-bridge" in proc.stdout
    for site in sites:  # the bridge served (and recorded) every step of both elements
        history = read_history(run_dir, site=site)
        assert history.disp.size == STEPS
        assert history.force is not None and float(abs(history.force).max()) > 0.0


@pytest.mark.parametrize(("script", "config", "sites"), EXAMPLE_RUNS)
def test_without_a_bridge_the_example_says_so_and_exits_1(
        script: str, config: str, sites: tuple[str, str]) -> None:
    ports = [str(p) for p in free_ports(2)]
    proc = run_example(script, "--steps", "5", "--ports", *ports)
    assert proc.returncode == 1, proc.stderr  # not a signal: OpenSees never started
    first = proc.stderr.strip().splitlines()
    assert len(first) == 1, proc.stderr  # one line, no traceback
    assert first[0].startswith(f"{script}: no bridge is listening on 127.0.0.1:{ports[0]}")
    assert f"127.0.0.1:{ports[1]}" in first[0]
    assert first[0].endswith(f"(start it first: .venv/bin/fresco-bridge serve --config "
                             f"examples/{config})")


def test_a_missing_record_is_one_line_and_exit_2() -> None:
    proc = run_example("opensees_two_story.py", "--record", "no-such.AT2")
    assert proc.returncode == 2
    assert proc.stderr.startswith("opensees_two_story.py: cannot read the record: ")
    assert "no-such.AT2" in proc.stderr and "Traceback" not in proc.stderr


def test_make_demo_installs_what_the_examples_need() -> None:
    """``make demo`` installs the ``opensees`` extra, and that extra is OpenSeesPy."""
    project = tomllib.loads((REPO / "pyproject.toml").read_text(encoding="utf-8"))
    extras = project["project"]["optional-dependencies"]
    assert any(req.startswith("openseespy==") for req in extras["opensees"])
    makefile = (REPO / "Makefile").read_text(encoding="utf-8")
    runtime = makefile.split("$(VENV)/.runtime:", 1)[1].split("\n\n", 1)[0]
    assert "pip install" in runtime and ".[opensees]" in runtime
    assert re.search(r"(?m)^demo: .*\$\(VENV\)/\.runtime", makefile)


def test_the_example_data_ships_small_and_unedited() -> None:
    lines = (DATA / "SHA256SUMS").read_text(encoding="utf-8").splitlines()
    listed = {name.strip(): digest for digest, name in (ln.split(maxsplit=1) for ln in lines)}
    shipped = {p.name for p in DATA.iterdir()} - {"SHA256SUMS", "README.md", "make_data.py"}
    assert shipped == set(listed)
    for name, digest in listed.items():
        assert hashlib.sha256((DATA / name).read_bytes()).hexdigest() == digest, name
    assert sum((DATA / n).stat().st_size for n in listed) < 200_000
    readme = (DATA / "README.md").read_text(encoding="utf-8")
    assert all(f"`{name}`" in readme for name in listed)
    assert "CC BY-SA 4.0" in readme and "MIT" in readme


def _replay(updater: str, out: Path) -> dict[str, Any]:
    """``updater replay`` on the shipped pair, as the README's command; its ``pred.json``."""
    rc = cli_main(["updater", "replay", "--source", str(DATA / "brfd_imperial_valley_dbe.csv"),
                   "--twin", str(DATA / "brfd_imperial_valley_mce.csv"), "--updater", updater,
                   "--offline", str(DATA / "brfd_sine_0.25hz.csv"), "--lag", "--quiet",
                   "-o", str(out)])
    assert rc == 0, f"updater replay {updater} failed (exit {rc})"
    assert len(out.read_text().splitlines()) == 1 + 1794
    summary: dict[str, Any] = json.loads(out.with_suffix(".json").read_text())
    return summary


def test_updater_replay_runs_on_the_shipped_measured_pair(tmp_path: Path) -> None:
    """The README's replay on data a fresh clone has: DBE as the tested damper, MCE as its
    twin, the sine as the offline database (mm, kN: no ``--units``)."""
    ukf = _replay("online_ukf", tmp_path / "pred_ukf.csv")
    assert ukf["steps"] == 1794 and ukf["units"] == "mm,kN"
    assert ukf["metrics_kN"]["maeth"] > 0.0
    # the baseline it compares with is the calibrated Bilinear, `none --offline`, replayed alone
    calibrated = _replay("none", tmp_path / "pred_none.csv")
    baseline = ukf["baseline"]["metrics_kN"]
    assert baseline == pytest.approx({k: calibrated["metrics_kN"][k] for k in baseline}, rel=1e-9)
