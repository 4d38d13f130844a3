"""kill -9 of a real ``fresco-bridge serve`` with an updatable site, then ``serve --resume``:
the learner's worker does not outlive the bridge, and the twin's answers after the resume
equal an uninterrupted run's (the learner replays the record before it answers)."""

from __future__ import annotations

import math
import re
import signal
import subprocess
import sys
import textwrap
import time
from pathlib import Path

import numpy as np
import pytest

from fresco_bridge.integrator.link import GenericClientLink
from fresco_bridge.record.export import committed_steps
from fresco_bridge.updating.registry import make_updater
from fresco_bridge.updating.replay import replay
from protocol import Action
from tests.e2e.test_crash_resume import _STARTED, _kill_leftover_bridges  # noqa: F401

pytest.importorskip("filterpy")

READY = re.compile(r"fresco-bridge ready: damper=(\d+), twin1=(\d+)")
def serve(cwd: Path, *args: str) -> tuple[subprocess.Popen[str], tuple[int, int]]:
    proc = subprocess.Popen([sys.executable, "-m", "fresco_bridge.cli", "serve", *args],
                            cwd=cwd, stdout=subprocess.PIPE,
                            stderr=(cwd / f"serve-{time.monotonic_ns()}.log").open("w"),
                            text=True)
    _STARTED.append(proc)
    assert proc.stdout is not None
    end = time.monotonic() + 60
    while time.monotonic() < end:
        m = READY.search(proc.stdout.readline())
        if m or proc.poll() is not None:
            break
    assert m, "the bridge did not print its ready line"
    return proc, (int(m.group(1)), int(m.group(2)))


def workers_of(pid: int) -> set[int]:
    """The learner workers among ``pid``'s children (not multiprocessing's resource tracker)."""
    found: set[int] = set()
    for task in Path(f"/proc/{pid}/task").iterdir():
        found |= {int(p) for p in (task / "children").read_text().split()}
    return {p for p in found
            if b"spawn_main" in Path(f"/proc/{p}/cmdline").read_bytes()}


def gone(pid: int) -> bool:
    """The process ended (a zombie waiting for init to reap it counts as ended)."""
    try:
        return Path(f"/proc/{pid}/stat").read_text().split()[2] == "Z"
    except FileNotFoundError:
        return True


def drive(ports: tuple[int, int], start: int, n: int) -> None:
    with GenericClientLink("127.0.0.1", ports[0], 1, data_size=1) as source, \
            GenericClientLink("127.0.0.1", ports[1], 1, data_size=1) as twin:
        for i in range(start, start + n):
            d = 1.5 * math.sin(i / 4.0)
            for trial in (0.9 * d, d):  # two Newton iterations: the last one is committed
                source.set_trial((trial,), time=0.01 * i)
                source.force()
                twin.set_trial((0.8 * trial,), time=0.01 * i)
                twin.force()
            source.commit()
            twin.commit()
        twin.request(Action.GET_DISP)  # answered after the last commit


def test_a_resumed_twin_answers_as_an_uninterrupted_one(tmp_path: Path) -> None:
    cfg = tmp_path / "lab.toml"
    cfg.write_text(textwrap.dedent(f"""
        [bridge]
        run_dir = "{tmp_path / 'runs'}"
        run_name = "twin-resume"
        [[sites]]
        name = "damper"
        port = 0
        [sites.controller]
        model = "bilinear"
        params = {{ k0 = 20.0, fy = 5.0, alpha = 0.05 }}
        reset_on_new_session = false
        [[sites]]
        name = "twin1"
        port = 0
        kind = "updatable"
        learns_from = "damper"
        updater = "online_ukf"
        """))
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
    cfg = tmp_path / f"{name}.toml"
    cfg.write_text(textwrap.dedent(f"""
        [bridge]
        run_dir = "{tmp_path / name}"
        run_name = "{name}"
        [[sites]]
        name = "damper"
        port = 0
        [sites.controller]
        model = "bilinear"
        params = {{ k0 = 20.0, fy = 5.0, alpha = 0.05 }}
        [[sites]]
        name = "twin1"
        port = 0
        kind = "updatable"
        learns_from = "damper"
        updater = "online_ukf"
        """))
    return cfg


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
