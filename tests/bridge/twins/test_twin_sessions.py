"""Sessions keyed by (session, step), in a real bridge over the element protocol: a session
after a source-only one, and a second pair session, learn exactly what one long session
would (source-only sessions are learned from, at the pair's first step)."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest

from fresco_bridge.integrator.link import GenericClientLink
from fresco_bridge.record.export import committed_steps
from fresco_bridge.runs import load_run
from fresco_bridge.updating.registry import make_updater
from fresco_bridge.updating.replay import replay
from protocol import Action
from tests.bridge.twins.test_twin_bridge import TOML
from tests.support.bridge import RunningBridge


def _source_only(port: int, first: int, n: int) -> None:
    with GenericClientLink("127.0.0.1", port, 1) as source:
        for i in range(first, first + n):
            source.set_trial((1.5 * math.sin(i / 4.0),), time=0.01 * i)
            source.force()
            source.commit()
        source.request(Action.GET_DISP)


def _pair(ports: dict[str, int], first: int, n: int) -> None:
    with GenericClientLink("127.0.0.1", ports["damper"], 1) as source, \
            GenericClientLink("127.0.0.1", ports["twin1"], 1) as twin:
        for i in range(first, first + n):
            d = 1.5 * math.sin(i / 4.0)
            twin.set_trial((0.8 * d,), time=0.01 * (i - first + 1))
            twin.force()
            source.set_trial((d,), time=0.01 * (i - first + 1))
            source.force()
            twin.commit()  # the twin's element first: previous-step must not depend on it
            source.commit()
        twin.request(Action.GET_DISP)
        source.request(Action.GET_DISP)


def test_sessions_after_a_source_only_one_learn_what_one_long_session_would(
        tmp_path: Path) -> None:
    pytest.importorskip("filterpy")
    toml = TOML.replace("[telemetry]\nmetrics_port = 0\n", "")
    with RunningBridge(toml, tmp_path) as bridge:
        _source_only(bridge.ports["damper"], 1, 30)
        _pair(bridge.ports, 31, 25)
        _pair(bridge.ports, 56, 25)
        run_dir = bridge.run_dir
    steps = committed_steps(run_dir)
    src = [s for s in steps if s.site == "damper"]
    twin = [s for s in steps if s.site == "twin1"]
    assert [s.session for s in src] == [1] * 30 + [2] * 25 + [3] * 25
    assert [s.step for s in twin] == list(range(1, 26)) * 2  # steps restart per session
    updater = make_updater("online_ukf")
    for s in src[:30]:  # the source-only session, learned at the pair's first step
        updater.observe(s.meas_disp[0], s.meas_force[0])
    expected = replay(updater, [s.meas_disp[0] for s in src[30:]],
                      [s.meas_force[0] for s in src[30:]], [s.cmd_disp[0] for s in twin],
                      lag=True).force_pred
    got = np.array([s.meas_force[0] for s in twin])
    assert float(np.max(np.abs(got - expected))) / float(np.max(np.abs(expected))) < 1e-9
    updates = [(u["session"], u["step"], u["through"]) for u in load_run(run_dir).updates]
    assert updates[:2] == [(1, 1, 30), (1, 2, 1)]  # session 1 of the twin: source session 2
    assert updates[25:27] == [(2, 1, 25), (2, 2, 1)]  # all of the earlier session, then k-1


def test_after_source_only_sessions_the_twin_answers_from_step_1_within_its_deadline(
        tmp_path: Path) -> None:
    """Four source-only sessions of 750 steps, then a pair: the twin answers from its step 1
    within its learner deadline (its trial learns at most ``CATCH_UP`` of the backlog, the
    rest is learned between its steps); each answer's update line says how far it was
    learned, never past what previous-step allows, and one that learned less than it asked
    for says so (``upto``, a ``learner-behind`` event)."""
    pytest.importorskip("filterpy")
    toml = TOML.replace("[telemetry]\nmetrics_port = 0\n", "")
    with RunningBridge(toml, tmp_path) as bridge:
        for first in (1, 751, 1501, 2251):
            _source_only(bridge.ports["damper"], first, 750)
        _pair(bridge.ports, 3001, 40)
        run_dir = bridge.run_dir
    run = load_run(run_dir)
    assert not [e for e in run.events if e["event"] in ("hold", "learner-lost")]
    twin = [s for s in committed_steps(run_dir) if s.site == "twin1"]
    assert len(twin) == 40 and all(math.isfinite(s.meas_force[0]) for s in twin)
    keys = []
    for u in run.updates:  # twin step k of source session 5 may learn through (5, k - 1)
        upto = u.get("upto")
        key = (5, u["step"] - 1) if upto is None else tuple(upto)
        assert key <= (5, u["step"] - 1) and (upto is None or key[1] == u["through"])
        keys.append(key)
    assert keys == sorted(keys)
    behind = [e for e in run.events if e["event"] == "learner-behind"]
    assert bool(behind) == any("upto" in u for u in run.updates)


def test_the_log_is_trimmed_behind_the_snapshot_and_a_new_worker_starts_from_it(
        tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """Memory bounded: the learner keeps what came after its last snapshot only; a worker
    lost late in a run is replaced from that snapshot, replaying a bounded tail, and answers
    as the lost one would have."""
    pytest.importorskip("filterpy")
    import os
    import signal
    import time

    from fresco_bridge.twins import learner as learner_module
    from tests.support.twins import learners_of

    monkeypatch.setattr(learner_module, "CHECKPOINT_EVERY", 100)
    toml = TOML.replace("[telemetry]\nmetrics_port = 0\n", "")
    with RunningBridge(toml, tmp_path) as bridge:
        _pair(bridge.ports, 1, 400)
        learner = learners_of(bridge)["damper"]
        lengths = bridge.call(lambda: (len(learner.log), learner._log_base))
        assert lengths[0] < 250 and lengths[1] > 0  # trimmed behind the snapshot
        pid = learner.pid
        assert pid is not None
        os.kill(pid, signal.SIGKILL)
        end = time.monotonic() + 30
        while bridge.call(lambda: learner.state) != "live" or learner.pid == pid:
            assert time.monotonic() < end, "the learner did not come back"
            time.sleep(0.05)
        _pair(bridge.ports, 401, 50)
        run_dir = bridge.run_dir
    restored = [e for e in load_run(run_dir).events if e["event"] == "learner-restored"]
    assert restored and all(int(e["reason"].split("(worker restarted, ")[1].split()[0]) < 250
                            for e in restored)
    steps = committed_steps(run_dir)
    src = [s for s in steps if s.site == "damper"]
    twin = [s for s in steps if s.site == "twin1"]
    expected = replay(make_updater("online_ukf"), [s.meas_disp[0] for s in src],
                      [s.meas_force[0] for s in src], [s.cmd_disp[0] for s in twin],
                      lag=True).force_pred
    got = np.array([s.meas_force[0] for s in twin])
    assert float(np.max(np.abs(got - expected))) / float(np.max(np.abs(expected))) < 1e-9
