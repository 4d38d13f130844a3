"""A spawned worker's output reaches the bridge's log as its lines, under its site's name, and
a killed bridge's resource tracker releases the queues' semaphores without a stray warning."""

from __future__ import annotations

import logging
import multiprocessing
import os
import queue
import subprocess
import sys
import textwrap
from pathlib import Path
from typing import Any

import pytest

from fresco_bridge.worker_output import OUTPUT, forward_output, relay_output


def noisy_worker(out: Any) -> None:
    """What a worker's libraries do: a numpy overflow warning, a warning of its own logging,
    a print to stderr over two lines and a C-level write to fd 2."""
    import numpy as np

    end = forward_output(out.put)
    with np.errstate(over="warn"):
        np.array([1e308]) * 10.0
    logging.getLogger("fresco_bridge.twins").warning("learner: source step %d not learned", 7)
    print("first\nsecond\x1b[2J", file=sys.stderr, flush=True)
    os.write(2, b"from C\n")
    end()  # what a worker does last: its fd 2's last lines are sent before it returns
    out.put(("done",))


def test_a_workers_warnings_and_stderr_are_lines_of_the_log(
        caplog: pytest.LogCaptureFixture) -> None:
    ctx = multiprocessing.get_context("spawn")
    out: Any = ctx.Queue()
    proc = ctx.Process(target=noisy_worker, args=(out,), daemon=True)
    proc.start()
    replies: list[tuple[Any, ...]] = []
    try:
        while True:  # fd 2's lines come from a thread: "done" may overtake them
            try:
                reply = out.get(timeout=30)
            except queue.Empty:
                break
            replies.append(reply)
            if ("done",) in replies and sum(r[0] == OUTPUT and r[2] == "stderr"
                                            for r in replies) >= 3:
                break
    finally:
        proc.join(30)
    with caplog.at_level(logging.DEBUG, logger="fresco_bridge.worker"):
        for reply in replies:
            if reply[0] == OUTPUT:
                relay_output("damper", proc.pid, reply)
    lines = [r.getMessage() for r in caplog.records]
    head = f"worker of damper (pid {proc.pid})"
    assert any(line.startswith(f"{head} py.warnings: ") and "RuntimeWarning: overflow "
               "encountered in multiply" in line for line in lines), lines
    assert f"{head} fresco_bridge.twins: learner: source step 7 not learned" in lines
    assert [line for line in lines if " stderr: " in line] == [
        f"{head} stderr: first", f"{head} stderr: second\x1b[2J", f"{head} stderr: from C"]
    assert all("\n" not in line for line in lines)  # the escape itself: logs.printable


@pytest.mark.parametrize("quiet", [False, True])
def test_the_trackers_report_of_a_killed_bridge_is_its_own_clean_up(tmp_path: Path,
                                                                    quiet: bool) -> None:
    """Two spawn queues hold six named semaphores; a bridge killed with -9 cannot release them,
    its resource tracker does and says so. With ``quiet_tracker`` it only does."""
    script = tmp_path / "killed.py"
    script.write_text(textwrap.dedent(f"""
        import multiprocessing, os, signal, sys, time
        from fresco_bridge.worker_output import quiet_tracker

        def idle(a, b):
            time.sleep(2)

        if __name__ == "__main__":
            if {quiet}:
                quiet_tracker()
            ctx = multiprocessing.get_context("spawn")
            a, b = ctx.Queue(16), ctx.Queue()
            names = [q._rlock._semlock.name for q in (a, b)]  # to see them gone
            print(" ".join(names), flush=True)
            ctx.Process(target=idle, args=(a, b), daemon=True).start()
            time.sleep(0.5)
            os.kill(os.getpid(), signal.SIGKILL)
        """), encoding="utf-8")
    env = {**os.environ, "PYTHONPATH": os.pathsep.join(sys.path)}
    env.pop("PYTHONWARNINGS", None)
    r = subprocess.run([sys.executable, str(script)], capture_output=True, text=True,
                       timeout=60, env=env)
    assert r.returncode == -9
    import time

    time.sleep(3.0)  # the tracker notices its parent's end and releases what it held
    for name in r.stdout.split():
        assert not Path("/dev/shm", "sem." + name.lstrip("/")).exists()
    leaked = "leaked semaphore objects to clean up at shutdown" in r.stderr
    assert leaked is not quiet, r.stderr


def test_a_learners_worker_warning_reaches_the_log_under_its_sites_name(
        caplog: pytest.LogCaptureFixture) -> None:
    """The real path: a twin's updater overflows in its worker (numpy warns there); the line
    arrives through the learner's reply channel as a line of the bridge's log."""
    pytest.importorskip("filterpy")
    import asyncio
    import contextlib

    from fresco_bridge.site_output import CommittedStep
    from fresco_bridge.twins.learner import Learner, LearnerError
    from fresco_bridge.twins.worker import LearnerSpec, TwinSpec

    spec = LearnerSpec("damper", (TwinSpec("t", "online_ukf",
                                           {"k0": 1e308, "fy": 1e308, "alpha": 0.05}),))

    async def run() -> int | None:
        learner = Learner("damper", spec, deadline=30.0)
        await learner.start()
        try:
            for n in (1, 2, 3):
                with contextlib.suppress(LearnerError):  # the twin's answer is not finite
                    await learner.trial("t", 1e300, step=n)
                learner.commit("t")
                learner.step_committed(CommittedStep("damper", 1, n, 0.01 * n, (1e300,),
                                                     (1e300,), (1e300,), (1e308,), "RUNNING"))
            deadline = asyncio.get_running_loop().time() + 30.0
            while not any("worker of damper" in r.getMessage() for r in caplog.records):
                assert asyncio.get_running_loop().time() < deadline, caplog.text
                await asyncio.sleep(0.05)
            return learner.pid
        finally:
            await learner.close()

    with caplog.at_level(logging.WARNING, logger="fresco_bridge.worker"):
        pid = asyncio.run(run())
    lines = [r.getMessage() for r in caplog.records if r.name == "fresco_bridge.worker"]
    assert any(line.startswith(f"worker of damper (pid {pid}) py.warnings: ")
               and "RuntimeWarning" in line for line in lines), lines
