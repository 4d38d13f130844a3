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

The twin's n-th moving trial of a step awaits the source's n-th trial of that step: each
iteration updates every element once, whichever element OpenSees visits first, so the twin's
second iteration sees the source's second trial (the one that refutes same-step) and never
answers from the first one again.
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
        self._count = 0
        """Trials of ``_trial``'s step (and time) published so far."""
        self._waiters: dict[tuple[int, float],
                            list[tuple[int, asyncio.Future[ForwardedTrial | None]]]] = {}
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
        same = last is not None and (last.session, last.step, last.time) == (
            trial.session, trial.step, trial.time)
        self._count = self._count + 1 if same else 1
        if (same and last is not None and last.ctrl != trial.ctrl
                and self.iterating != (trial.session, trial.step)):
            self.iterating = (trial.session, trial.step)
        self._trial = trial
        self._wake((trial.step, trial.time), trial, self._count)

    def _wake(self, key: tuple[int, float], trial: ForwardedTrial | None, count: int) -> None:
        """Resolve the waiters of ``key`` whose trial has come (``count`` trials of it)."""
        waiting = self._waiters.get(key)
        if not waiting:
            return
        rest = [(n, fut) for n, fut in waiting if n > count and not fut.done()]
        for n, fut in waiting:
            if n <= count and not fut.done():
                fut.set_result(trial)
        if rest:
            self._waiters[key] = rest
        else:
            del self._waiters[key]

    def step_committed(self, step: CommittedStep) -> None:
        self._committed_ctrl, self._committed_session = step.ctrl, step.session
        self._committed[(step.step, step.time)] = (step.daq_disp[0], step.daq_force[0])
        if len(self._committed) > KEEP_COMMITTED:
            self._committed.popitem(last=False)
        self._wake((step.step, step.time), self._trial, 1 << 30)  # they take the commit

    def site_event(self, notice: SiteNotice, status: SiteStatus) -> None:
        """The source stopped forwarding (HOLD, FAULT): nothing more to learn this step."""
        if status.state in STOPPED:
            waiters, self._waiters = self._waiters, {}
            for futs in waiters.values():
                for _, fut in futs:
                    if not fut.done():
                        fut.set_result(None)

    # -- the twin's side ------------------------------------------------------------------------
    async def measurement(self, step: int, time: float, deadline: float, nth: int = 1
                          ) -> tuple[float, float, bool] | None:
        """The source's ``(d, F, committed)`` of step ``step`` at trial time ``time``, from
        its ``nth`` trial of that step or a later one (the twin's ``nth`` moving trial); None
        if the source stopped (nothing to learn); ``SameStepImpossible`` if the order of
        messages makes same-step impossible (why)."""
        committed = self._committed.get((step, time))
        if committed is not None:
            return (*committed, True)
        trial = self._trial
        if trial is None or (trial.step, trial.time) != (step, time) or self._count < nth:
            fut: asyncio.Future[ForwardedTrial | None] = \
                asyncio.get_running_loop().create_future()
            self._waiters.setdefault((step, time), []).append((nth, fut))
            try:
                trial = await asyncio.wait_for(fut, deadline)
            except TimeoutError:
                waiting = [w for w in self._waiters.pop((step, time), []) if w[1] is not fut]
                if waiting:
                    self._waiters[(step, time)] = waiting
                raise SameStepImpossible(
                    f"the source's trial of step {step} (t = {time:g} s) did not reach its "
                    f"controller within {deadline:g} s of the twin's trial (the client asks "
                    "the twin's force before sending the source's trial)") from None
            if trial is None:
                return None
            committed = self._committed.get((step, time))
            if committed is not None:
                return (*committed, True)
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
