"""How a twin answers while its learner is behind the source (a backlog: source-only sessions
run faster than the learner learns, a source that ran ahead of the twin's session), and how
that is said.

The rule (docs/updatable-sites.md, "Catch-up"): every committed source step is learned, in
order, once; none is skipped. A twin's trial asks for the source steps its causality allows
(previous-step: through (S, k − 1); same-step: (S, k)); the worker learns at most
``CATCH_UP`` of those it has not learned yet, and stops early once it has spent
``CATCH_UP_SHARE`` of the learner's deadline past the first two (a loaded host, a law refit
among them), then answers from its model as learned so far.
What is left is learned in the background, one step at a time between the twin's steps (never
between a twin's trial and its commit, so a replay that learns a step's steps at its committed
trial rebuilds the same model), and by the next trials. So the first trial after any backlog
waits for at most ``CATCH_UP`` updates and about a quarter of the deadline, and the backlog
shrinks by at least one step per twin step: the twin catches up.

A same-step trial's tentative step (the source's trial measurement, ``worker.py``) is learned
only once every committed source step before it is: a trial the cap stops short answers as a
previous-step one would, from the committed steps learned so far, and says ``upto``. Steps
re-learned after a rollback (``worker.py``) are not counted: the twin had learned them.

An answer that learned less than it asked for is never passed off as current: its update line
carries ``upto`` (the source (session, step) it was learned through, ``record/lines.py``,
which a resume replays exactly), and the twin's site says when it fell behind (how many steps)
and when it caught up again (``learner-behind``, ``learner-caught-up`` events).
"""

from __future__ import annotations

from collections.abc import Callable

__all__ = ["CATCH_UP", "CATCH_UP_SHARE", "CatchUpEvents", "trial_cap"]

CATCH_UP = 32
"""Source steps a trial may learn before it answers (the worker's cap)."""
CATCH_UP_SHARE = 0.25
"""The share of ``learner_deadline`` a trial may spend learning a backlog past its first two
steps (two: a twin that learns one new step per step of its own always gains on it)."""


def trial_cap(deadline: float) -> tuple[int, float]:
    """A trial's cap (its message's last item, ``worker.py``): at most ``CATCH_UP`` steps,
    for at most ``CATCH_UP_SHARE`` of the learner's ``deadline`` past the first two."""
    return CATCH_UP, CATCH_UP_SHARE * deadline


Event = Callable[..., None]
"""``event(kind, reason, **extra)``: an event of the learner's twins."""


class CatchUpEvents:
    """Per twin, whether its last answer was behind: an event when that changes."""

    def __init__(self, source: str, event: Event) -> None:
        self.source = source
        self._event = event
        self._behind: dict[str, int] = {}

    def answered(self, twin: str, step: int, behind: int, upto: tuple[int, int]) -> None:
        """Twin ``twin``'s answer at its ``step`` left ``behind`` of the source steps it
        asked for unlearned; it was learned through source ``upto`` (session, step)."""
        was = self._behind.get(twin, 0)
        if behind and not was:
            self._event("learner-behind", f"twin {twin} step {step}: its learner is {behind} "
                        f"source step(s) behind; it answers from its model learned through "
                        f"source session {upto[0]} step {upto[1]} while it catches up "
                        f"(at most {CATCH_UP} steps learned per trial, the rest between "
                        "steps)", twin=twin, behind=behind, upto=list(upto))
        elif was and not behind:
            self._event("learner-caught-up", f"twin {twin} step {step}: its learner caught "
                        f"up with the source (learned through source session {upto[0]} step "
                        f"{upto[1]})", twin=twin, upto=list(upto))
        self._behind[twin] = behind

    def behind(self, twin: str) -> bool:
        return self._behind.get(twin, 0) > 0
