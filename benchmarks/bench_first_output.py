"""Seconds from starting a long command on a terminal to its first output, and to its end.

    python -m benchmarks.bench_first_output [--quick] [--repeat N] [--tree DIR]

Each command runs on a pseudo-terminal (what a person at a shell sees) with the pure sources of
``--tree`` (default: this checkout), ``--repeat`` times; the medians are printed. A 5 s demo
run recorded first is the input of ``diagnose`` and ``updater replay``. BENCHMARKS.md, "First
output of long commands".
"""

from __future__ import annotations

import argparse
import os
import pty
import select
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
ENTRY = "import sys; from fresco_bridge.entry import main; sys.exit(main(sys.argv[1:]))"


def on_terminal(argv: list[str], env: dict[str, str], cwd: Path,
                timeout: float = 600.0) -> tuple[float, float, bytes]:
    """(seconds to the first byte, seconds to the end, the first bytes) of ``argv`` on a pty."""
    leader, follower = pty.openpty()
    start = time.monotonic()
    proc = subprocess.Popen(argv, stdin=subprocess.DEVNULL, stdout=follower, stderr=follower,
                            env=env, cwd=cwd)
    os.close(follower)
    first, head = None, b""
    try:
        while time.monotonic() - start < timeout:
            ready, _, _ = select.select([leader], [], [], 0.02)
            if ready:
                try:
                    data = os.read(leader, 65536)
                except OSError:
                    break
                if not data:
                    break
                if first is None:
                    first, head = time.monotonic() - start, data[:80]
            elif proc.poll() is not None:
                break
        proc.wait(timeout=30)
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.wait()
        os.close(leader)
    return (first if first is not None else float("nan")), time.monotonic() - start, head


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--quick", action="store_true", help="one run of each, short inputs")
    parser.add_argument("--repeat", type=int, default=3)
    parser.add_argument("--tree", type=Path, default=ROOT, help="the sources to measure")
    args = parser.parse_args(argv)
    repeat = 1 if args.quick else args.repeat
    env = {**os.environ, "PYTHONPATH": str(args.tree.resolve()), "FRESCO_BRIDGE_PURE": "1",
           "COLUMNS": "120", "TERM": "xterm"}
    cli = [sys.executable, "-c", ENTRY]
    with tempfile.TemporaryDirectory(prefix="first-output-") as tmp:
        work = Path(tmp)
        subprocess.run([*cli, "demo", "--duration", "5", "--runs", "runs"], cwd=work, env=env,
                       check=True, capture_output=True, timeout=600)
        (run,) = (work / "runs").iterdir()
        commands = [
            ["diagnose", str(run)],
            ["updater", "replay", "--source", str(run), "--twin", str(run), "--updater", "none",
             "-o", "pred.csv"],
            ["study", "paper", "--steps", "50", "--cases", "online_improved", "--no-plots",
             "--workers", "1", "-o", "study"],
            ["demo", "--duration", "5"],
            ["diagnose-bench", "--n", "2", "--steps", "300", "--workers", "1"],
        ]
        for command in commands:
            runs = [on_terminal([*cli, *command], env, work) for _ in range(repeat)]
            first = statistics.median(r[0] for r in runs)
            end = statistics.median(r[1] for r in runs)
            print(f"{' '.join(command)[:58]:<58} first {first:5.2f} s  end {end:6.2f} s  "
                  f"{runs[0][2]!r}", flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
