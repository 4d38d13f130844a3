"""Causality under the integrators labs use, through real OpenSeesPy over TCP: explicit
Newmark (γ = ½, β = 0) and ``CentralDifference`` with ``Linear`` (one trial per step), and
Newmark (½, ¼) with ``Newton`` (several trials per step). ``previous-step`` learns committed
steps only, whatever the scheme (equal to the in-process lagged replay); ``same-step`` learns
the source's step before answering it under the explicit schemes (equal to the in-process
replay in that order, no fallback, no mismatch), and under Newton falls back once per session
with the true reason, its update lines then saying previous-step. Whatever the scheme, what
the learner trained on (its log of what changed the worker) is the committed record, exactly,
and a same-step answer's trial measurement is the one then committed, in every session."""

from __future__ import annotations

import itertools
import time
from pathlib import Path
from typing import Any, NamedTuple

import numpy as np
import pytest

from fresco_bridge.record.export import committed_steps
from fresco_bridge.runs import load_run
from fresco_bridge.updating.registry import make_updater
from fresco_bridge.updating.replay import replay
from tests.e2e.test_opensees_updatable import NSTEPS, frame_toml
from tests.support.bridge import RunningBridge, run_opensees
from tests.support.opensees_frame import frame_params
from tests.support.twins import learners_of

SCHEMES: dict[str, dict[str, Any]] = {
    "explicit-newmark": {"integrator": ["NewmarkExplicit", 0.5], "algorithm": ["Linear"]},
    "central-difference": {"integrator": ["CentralDifference"], "algorithm": ["Linear"]},
    "newmark-newton": {"integrator": ["Newmark", 0.5, 0.25], "algorithm": ["Newton"]},
}


def _events(run_dir: Path, *kinds: str) -> list[dict[str, Any]]:
    return [e for e in load_run(run_dir).events if e["event"] in kinds]


class History(NamedTuple):
    disp: Any
    force: Any


def _served(tmp_path: Path, causality: str, scheme: str, sessions: int = 1, **extra: Any
            ) -> tuple[Path, Any, Any, list[tuple[Any, ...]]]:
    """The frame served ``sessions`` times by one bridge (one OpenSees run each; ``extra``:
    e.g. the element order): its run directory, the source's and the twin's histories, and
    the learner's log of what changed its worker (the source's steps it was sent, the twin's
    committed trials)."""
    pytest.importorskip("filterpy")
    toml = frame_toml(f'updater = "online_ukf"\ncausality = "{causality}"\n')
    runs = []
    with RunningBridge(toml, tmp_path) as bridge:
        ports = [bridge.ports["story1"], bridge.ports["story2"]]
        for _ in range(sessions):
            runs += run_opensees("frame2", **frame_params(ports=ports, nsteps=NSTEPS,
                                                           **SCHEMES[scheme], **extra))["runs"]
            end = time.monotonic() + 30  # the last commit and DIE need no reply: let them land
            while bridge.call(lambda: any(s.busy for s in bridge.bridge.sites.values())):
                assert time.monotonic() < end, "the sessions did not end after the DIE"
                time.sleep(0.02)
        learner = learners_of(bridge)["story1"]
        log = bridge.call(lambda: list(learner.log))
        assert bridge.call(lambda: learner._log_base) == 0  # the whole run's log
        run_dir = bridge.run_dir
    for served in runs:
        assert all(np.isfinite(served["u3"]))
    steps = committed_steps(run_dir)  # every session's, in order
    source, twin = (History(np.array([s.meas_disp[0] for s in steps if s.site == site]),
                            np.array([s.meas_force[0] for s in steps if s.site == site]))
                    for site in ("story1", "story2"))
    assert twin.disp.size == NSTEPS * sessions
    _trained_on_commits_only(run_dir, log)
    return run_dir, source, twin, log


def _trained_on_commits_only(run_dir: Path, log: list[tuple[Any, ...]]) -> None:
    """The source steps the learner was sent are the committed record, exactly and in order,
    and every trial measurement a committed twin answer used is that step's committed one."""
    committed = {(s.session, s.step): (s.meas_disp[0], s.meas_force[0])
                 for s in committed_steps(run_dir) if s.site == "story1"}
    sent = [(m[1], m[2], m[3], m[4]) for m in log if m[0] == "observe"]
    assert sent == [(*key, *value) for key, value in committed.items()]
    for m in log:
        if m[0] == "trial" and len(m) > 5 and m[5] is not None:
            assert tuple(m[5]) == committed[tuple(m[4])]


def _close(a: Any, b: Any) -> bool:
    return float(np.max(np.abs(a - b))) / float(np.max(np.abs(b))) < 1e-9


@pytest.mark.parametrize("scheme", list(SCHEMES))
def test_previous_step_learns_committed_steps_only(tmp_path: Path, scheme: str) -> None:
    run_dir, source, twin, _ = _served(tmp_path, "previous-step", scheme)
    expected = replay(make_updater("online_ukf"), source.disp, source.force, twin.disp,
                      lag=True).force_pred
    assert _close(twin.force, expected)
    assert not _events(run_dir, "same-step-fallback", "same-step-mismatch")


@pytest.mark.parametrize("scheme", ["explicit-newmark", "central-difference"])
def test_same_step_under_explicit_schemes(tmp_path: Path, scheme: str) -> None:
    run_dir, source, twin, log = _served(tmp_path, "same-step", scheme)
    expected = replay(make_updater("online_ukf"), source.disp, source.force, twin.disp,
                      lag=False).force_pred
    assert _close(twin.force, expected)
    assert not _events(run_dir, "same-step-fallback", "same-step-mismatch")
    updates = load_run(run_dir).updates
    # a twin step that moved learned its source's step; one that did not (a trial of its
    # committed state) asked nothing, its answer the last one, learned through the same step
    moved = np.diff(twin.disp, prepend=0.0) != 0.0
    moved[0] = True  # a session's first trial is never its committed state
    through = list(itertools.accumulate(
        (k if m else 0 for k, m in zip(range(1, NSTEPS + 1), moved, strict=True)), max))
    assert [(u["step"], u["through"]) for u in updates] == list(
        zip(range(1, NSTEPS + 1), through, strict=True))
    assert sum(moved) > NSTEPS - 5
    # each twin step's answer used the source's trial of that step (or its commit, come
    # first): the committed one (checked in _served)
    assert sum(1 for m in log if m[0] == "trial" and m[5] is not None) > 0


@pytest.mark.parametrize("story2_first", [False, True])
def test_same_step_under_newton_falls_back_once_a_session_and_trains_on_commits_only(
        tmp_path: Path, story2_first: bool) -> None:
    """Two sessions (two OpenSees runs against one bridge), the client visiting the source's
    element first or the twin's: in each session the first step's second trial refutes
    same-step (one fallback, its true reason), the first trial learned tentatively is
    unlearned before any answer is committed (no mismatch), and the twin then answers exactly
    as a twin that learned the committed steps before its own (the lagged replay, across both
    sessions), its update lines saying so."""
    run_dir, source, twin, log = _served(tmp_path, "same-step", "newmark-newton", sessions=2,
                                         story2_first=story2_first)
    fallbacks = _events(run_dir, "same-step-fallback")
    assert [e["session"] for e in fallbacks] == [1, 2]
    for e in fallbacks:
        assert "several trials" in e["reason"] and "implicit" in e["reason"]
        assert e["step"] == 1
    assert not _events(run_dir, "same-step-mismatch")
    assert all(m[5] is None for m in log if m[0] == "trial")  # no answer kept a trial's
    expected = replay(make_updater("online_ukf"), source.disp, source.force, twin.disp,
                      lag=True).force_pred
    assert _close(twin.force, expected)
    updates = load_run(run_dir).updates
    assert [(u["session"], u["step"], u["through"]) for u in updates] == [
        (session, k, k - 1 if k > 1 else (NSTEPS if session == 2 else 0))
        for session in (1, 2) for k in range(1, NSTEPS + 1)]
