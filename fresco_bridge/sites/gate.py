"""The full path of a command: the ctrl limits and the operator's pause between a target and
the controller (a mixin of ``ExperimentalSite``: its state is the site's).

A target the limits let go as it is takes the site's eager path (``clear_of_limits``: the
limiter is a pure verdict, so asking it first changes nothing); every other one comes here
(``set_trial_later``): a pause to wait out, limits that reject (HOLD), pause (an operator
decides), clamp or split the command (sub-commands under the velocity limit), each hit counted,
logged, recorded and published.
"""

from __future__ import annotations

import asyncio
import logging
from typing import TYPE_CHECKING

from protocol import Signals

from ..safety import Limiter, LimitHit, SiteState, Trigger

if TYPE_CHECKING:
    from ..controls.base import Controller, InlineController
    from ..record.site import SiteRecorder
    from .guard import ControllerGuard

log = logging.getLogger("fresco_bridge.site")

PAUSE_LOG_INTERVAL = 30.0
"""While a command waits for an operator, a warning is logged this often (s)."""

RUNNING, PAUSED, HOLD, FAULT = SiteState.RUNNING, SiteState.PAUSED, SiteState.HOLD, SiteState.FAULT


class CommandGate:
    """Limits and pauses of an ``ExperimentalSite`` (declared here: what they use of it)."""

    name: str
    state: SiteState
    reason: str
    peer: str
    session: int
    step: int
    time: float
    ctrl: tuple[float, ...]
    pending: tuple[float, ...] | None
    limit_counts: dict[str, int]
    recorder: SiteRecorder | None
    guard: ControllerGuard
    controller: Controller
    _now: InlineController | None
    _ctrl_limiter: Limiter | None
    _reference: tuple[float, ...] | None
    _commit_time: float
    _wake: asyncio.Event | None

    # The site's own, used here (ExperimentalSite defines them; real methods, not a
    # TYPE_CHECKING block, so that mypyc can compile the class).
    def enter_hold(self, reason: str) -> None:
        raise NotImplementedError

    def event(self, kind: str, reason: str, **extra: object) -> None:
        raise NotImplementedError

    def _transition(self, trigger: Trigger, reason: str, **extra: object) -> SiteState:
        raise NotImplementedError

    async def _send(self, command: tuple[float, ...]) -> bool:
        raise NotImplementedError

    def clear_of_limits(self, target: tuple[float, ...]) -> bool:
        """No ctrl limit, or an in-process controller and a verdict that lets ``target`` go
        as it is (the limiter is pure: a command it acts on is checked again, with its events,
        on the full path)."""
        limiter = self._ctrl_limiter
        if limiter is None:
            return True
        if self._now is None or (self._reference is None and limiter.needs_reference):
            return False
        return limiter.check_ctrl(target, self._reference, self.time - self._commit_time,
                                  approved=False) is None


    async def set_trial_later(self, trial: Signals, target: tuple[float, ...]) -> None:
        """The full path of code 3: a pause to wait out, limits that act, sub-commands."""
        commands = await self.commands_for(target)
        if commands is None:
            return
        ctrl = self.ctrl = commands[-1]
        if self.recorder is not None:
            self.recorder.trial(self.session, self.step, self.time, trial.disp, ctrl)
            if self.state is HOLD:  # the record failed (``record_failed``)
                return
        for command in commands:
            if command != self.guard.sent and not await self._send(command):
                return


    async def commands_for(
        self, target: tuple[float, ...]
    ) -> tuple[tuple[float, ...], ...] | None:
        """Wait out a pause, apply the limits: the commands to send in order, or None."""
        while True:
            if self.state is PAUSED:
                await self.wait_for_operator(target)
            if self._ctrl_limiter is None:
                commands: tuple[tuple[float, ...], ...] | None = (target,)
            else:
                commands = await self.limited(target)
            state = self.state
            if commands is None or state is HOLD:
                return None
            if state is RUNNING:
                return commands
            if state is FAULT:
                return None  # aborted while waiting: the next reply request ends the session
            if state is not PAUSED:  # no session (IDLE): nothing is ever forwarded
                log.error("site %s: command %s without a running session not forwarded",
                          self.name, list(target))
                return None
            # paused by the operator while the limits were being checked: wait, check again

    async def limited(self, target: tuple[float, ...]) -> tuple[tuple[float, ...], ...] | None:
        """The commands to send for ``target`` under the limits, or None (HOLD)."""
        limiter = self._ctrl_limiter
        assert limiter is not None
        if self._reference is None and limiter.needs_reference:
            daq = await self.guard.guarded("get_daq (reference position)", self.controller.get_daq)
            if daq is None:
                return None
            self._reference = daq.disp
        approved = False
        while True:
            verdict = limiter.check_ctrl(target, self._reference, self.time - self._commit_time,
                                         approved=approved)
            if verdict is None:
                return (target,)
            action = verdict.action
            for hit in verdict.hits:
                self.limit_event(hit, action)
            if action == "reject":
                self.enter_hold(f"limit exceeded, command {list(target)} not forwarded: "
                                f"{verdict.describe()}")
                return None
            if action == "pause":
                self._transition(Trigger.PAUSE, f"limit exceeded, command {list(target)} "
                                 f"waits for an operator: {verdict.describe()}", step=self.step)
                await self.wait_for_operator(target)
                if self.state is not RUNNING:
                    return None  # aborted
                approved = True  # the operator saw it: increment/velocity waived, absolute not
                continue
            if action == "substep":
                log.info("site %s: step %d sent as %d sub-commands (velocity limit)",
                         self.name, self.step + 1, len(verdict.commands))
                self.event("substep", f"{len(verdict.commands)} sub-commands within the "
                           "velocity limit", substeps=len(verdict.commands),
                           target=list(verdict.commands[-1]), step=self.step)
            return verdict.commands


    async def wait_for_operator(self, command: tuple[float, ...]) -> None:
        """Wait (logging every PAUSE_LOG_INTERVAL s) until resumed or aborted."""
        self.pending = command
        log.warning("site %s: command %s at step %d waits for an operator (%s): "
                    "'fresco-bridge ctl resume --site %s' or 'abort'", self.name, list(command),
                    self.step + 1, self.reason, self.name)
        await asyncio.sleep(0)  # leave the eager path: asyncio.timeout needs a task
        waited = 0.0
        try:
            while self.state is PAUSED:
                self._wake = wake = asyncio.Event()
                try:
                    async with asyncio.timeout(PAUSE_LOG_INTERVAL):
                        await wake.wait()
                except TimeoutError:
                    waited += PAUSE_LOG_INTERVAL
                    log.warning("site %s: still PAUSED after %.0f s (%s); client %s waits for "
                                "step %d", self.name, waited, self.reason, self.peer,
                                self.step + 1)
        finally:
            self.pending = None
            self._wake = None


    def limit_event(self, hit: LimitHit, action: str) -> None:
        """Every limit hit is counted, logged, recorded and published (also when clamped)."""
        self.limit_counts[hit.limit] = self.limit_counts.get(hit.limit, 0) + 1
        log.warning("site %s: LIMIT at step %d: %s (policy %s: %s)", self.name, self.step + 1,
                    hit.describe(), hit.policy, action)
        self.event("limit", hit.describe(), **hit.as_record(), action=action, step=self.step)


    def resend_refused(self, command: tuple[float, ...],
                       measured: tuple[float, ...]) -> str | None:
        """Why ``command`` may not be re-sent from the ``measured`` position, or None."""
        limiter = self._ctrl_limiter
        if limiter is None:
            return None
        verdict = limiter.check_ctrl(command, measured, self.time - self._commit_time)
        if verdict is None:
            return None
        what = verdict.describe() or (f"the move needs {len(verdict.commands)} sub-commands "
                                      "under the velocity limit")
        return (f"controller answers again with the actuator at {list(measured)} mm; re-sending "
                f"{list(command)} mm from there is not within the limits ({what}); not sent")

