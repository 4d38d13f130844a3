"""The controller guard of a site: every controller call under its deadline, the controller's
hold, and the bounded recovery of a lost or silent controller (``bridge.controller_recovery``).

The guard talks to the controller; the site keeps the state table, the limits and the session.
What the guard needs of its site is :class:`GuardedSite` (its state, a HOLD, an event, the
RECOVERED transition, telling the integrator to stop, the limits' say on a re-sent setpoint).

Recovery runs inside the integrator's request that hit the fault, so the integrator simply
waits (OpenSees blocks in its socket read): no answer is ever made up from a stale measurement.
Either the controller answers again in time and the same request is served with fresh data,
or the integrator is told to stop (NaN answers until it sends DIE: OpenSees' Newton then fails
to converge) instead of integrating frozen forces. Only ``ControllerLinkError`` / a missed
deadline qualify: a latched fault, an interlock that is not ours or a refused command needs a
human and keeps the plain HOLD.

Why re-sending the setpoint afterwards is not a blind retry of a motion command:

* it goes out only after a probe (``get_daq``, with the per-call deadline) got a complete,
  finite answer with a live heartbeat over a fresh connection, and after the background
  ``hold()`` has settled, so nothing else is talking to the controller;
* the adapter reads the controller's status first and refuses to move a controller that is in
  FAULT, MOVING or under an interlock it did not engage itself;
* setpoints are absolute: the same target, already checked against the absolute limits, is
  sent once. A controller that completed it before the link broke moves by zero; one that was
  restarted (and lost it) is driven back to where the integrator's step says it must be.
* the increment/velocity limits are checked again against the *measured* position of the probe
  (the last command is no longer a trustworthy reference): a move they would not allow is not
  sent and the session ends instead.
"""

from __future__ import annotations

import asyncio
import contextlib
import logging
import time as _time
from collections.abc import Awaitable, Callable, Coroutine
from typing import Any, Protocol, TypeVar

from ..backoff import Backoff
from ..controls.base import Controller, ControllerError, ControllerLinkError, Daq
from ..eager import Suspended, start_eager
from ..safety import SiteState

log = logging.getLogger("fresco_bridge.site")
T = TypeVar("T")

RECOVERY_LOG_INTERVAL = 5.0
"""While a site waits for a lost controller, a warning is logged this often (s)."""
PROBE_BACKOFF = (0.05, 1.0)
"""Jittered exponential delay between probes, s (capped so a returning controller is seen
within about a second)."""

RUNNING, HOLD, FAULT = SiteState.RUNNING, SiteState.HOLD, SiteState.FAULT


class GuardedSite(Protocol):
    """What the guard needs of the site it guards."""

    name: str

    @property
    def state(self) -> SiteState: ...

    @property
    def reason(self) -> str: ...

    step: int
    ctrl: tuple[float, ...]
    pending: tuple[float, ...] | None

    def enter_hold(self, reason: str) -> None: ...

    def event(self, kind: str, reason: str, **extra: object) -> None: ...

    def recovered(self, reason: str, **extra: object) -> None:
        """HOLD → RUNNING: the controller answers again."""
        ...

    def tell_integrator_to_stop(self, why: str) -> None: ...

    def resend_refused(self, command: tuple[float, ...], measured: tuple[float, ...]) -> str | None:
        """Why ``command`` may not go from the ``measured`` position (the limits), or None."""
        ...


class ControllerGuard:
    """One site's controller calls: deadline, HOLD on failure, hold, recovery."""

    def __init__(self, site: GuardedSite, controller: Controller, *, timeout: float,
                 recovery: float) -> None:
        self.site = site
        self.controller = controller
        self.timeout = timeout
        """Deadline (s) of every controller call."""
        self.recovery = recovery
        """Seconds a lost or silent controller is waited for; 0: plain HOLD."""
        self.recovering_since: float | None = None
        self.sent: tuple[float, ...] | None = None
        """The last setpoint the controller acknowledged in this session (re-sent by a read
        that recovered the controller)."""
        self._wake: asyncio.Event | None = None
        self._background: set[asyncio.Task[None]] = set()

    def wake(self) -> None:
        """An operator acted (abort, resume): a recovery in progress ends at once."""
        if self._wake is not None:
            self._wake.set()

    # -- calls ----------------------------------------------------------------------------------
    def call(self, coro: Coroutine[Any, Any, T]) -> Awaitable[T]:
        """The call with the deadline; an in-process controller completes at once."""
        if self.controller.inline:
            return coro
        return asyncio.wait_for(coro, self.timeout)

    def now(self, what: str, call: Callable[..., T], *args: Any) -> T | None:
        """An in-process controller's synchronous call (``InlineController.*_now``): no
        deadline, no recovery (there is no link to lose); a failure HOLDs (None), as in
        ``guarded``."""
        try:
            return call(*args)
        except ControllerError as exc:
            self.site.enter_hold(f"controller failed on {what}: {exc}")
            return None

    async def guarded(self, what: str, call: Callable[[], Coroutine[Any, Any, T]],
                      command: tuple[float, ...] | None = None) -> T | None:
        """``call()`` under the deadline; a failure HOLDs (None). A lost or silent controller
        is waited for first (recovery), then the call is made again: ``command`` is the
        setpoint ``call`` sends, a read re-sends the last setpoint before reading again."""
        site = self.site
        deadline: float | None = None
        resend: tuple[float, ...] | None = None
        while True:
            started, doing = site.state, what
            try:
                if resend is not None:
                    doing = f"set_ctrl {list(resend)} (re-sent after the controller came back)"
                    await self.call(self.controller.set_ctrl(resend))
                    resend = None
                    doing = what
                return await self.call(call())
            except TimeoutError:
                reason, lost = f"controller did not answer {doing} within {self.timeout:g} s", True
            except ControllerError as exc:
                reason = f"controller failed on {doing}: {exc}"
                lost = isinstance(exc, ControllerLinkError)
            site.enter_hold(reason)
            if not lost or self.recovery <= 0.0 or started is not RUNNING or site.state is not HOLD:
                return None
            loop = asyncio.get_running_loop()
            deadline = loop.time() + self.recovery if deadline is None else deadline
            if resend is None:
                resend = command if command is not None else self.sent
            why = await self.recover(reason, deadline, resend)
            if site.state is FAULT:
                return None  # aborted meanwhile: the reply is NaN
            if why is not None:
                site.tell_integrator_to_stop(why)
                return None
            if command is not None:
                resend = None  # ``call`` itself sends ``command`` again

    # -- hold -----------------------------------------------------------------------------------
    def hold(self) -> None:
        """Stop the actuator where it is; the adapter itself releases the interlock it engaged
        at the next command the site forwards (a new session or an operator's resume)."""
        if self.controller.inline:
            r = start_eager(self.controller.hold())
            if isinstance(r, Suspended):
                r.task()
            return
        task = asyncio.get_running_loop().create_task(self._hold_in_background(),
                                                      name=f"{self.site.name}.hold")
        self._background.add(task)  # the loop keeps only a weak reference
        task.add_done_callback(self._background.discard)

    async def _hold_in_background(self) -> None:
        """The hold call with its deadline; a failure is logged and recorded, never lost."""
        try:
            await asyncio.wait_for(self.controller.hold(), self.timeout)
        except Exception as exc:  # any failure: logged and recorded, never "never retrieved"
            detail = (str(exc) if isinstance(exc, ControllerError | TimeoutError)
                      else f"{type(exc).__name__}: {exc}")
            reason = f"controller hold failed: {detail or f'no answer within {self.timeout:g} s'}"
            log.error("site %s: %s (the actuator keeps its last command only if the controller "
                      "does)", self.site.name, reason)
            self.site.event("controller-hold-failed", reason, step=self.site.step)

    # -- recovery -------------------------------------------------------------------------------
    async def recover(self, reason: str, deadline: float,
                      resend: tuple[float, ...] | None) -> str | None:
        """Probe the controller until ``deadline`` (loop time). ``None``: it answers again, the
        site is RUNNING (``recovered`` recorded); otherwise why the session must end (FAULT
        means an operator aborted meanwhile)."""
        site = self.site
        await asyncio.sleep(0)  # leave the eager path: asyncio.wait/timeouts need a task
        loop = asyncio.get_running_loop()
        start = loop.time()
        site.event("recovering", reason, step=site.step, window=round(deadline - start, 3))
        log.warning("site %s: controller lost at step %d (%s); the integrator's request waits "
                    "up to %.3g s for it to answer again ('fresco-bridge ctl abort --site %s' "
                    "ends it)", site.name, site.step + 1, reason, deadline - start, site.name)
        site.pending = resend if resend is not None else site.ctrl
        self.recovering_since = _time.monotonic()
        wake = self._wake = asyncio.Event()
        waker = loop.create_task(wake.wait(), name=f"{site.name}.recovery-wake")
        try:
            probed = await self._probe(reason, deadline, waker)
            if isinstance(probed, str):
                return probed
            daq, attempts = probed
            # the background hold() goes first: nothing else may talk to the controller
            holds = {t for t in self._background if not t.done()}
            while holds and not wake.is_set():
                await asyncio.wait((*holds, waker), return_when=asyncio.FIRST_COMPLETED)
                holds = {t for t in holds if not t.done()}
            if wake.is_set() or site.state is not HOLD:
                return f"recovery ended by the operator: the site is {site.state}"
            refused = None if resend is None else site.resend_refused(resend, daq.disp)
            if refused is not None:
                site.event("recovery-failed", refused, step=site.step, attempts=attempts)
                return refused
            elapsed = loop.time() - start
            then = ("the same setpoint " + str(list(resend)) + " mm is sent once over the "
                    "verified link" if resend is not None else "the measurement is read again")
            site.recovered(f"controller answers again after {elapsed:.3g} s ({attempts} "
                           f"probe(s)); {then}", step=site.step, attempts=attempts,
                           elapsed=round(elapsed, 3), measured=list(daq.disp))
            log.warning("site %s: controller answers again after %.3g s; HOLD → RUNNING, %s",
                        site.name, elapsed, then)
            return None
        finally:
            waker.cancel()
            self._wake = None
            site.pending = None
            self.recovering_since = None

    async def _probe(self, reason: str, deadline: float,
                     waker: asyncio.Task[bool]) -> tuple[Daq, int] | str:
        """Probe with jittered backoff until an answer (its measurement and the attempts) or
        why not (deadline, operator, an unhealthy controller)."""
        site = self.site
        loop = asyncio.get_running_loop()
        start = loop.time()
        backoff = Backoff(*PROBE_BACKOFF)
        attempts, last, next_log = 0, "none yet", start + RECOVERY_LOG_INTERVAL
        while True:
            remaining = deadline - loop.time()
            if site.state is not HOLD:
                return f"recovery ended: the site is {site.state} ({site.reason})"
            if remaining <= 0.0:
                why = (f"controller did not answer again within controller_recovery "
                       f"{self.recovery:g} s after: {reason} ({attempts} probe(s); last: "
                       f"{last})")
                site.event("recovery-failed", why, step=site.step, attempts=attempts)
                return why
            if loop.time() >= next_log:
                next_log += RECOVERY_LOG_INTERVAL
                log.warning("site %s: still waiting for the controller after %.0f s (%d "
                            "probe(s); last: %s); %.0f s left", site.name, loop.time() - start,
                            attempts, last, remaining)
            attempts += 1
            probe = loop.create_task(self.controller.get_daq(), name=f"{site.name}.probe")
            # what a ``finally`` would do, without an ``await`` in one: mypyc (2.4.1) lets an
            # exception raised by an await inside a ``finally`` past the handlers there
            try:
                await asyncio.wait((probe, waker), timeout=min(self.timeout, remaining),
                                   return_when=asyncio.FIRST_COMPLETED)
            except BaseException:
                await _drop(probe)
                raise
            await _drop(probe)
            if self._wake is not None and self._wake.is_set():  # an operator acted: abort
                return f"recovery ended by the operator: the site is {site.state}"
            try:
                return probe.result(), attempts
            except (asyncio.CancelledError, TimeoutError):
                last = f"no answer within {min(self.timeout, remaining):.3g} s"
            except ControllerLinkError as exc:
                last = str(exc)
            except ControllerError as exc:  # it answers, but not as a healthy controller
                why = f"controller answers again but not healthy: {exc}"
                site.event("recovery-failed", why, step=site.step, attempts=attempts)
                return why
            backoff.failed()
            with contextlib.suppress(TimeoutError):
                async with asyncio.timeout(min(backoff.wait_time(),
                                               max(0.0, deadline - loop.time()))):
                    await asyncio.shield(waker)


async def _drop(probe: asyncio.Task[Daq]) -> None:
    """A probe still running is cancelled and awaited (a read: cancelling it is harmless, the
    link is dropped)."""
    if not probe.done():
        probe.cancel()
        with contextlib.suppress(asyncio.CancelledError, Exception):
            await probe
