"""A source site's trials and commits as its same-step twins await them.

The source publishes them as a listener's events (``sites/listeners.py``: every trial that
reached its controller, with a way to read that trial's one measurement; every committed step;
its state changes): the twin awaits the trial of its own step and time with a deadline, never
polls and never holds the source site itself.

Same-step is defined for the order of messages OpenSees' integrators produce. A trial of the
command last committed moves nothing (``CentralDifference`` and Newmark's predictor begin
each step with one): it is the committed state again, not a trial of the step, for the source
(never published to the twin as the step's trial, never an iteration) and for the twin (it
asks nothing of its source).

* explicit schemes (explicit Newmark, ``CentralDifference``): one moving trial per step; the twin's
  answer at step k learns the source's measurement of step k, read at the source's trial (the
  one read of that trial, shared with the source's own force request) or, when the source's
  commit of step k already came (its trial and commit both reached the bridge before the
  twin's force request), its committed measurement;
* implicit schemes (Newmark with Newton: several moving trials per step): the measurement of a
  trial is not the committed one, and an updater learns only what is committed. The second
  distinct moving trial of a source step says so; from then on the session answers
  ``previous-step`` (trained on commits only), said once per session with that reason.
"""

from __future__ import annotations

import asyncio
from collections import OrderedDict

from ..site_output import CommittedStep, SiteNotice
from ..sites.listeners import ForwardedTrial
from ..telemetry.schema import SiteStatus

__all__ = ["SameStepImpossible", "SourceFeed"]

KEEP_COMMITTED = 16
"""Committed source steps kept for a twin whose force request comes after the source's commit
(explicit schemes: at most one step behind)."""
STOPPED = ("HOLD", "FAULT")


class SameStepImpossible(Exception):
    """The order of messages makes same-step impossible (the reason, for the fallback)."""


class SourceFeed:
    """One source site's published trials and commits, for its same-step twins."""

    def __init__(self, source: str) -> None:
        self.source = source
        self._trial: ForwardedTrial | None = None
        self._waiters: dict[tuple[int, float], list[asyncio.Future[ForwardedTrial | None]]] = {}
        self._committed: OrderedDict[tuple[int, float], tuple[float, float]] = OrderedDict()
        self._committed_session = 0
        self._committed_ctrl: tuple[float, ...] | None = None
        """The source's last committed command: a trial of it again moves nothing (the first
        update of a step under ``CentralDifference`` and Newmark's constant-displacement
        predictor) and is neither a trial to learn nor an iteration."""
        self.iterating: tuple[int, int] | None = None
        """``(source session, step)`` where a second distinct trial of one step came."""

    # -- the source's listener -----------------------------------------------------------------
    def trial_forwarded(self, trial: ForwardedTrial) -> None:
        if self.iterating is not None and self.iterating[0] != trial.session:
            self.iterating = None  # a new session: its own scheme
        if trial.ctrl == self._committed_ctrl and trial.session == self._committed_session:
            return  # the committed state again (a new step's first update): nothing new
        last = self._trial
        if (last is not None and last.session == trial.session and last.step == trial.step
                and last.ctrl != trial.ctrl and self.iterating != (trial.session, trial.step)):
            self.iterating = (trial.session, trial.step)
        self._trial = trial
        for fut in self._waiters.pop((trial.step, trial.time), ()):
            if not fut.done():
                fut.set_result(trial)

    def step_committed(self, step: CommittedStep) -> None:
        self._committed_ctrl, self._committed_session = step.ctrl, step.session
        self._committed[(step.step, step.time)] = (step.daq_disp[0], step.daq_force[0])
        if len(self._committed) > KEEP_COMMITTED:
            self._committed.popitem(last=False)

    def site_event(self, notice: SiteNotice, status: SiteStatus) -> None:
        """The source stopped forwarding (HOLD, FAULT): nothing more to learn this step."""
        if status.state in STOPPED:
            waiters, self._waiters = self._waiters, {}
            for futs in waiters.values():
                for fut in futs:
                    if not fut.done():
                        fut.set_result(None)

    # -- the twin's side ------------------------------------------------------------------------
    async def measurement(self, step: int, time: float, deadline: float
                          ) -> tuple[float, float, bool] | None:
        """The source's ``(d, F, committed)`` of step ``step`` at trial time ``time``; None if
        the source stopped (nothing to learn); ``SameStepImpossible`` if the order of
        messages makes same-step impossible (why)."""
        committed = self._committed.get((step, time))
        if committed is not None:
            return (*committed, True)
        trial = self._trial
        if trial is None or (trial.step, trial.time) != (step, time):
            fut: asyncio.Future[ForwardedTrial | None] = \
                asyncio.get_running_loop().create_future()
            self._waiters.setdefault((step, time), []).append(fut)
            try:
                trial = await asyncio.wait_for(fut, deadline)
            except TimeoutError:
                self._waiters.pop((step, time), None)
                raise SameStepImpossible(
                    f"the source's trial of step {step} (t = {time:g} s) did not reach its "
                    f"controller within {deadline:g} s of the twin's trial (the client asks "
                    "the twin's force before sending the source's trial)") from None
            if trial is None:
                return None
        if self.iterating is not None and self.iterating[0] == trial.session:
            raise SameStepImpossible(
                f"the source's step {self.iterating[1]} had several trials (an implicit "
                "scheme's iterations): a trial's measurement is not the committed one and the "
                "twin learns only committed ones")
        daq = await trial.read()
        if daq is None:
            committed = self._committed.get((step, time))
            return None if committed is None else (*committed, True)
        return daq.disp[0], daq.force[0], False
