"""Site states and the one table of allowed transitions (h11 style: the table is the rule).

IDLE     no integrator session; nothing moves.
RUNNING  a session is open and commands are forwarded within the limits.
PAUSED   commands are not forwarded; the integrator's request waits for an operator
         (``ctl resume`` / ``ctl abort``). Persists across sessions until resumed.
HOLD     a fault the site survives (controller lost or late, NaN/inf, limit violation,
         integrator lost mid-step): nothing is forwarded. A controller that was only lost or
         late is probed inside the integrator's waiting request for up to
         ``bridge.controller_recovery`` s: back in time → RECOVERED → RUNNING (the failed call
         is made again over the verified link); not back → NaN answers until DIE. Every other
         HOLD answers NaN (the integrator stops) until the session ends (→ IDLE).
FAULT    an operator abort (anything that needs a human): the current session's answers are
         NaN from its next request on (the integrator stops and sends DIE) and new sessions
         are refused until an operator resumes.
"""

from __future__ import annotations

import enum


class SiteState(enum.StrEnum):
    IDLE = "IDLE"
    RUNNING = "RUNNING"
    PAUSED = "PAUSED"
    HOLD = "HOLD"
    FAULT = "FAULT"


class Trigger(enum.StrEnum):
    """What happened; the value is the run record's event kind."""

    SESSION_OPEN = "session-open"
    SESSION_CLOSE = "session-close"
    HOLD = "hold"
    INTEGRATOR_LOST = "integrator-lost"
    PAUSE = "pause"
    RESUME = "resume"
    ABORT = "abort"
    RECOVERED = "recovered"


class TransitionRefused(Exception):
    """The trigger is not allowed in this state; the message says why and what to do."""


IDLE, RUNNING, PAUSED, HOLD, FAULT = SiteState
T = Trigger

# (from, trigger) -> (to while a session is open, to without a session); None = refused.
TRANSITIONS: dict[tuple[SiteState, Trigger], tuple[SiteState | None, SiteState | None]] = {
    (IDLE, T.SESSION_OPEN):       (None, RUNNING),
    (IDLE, T.PAUSE):              (None, PAUSED),
    (IDLE, T.ABORT):              (None, FAULT),
    (RUNNING, T.SESSION_CLOSE):   (IDLE, None),
    (RUNNING, T.HOLD):            (HOLD, None),
    (RUNNING, T.INTEGRATOR_LOST): (HOLD, None),
    (RUNNING, T.PAUSE):           (PAUSED, None),
    (RUNNING, T.ABORT):           (FAULT, None),
    (PAUSED, T.SESSION_OPEN):     (None, PAUSED),
    (PAUSED, T.SESSION_CLOSE):    (PAUSED, None),
    (PAUSED, T.HOLD):             (HOLD, None),
    (PAUSED, T.INTEGRATOR_LOST):  (PAUSED, None),
    (PAUSED, T.PAUSE):            (PAUSED, PAUSED),
    (PAUSED, T.RESUME):           (RUNNING, IDLE),
    (PAUSED, T.ABORT):            (FAULT, FAULT),
    (HOLD, T.SESSION_CLOSE):      (IDLE, None),
    (HOLD, T.HOLD):               (HOLD, None),
    (HOLD, T.INTEGRATOR_LOST):    (HOLD, None),
    (HOLD, T.ABORT):              (FAULT, None),
    (HOLD, T.RECOVERED):          (RUNNING, None),
    (FAULT, T.SESSION_CLOSE):     (FAULT, None),
    (FAULT, T.HOLD):              (FAULT, None),
    (FAULT, T.INTEGRATOR_LOST):   (FAULT, None),
    (FAULT, T.RESUME):            (None, IDLE),
    (FAULT, T.ABORT):             (FAULT, FAULT),
}

_HINTS: dict[tuple[SiteState, Trigger], str] = {
    (IDLE, T.RECOVERED): "only a HOLD with an open session can recover",
    (RUNNING, T.RECOVERED): "only a HOLD with an open session can recover",
    (PAUSED, T.RECOVERED): "only a HOLD with an open session can recover",
    (FAULT, T.RECOVERED): "the site was aborted by the operator; it does not recover by itself",
    (IDLE, T.RESUME): "the site is not paused",
    (RUNNING, T.RESUME): "the site is not paused",
    (HOLD, T.RESUME): "HOLD ends by itself when a lost controller answers again within "
                      "bridge.controller_recovery, otherwise when the integrator session ends "
                      "(its answers since the fault were stale); use abort to end it now",
    (HOLD, T.PAUSE): "the site is in HOLD: nothing is forwarded already",
    (FAULT, T.PAUSE): "the site is in FAULT: nothing is forwarded already",
    (FAULT, T.RESUME): "the aborted client is still connected; it is disconnected at its next "
                       "request (or stop it), then resume",
    (FAULT, T.SESSION_OPEN): "the site was aborted; an operator must resume it first",
}


def next_state(state: SiteState, trigger: Trigger, in_session: bool) -> SiteState:
    """The state after ``trigger``, or ``TransitionRefused`` naming why it is not allowed."""
    row = TRANSITIONS.get((state, trigger))
    to = None if row is None else row[0] if in_session else row[1]
    if to is None:
        hint = _HINTS.get((state, trigger), "not a transition of the site state machine")
        raise TransitionRefused(f"{trigger} refused in state {state}: {hint}")
    return to
