"""Run a benchmark of ``benchmarks/`` as a user runs it: ``python -m benchmarks.NAME ...`` in its
own process, from the repository root, with a deadline. Tests never import ``benchmarks/``
(one-off scripts must not become load-bearing); the few that check a benchmark run it this way.
"""

from __future__ import annotations

import os
import signal
import subprocess
import sys

from tests.support.paths import REPO


def run_benchmark(module: str, *args: str, deadline: float) -> str:
    """Run ``python -m benchmarks.<module> args``; its output (stdout and stderr), or
    ``AssertionError`` if it fails or outlives ``deadline`` seconds (then it and every process
    it started are killed: it runs in its own session)."""
    env = {**os.environ, "PYTHONPATH": os.pathsep.join(
        p for p in (str(REPO), os.environ.get("PYTHONPATH", "")) if p)}
    proc = subprocess.Popen([sys.executable, "-m", f"benchmarks.{module}", *args], cwd=REPO,
                            env=env, stdout=subprocess.PIPE, stderr=subprocess.STDOUT,
                            text=True, start_new_session=True)  # fmt: skip
    try:
        printed, _ = proc.communicate(timeout=deadline)
    except subprocess.TimeoutExpired:
        os.killpg(proc.pid, signal.SIGKILL)
        printed, _ = proc.communicate()
        raise AssertionError(f"benchmarks.{module} did not end within {deadline} s:\n"
                             f"{printed}") from None
    assert proc.returncode == 0, f"benchmarks.{module} exited {proc.returncode}:\n{printed}"
    return printed
