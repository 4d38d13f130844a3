"""The full path of a command: the ctrl limits and the operator's pause between a target and
the controller, composed into a site (``ExperimentalSite.gate``).

A target the limits let go as it is takes the site's eager path (``clear_of_limits``: the
limiter is a pure verdict, so asking it first changes nothing); every other one comes here
(``set_trial_later``): a pause to wait out, limits that reject (HOLD), pause (an operator
decides), clamp or split the command (sub-commands under the velocity limit), each hit counted,
logged, recorded and published. The gate owns what only it needs (the limiter, the reference
position, the hit counts, the operator's wake-up); what it needs of its site is ``GatedSite``.
"""

from __future__ import annotations

import asyncio
import logging
from typing import TYPE_CHECKING, Protocol

from protocol import Signals

from ..safety import Limiter, LimitHit, SiteState, Trigger

if TYPE_CHECKING:
    from ..controls.base import Daq
    from ..record.site import SiteRecorder

log = logging.getLogger("fresco_bridge.site")

PAUSE_LOG_INTERVAL = 30.0
"""While a command waits for an operator, a warning is logged this often (s)."""

RUNNING, PAUSED, HOLD, FAULT = SiteState.RUNNING, SiteState.PAUSED, SiteState.HOLD, SiteState.FAULT


class GatedSite(Protocol):
    """What the gate needs of its site: where the session is, and how to act on it."""

    name: str

    @property
    def state(self) -> SiteState: ...

    @property
    def reason(self) -> str: ...

    @property
    def peer(self) -> str: ...

    @property
    def session(self) -> int: ...

    step: int
    time: float
    commit_time: float
    """Pseudo-time of the last commit (the velocity limit's interval starts there)."""
    ctrl: tuple[float, ...]
    pending: tuple[float, ...] | None
    recorder: SiteRecorder | None

    @property
    def sent(self) -> tuple[float, ...] | None:
        """The last setpoint the controller acknowledged (``guard.sent``)."""
        ...

    def enter_hold(self, reason: str) -> None: ...

    def event(self, kind: str, reason: str, **extra: object) -> None: ...

    def transition(self, trigger: Trigger, reason: str, **extra: object) -> SiteState: ...

    async def send(self, command: tuple[float, ...]) -> bool:
        """One command to the controller; False if the site left RUNNING/PAUSED meanwhile."""
        ...

    async def read_position(self) -> Daq | None:
        """A fresh measurement (the limits' reference), None if the controller failed."""
        ...


class CommandGate:
    """Limits and pauses between a site's targets and its controller."""

    def __init__(self, site: GatedSite, limiter: Limiter | None, *, inline: bool) -> None:
        self.site = site
        self.limiter = limiter if limiter is not None and limiter.has_ctrl else None
        """The ctrl limits (None: none configured)."""
        self.inline = inline
        """An in-process controller: a clear verdict may take the eager path."""
        self.reference: tuple[float, ...] | None = None
        """The last command the controller got (None: where the actuator is is not known)."""
        self.limit_counts: dict[str, int] = {}
        self._wake: asyncio.Event | None = None

    def wake(self) -> None:
        """An operator acted (resume, abort): a command waiting for one checks again."""
        if self._wake is not None:
            self._wake.set()

    def clear_of_limits(self, target: tuple[float, ...]) -> bool:
        """No ctrl limit, or an in-process controller and a verdict that lets ``target`` go
        as it is (the limiter is pure: a command it acts on is checked again, with its events,
        on the full path)."""
        limiter = self.limiter
        if limiter is None:
            return True
        if not self.inline or (self.reference is None and limiter.needs_reference):
            return False
        site = self.site
        return limiter.check_ctrl(target, self.reference, site.time - site.commit_time,
                                  approved=False) is None


    async def set_trial_later(self, trial: Signals, target: tuple[float, ...]) -> None:
        """The full path of code 3: a pause to wait out, limits that act, sub-commands."""
        site = self.site
        commands = await self.commands_for(target)
        if commands is None:
            return
        ctrl = site.ctrl = commands[-1]
        if site.recorder is not None:
            site.recorder.trial(site.session, site.step, site.time, trial.disp, ctrl)
            if site.state is HOLD:  # the record failed (``record_failed``)
                return
        for command in commands:
            if command != site.sent and not await site.send(command):
                return

    async def commands_for(
        self, target: tuple[float, ...]
    ) -> tuple[tuple[float, ...], ...] | None:
        """Wait out a pause, apply the limits: the commands to send in order, or None."""
        site = self.site
        while True:
            if site.state is PAUSED:
                await self.wait_for_operator(target)
            if self.limiter is None:
                commands: tuple[tuple[float, ...], ...] | None = (target,)
            else:
                commands = await self.limited(target)
            state = site.state
            if commands is None or state is HOLD:
                return None
            if state is RUNNING:
                return commands
            if state is FAULT:
                return None  # aborted while waiting: the next reply request ends the session
            if state is not PAUSED:  # no session (IDLE): nothing is ever forwarded
                log.error("site %s: command %s without a running session not forwarded",
                          site.name, list(target))
                return None
            # paused by the operator while the limits were being checked: wait, check again

    async def limited(self, target: tuple[float, ...]) -> tuple[tuple[float, ...], ...] | None:
        """The commands to send for ``target`` under the limits, or None (HOLD)."""
        site, limiter = self.site, self.limiter
        assert limiter is not None
        if self.reference is None and limiter.needs_reference:
            daq = await site.read_position()
            if daq is None:
                return None
            self.reference = daq.disp
        approved = False
        while True:
            verdict = limiter.check_ctrl(target, self.reference, site.time - site.commit_time,
                                         approved=approved)
            if verdict is None:
                return (target,)
            action = verdict.action
            for hit in verdict.hits:
                self.limit_event(hit, action)
            if action == "reject":
                site.enter_hold(f"limit exceeded, command {list(target)} not forwarded: "
                                f"{verdict.describe()}")
                return None
            if action == "pause":
                site.transition(Trigger.PAUSE, f"limit exceeded, command {list(target)} "
                                f"waits for an operator: {verdict.describe()}", step=site.step)
                await self.wait_for_operator(target)
                if site.state is not RUNNING:
                    return None  # aborted
                approved = True  # the operator saw it: increment/velocity waived, absolute not
                continue
            if action == "substep":
                log.info("site %s: step %d sent as %d sub-commands (velocity limit)",
                         site.name, site.step + 1, len(verdict.commands))
                site.event("substep", f"{len(verdict.commands)} sub-commands within the "
                           "velocity limit", substeps=len(verdict.commands),
                           target=list(verdict.commands[-1]), step=site.step)
            return verdict.commands

    async def wait_for_operator(self, command: tuple[float, ...]) -> None:
        """Wait (logging every PAUSE_LOG_INTERVAL s) until resumed or aborted."""
        site = self.site
        site.pending = command
        log.warning("site %s: command %s at step %d waits for an operator (%s): "
                    "'fresco-bridge ctl resume --site %s' or 'abort'", site.name, list(command),
                    site.step + 1, site.reason, site.name)
        await asyncio.sleep(0)  # leave the eager path: asyncio.timeout needs a task
        waited = 0.0
        try:
            while site.state is PAUSED:
                self._wake = wake = asyncio.Event()
                try:
                    async with asyncio.timeout(PAUSE_LOG_INTERVAL):
                        await wake.wait()
                except TimeoutError:
                    waited += PAUSE_LOG_INTERVAL
                    log.warning("site %s: still PAUSED after %.0f s (%s); client %s waits for "
                                "step %d", site.name, waited, site.reason, site.peer,
                                site.step + 1)
        finally:
            site.pending = None
            self._wake = None

    def limit_event(self, hit: LimitHit, action: str) -> None:
        """Every limit hit is counted, logged, recorded and published (also when clamped)."""
        site = self.site
        self.limit_counts[hit.limit] = self.limit_counts.get(hit.limit, 0) + 1
        log.warning("site %s: LIMIT at step %d: %s (policy %s: %s)", site.name, site.step + 1,
                    hit.describe(), hit.policy, action)
        site.event("limit", hit.describe(), **hit.as_record(), action=action, step=site.step)

    def resend_refused(self, command: tuple[float, ...],
                       measured: tuple[float, ...]) -> str | None:
        """Why ``command`` may not be re-sent from the ``measured`` position, or None."""
        limiter = self.limiter
        if limiter is None:
            return None
        verdict = limiter.check_ctrl(command, measured, self.site.time - self.site.commit_time)
        if verdict is None:
            return None
        what = verdict.describe() or (f"the move needs {len(verdict.commands)} sub-commands "
                                      "under the velocity limit")
        return (f"controller answers again with the actuator at {list(measured)} mm; re-sending "
                f"{list(command)} mm from there is not within the limits ({what}); not sent")
