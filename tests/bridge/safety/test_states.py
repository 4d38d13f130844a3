"""The site state table: every (state, trigger) pair either moves or is refused with a reason."""

from __future__ import annotations

import itertools

import pytest

from fresco_bridge.safety import TRANSITIONS, SiteState, TransitionRefused, Trigger, next_state

S, T = SiteState, Trigger


@pytest.mark.parametrize(
    ("state", "trigger", "in_session", "expected"),
    [
        (S.IDLE, T.SESSION_OPEN, False, S.RUNNING),
        (S.RUNNING, T.HOLD, True, S.HOLD),
        (S.RUNNING, T.INTEGRATOR_LOST, True, S.HOLD),
        (S.HOLD, T.SESSION_CLOSE, True, S.IDLE),
        (S.RUNNING, T.PAUSE, True, S.PAUSED),
        (S.PAUSED, T.RESUME, True, S.RUNNING),
        (S.PAUSED, T.RESUME, False, S.IDLE),
        (S.PAUSED, T.SESSION_CLOSE, True, S.PAUSED),  # a pause outlives the session
        (S.PAUSED, T.SESSION_OPEN, False, S.PAUSED),
        (S.PAUSED, T.INTEGRATOR_LOST, True, S.PAUSED),
        (S.IDLE, T.ABORT, False, S.FAULT),
        (S.HOLD, T.ABORT, True, S.FAULT),
        (S.FAULT, T.SESSION_CLOSE, True, S.FAULT),
        (S.FAULT, T.RESUME, False, S.IDLE),
        (S.HOLD, T.RECOVERED, True, S.RUNNING),  # a lost controller answered again in time
    ],
)
def test_transitions(state: SiteState, trigger: Trigger, in_session: bool,
                     expected: SiteState) -> None:
    assert next_state(state, trigger, in_session) is expected


@pytest.mark.parametrize(
    ("state", "trigger", "in_session", "fragment"),
    [
        (S.FAULT, T.SESSION_OPEN, False, "an operator must resume it first"),
        (S.FAULT, T.RESUME, True, "still connected"),
        (S.HOLD, T.RESUME, True, "HOLD ends by itself when a lost controller answers again"),
        (S.HOLD, T.RECOVERED, False, "not a transition"),  # no session: nothing to recover
        (S.RUNNING, T.RECOVERED, True, "only a HOLD with an open session can recover"),
        (S.FAULT, T.RECOVERED, True, "aborted by the operator"),
        (S.HOLD, T.PAUSE, True, "nothing is forwarded already"),
        (S.RUNNING, T.RESUME, True, "not paused"),
        (S.IDLE, T.RESUME, False, "not paused"),
        (S.IDLE, T.HOLD, False, "not a transition"),
    ],
)
def test_refused_transitions_say_why(state: SiteState, trigger: Trigger, in_session: bool,
                                     fragment: str) -> None:
    with pytest.raises(TransitionRefused, match=fragment):
        next_state(state, trigger, in_session)


def test_abort_reaches_fault_from_every_state_that_can_exist() -> None:
    reachable = [(S.IDLE, False), (S.RUNNING, True), (S.PAUSED, True), (S.PAUSED, False),
                 (S.HOLD, True), (S.FAULT, True), (S.FAULT, False)]
    for state, in_session in reachable:
        assert next_state(state, T.ABORT, in_session) is S.FAULT


def test_the_table_only_names_states_and_triggers_it_knows_and_fault_needs_an_operator() -> None:
    for (state, trigger), row in TRANSITIONS.items():
        assert isinstance(state, SiteState) and isinstance(trigger, Trigger)
        assert all(to is None or isinstance(to, SiteState) for to in row)
    # only an operator's resume leaves FAULT; HOLD is left only by a session end (→ IDLE) or
    # by a recovered controller within the session (→ RUNNING)
    for state, trigger, in_session in itertools.product(S, T, (True, False)):
        try:
            to = next_state(state, trigger, in_session)
        except TransitionRefused:
            continue
        if state is S.FAULT and to is not S.FAULT:
            assert trigger is T.RESUME
        if state is S.HOLD and to not in (S.HOLD, S.FAULT):
            assert (trigger, to, in_session) in ((T.SESSION_CLOSE, S.IDLE, True),
                                                 (T.RECOVERED, S.RUNNING, True))
