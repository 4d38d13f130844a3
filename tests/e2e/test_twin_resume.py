"""kill -9 of a real ``fresco-bridge serve`` with an updatable site, then ``serve --resume``:
the learner's worker does not outlive the bridge, and the twin's answers after the resume
equal an uninterrupted run's (the learner replays the record before it answers)."""

from __future__ import annotations

import re
import signal
import subprocess
import time
from pathlib import Path

import numpy as np
import pytest

from fresco_bridge.record.export import committed_steps
from fresco_bridge.updating.registry import make_updater
from fresco_bridge.updating.replay import replay
from tests.e2e.test_crash_resume import _STARTED, _kill_leftover_bridges  # noqa: F401
from tests.support.serve import drive_pair, source_and_twin, start_cli, started, workers_of

pytest.importorskip("filterpy")


def serve(cwd: Path, *args: str) -> tuple[subprocess.Popen[str], tuple[int, ...]]:
    proc = start_cli(cwd, "serve", *args)
    _STARTED.append(proc)
    return proc, started(proc)[0]


def gone(pid: int) -> bool:
    """The process ended (a zombie waiting for init to reap it counts as ended)."""
    try:
        return Path(f"/proc/{pid}/stat").read_text().split()[2] == "Z"
    except FileNotFoundError:
        return True


def drive(ports: tuple[int, ...], start: int, n: int) -> None:
    drive_pair(ports, start, n, trials=(0.9, 1.0))  # two Newton iterations, the last committed


def test_a_resumed_twin_answers_as_an_uninterrupted_one(tmp_path: Path) -> None:
    cfg = source_and_twin(tmp_path / "lab.toml", tmp_path / "runs", "twin-resume",
                          source="reset_on_new_session = false\n")
    first, ports = serve(tmp_path, "--config", str(cfg))
    workers = workers_of(first.pid)
    assert len(workers) == 1
    drive(ports, 1, 30)
    first.send_signal(signal.SIGKILL)
    first.wait(10)
    (worker,) = workers
    end = time.monotonic() + 5  # the worker ends the moment its parent's sentinel closes
    while not gone(worker) and time.monotonic() < end:
        time.sleep(0.05)
    assert gone(worker), "an orphan learner worker outlived the bridge"

    (run,) = [p for p in (tmp_path / "runs").iterdir() if p.is_dir()]
    second, ports = serve(tmp_path, "--config", str(cfg), "--resume", str(run))
    drive(ports, 31, 30)
    second.send_signal(signal.SIGTERM)
    second.wait(30)

    steps = committed_steps(run)
    src = [s for s in steps if s.site == "damper"]
    twin = [s for s in steps if s.site == "twin1"]
    assert [s.step for s in twin] == list(range(1, 61)) == [s.step for s in src]
    expected = replay(make_updater("online_ukf"), [s.meas_disp[0] for s in src],
                      [s.meas_force[0] for s in src], [s.cmd_disp[0] for s in twin],
                      lag=True).force_pred
    got = np.array([s.meas_force[0] for s in twin])
    scale = float(np.max(np.abs(expected)))
    assert float(np.max(np.abs(got - expected))) / scale < 1e-9
    # without the replay of the record the resumed twin would have restarted from scratch
    fresh = replay(make_updater("online_ukf"), [s.meas_disp[0] for s in src[30:]],
                   [s.meas_force[0] for s in src[30:]], [s.cmd_disp[0] for s in twin[30:]],
                   lag=True).force_pred
    assert float(np.max(np.abs(got[30:] - fresh))) / scale > 1e-6


def _config(tmp_path: Path, name: str) -> Path:
    return source_and_twin(tmp_path / f"{name}.toml", tmp_path / name, name)


def test_a_run_killed_after_yield_resumes_equal_to_an_uninterrupted_one(tmp_path: Path) -> None:
    """The in-process specimen yields long before the kill; ``--resume`` replays the record's
    commands into it (and does not reset it: the resumed session goes on), so the source and
    its twin go on exactly as if never interrupted."""
    whole = _config(tmp_path, "whole")
    proc, ports = serve(tmp_path, "--config", str(whole))
    drive(ports, 1, 60)
    proc.send_signal(signal.SIGTERM)
    proc.wait(30)

    cut = _config(tmp_path, "cut")
    first, ports = serve(tmp_path, "--config", str(cut))
    drive(ports, 1, 35)
    first.send_signal(signal.SIGKILL)
    first.wait(10)
    (run,) = [p for p in (tmp_path / "cut").iterdir() if p.is_dir()]
    second, ports = serve(tmp_path, "--config", str(cut), "--resume", str(run))
    drive(ports, 36, 25)
    second.send_signal(signal.SIGTERM)
    second.wait(30)

    (reference,) = [p for p in (tmp_path / "whole").iterdir() if p.is_dir()]
    for site in ("damper", "twin1"):
        want = np.array([s.meas_force[0] for s in committed_steps(reference) if s.site == site])
        got = np.array([s.meas_force[0] for s in committed_steps(run) if s.site == site])
        assert want.size == got.size == 60
        assert float(np.max(np.abs(want[:35]))) > 5.0  # yielded (fy = 5 kN) before the kill
        assert float(np.max(np.abs(got - want))) / float(np.max(np.abs(want))) < 1e-9, site


def test_a_resume_after_a_long_run_starts_from_the_learners_checkpoint(tmp_path: Path) -> None:
    """Past ``CHECKPOINT_EVERY`` messages the learner's snapshot is in the run directory; a
    kill -9 then ``--resume`` starts the worker from it and replays only the record after it,
    and the twin still answers exactly as an uninterrupted run's."""
    cfg = _config(tmp_path, "long")
    first, ports = serve(tmp_path, "--config", str(cfg))
    drive(ports, 1, 800)  # 3 messages a step: past one checkpoint
    first.send_signal(signal.SIGKILL)
    first.wait(10)
    (run,) = [p for p in (tmp_path / "long").iterdir() if p.is_dir()]
    assert (run / "learner-damper.checkpoint").stat().st_mode & 0o777 == 0o600
    second, ports = serve(tmp_path, "--config", str(cfg), "--resume", str(run))
    drive(ports, 801, 20)
    second.send_signal(signal.SIGTERM)
    second.wait(30)

    logs = "".join(p.read_text() for p in tmp_path.glob("serve-*.log"))
    found = re.search(r"resumes from its checkpoint of twin step (\d+) and replays (\d+) of the "
                      r"record's (\d+) message", logs)
    assert found, "the resumed learner did not start from its checkpoint"
    at, replayed, total = map(int, found.groups())
    assert at >= 600 and total == 3 * 800 and replayed == total - 3 * at
    steps = committed_steps(run)
    src = [s for s in steps if s.site == "damper"]
    twin = [s for s in steps if s.site == "twin1"]
    assert [s.step for s in twin] == list(range(1, 821)) == [s.step for s in src]
    expected = replay(make_updater("online_ukf"), [s.meas_disp[0] for s in src],
                      [s.meas_force[0] for s in src], [s.cmd_disp[0] for s in twin],
                      lag=True).force_pred
    got = np.array([s.meas_force[0] for s in twin])
    assert float(np.max(np.abs(got - expected))) / float(np.max(np.abs(expected))) < 1e-9
