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
