"""Controller recovery: a HOLD for a lost or silent controller, bounded by
``bridge.controller_recovery``.

It runs inside the integrator's request that hit the fault, so the integrator simply waits
(OpenSees blocks in its socket read): no answer is ever made up from a stale measurement.
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
from typing import TYPE_CHECKING

from ..controls._link import Backoff
from ..controls.base import ControllerError, ControllerLinkError, Daq
from ..safety import SiteState, Trigger

if TYPE_CHECKING:
    from .experimental import ExperimentalSite

log = logging.getLogger("fresco_bridge.site")

RECOVERY_LOG_INTERVAL = 5.0
"""While a site waits for a lost controller, a warning is logged this often (s)."""
PROBE_BACKOFF = (0.05, 1.0)
"""Jittered exponential delay between probes, s (capped so a returning controller is seen
within about a second)."""

HOLD, FAULT = SiteState.HOLD, SiteState.FAULT


async def recover(site: ExperimentalSite, reason: str, deadline: float,
                  resend: tuple[float, ...] | None) -> str | None:
    """Probe the controller until ``deadline`` (loop time). ``None``: it answers again, the
    site is RUNNING (``recovered`` recorded); otherwise why the session must end (the caller
    records nothing more than its error; FAULT means an operator aborted meanwhile)."""
    await asyncio.sleep(0)  # leave the eager path: asyncio.wait/timeouts need a task
    loop = asyncio.get_running_loop()
    start = loop.time()
    window = deadline - start
    site._event("recovering", reason, step=site.step, window=round(window, 3))
    log.warning("site %s: controller lost at step %d (%s); the integrator's request waits up to "
                "%.3g s for it to answer again ('fresco-bridge ctl abort --site %s' ends it)",
                site.name, site.step + 1, reason, window, site.name)
    site.pending = resend if resend is not None else site.ctrl
    site.recovering_since = _time.monotonic()
    wake = site._wake = asyncio.Event()
    waker = loop.create_task(wake.wait(), name=f"{site.name}.recovery-wake")
    backoff = Backoff(*PROBE_BACKOFF)
    attempts, last, next_log = 0, "none yet", start + RECOVERY_LOG_INTERVAL
    daq: Daq | None = None
    try:
        while daq is None:
            remaining = deadline - loop.time()
            if site.state is not HOLD:
                return f"recovery ended: the site is {site.state} ({site.reason})"
            if remaining <= 0.0:
                why = (f"controller did not answer again within controller_recovery "
                       f"{site.recovery:g} s after: {reason} ({attempts} probe(s); last: "
                       f"{last})")
                site._event("recovery-failed", why, step=site.step, attempts=attempts)
                return why
            if loop.time() >= next_log:
                next_log += RECOVERY_LOG_INTERVAL
                log.warning("site %s: still waiting for the controller after %.0f s (%d "
                            "probe(s); last: %s); %.0f s left", site.name, loop.time() - start,
                            attempts, last, remaining)
            attempts += 1
            probe = loop.create_task(site.controller.get_daq(), name=f"{site.name}.probe")
            try:
                await asyncio.wait((probe, waker), timeout=min(site.timeout, remaining),
                                   return_when=asyncio.FIRST_COMPLETED)
            finally:
                if not probe.done():
                    probe.cancel()  # a read: cancelling it is harmless (the link is dropped)
                    with contextlib.suppress(asyncio.CancelledError, Exception):
                        await probe
            if wake.is_set():  # an operator aborted: the caller sees FAULT
                return f"recovery ended by the operator: the site is {site.state}"
            try:
                daq = probe.result()
            except (asyncio.CancelledError, TimeoutError):
                last = f"no answer within {min(site.timeout, remaining):.3g} s"
            except ControllerLinkError as exc:
                last = str(exc)
            except ControllerError as exc:  # it answers, but not as a healthy controller
                why = f"controller answers again but not healthy: {exc}"
                site._event("recovery-failed", why, step=site.step, attempts=attempts)
                return why
            if daq is None:
                backoff.failed()
                with contextlib.suppress(TimeoutError):
                    async with asyncio.timeout(min(backoff.wait_time(),
                                                   max(0.0, deadline - loop.time()))):
                        await asyncio.shield(waker)
        # the background hold() goes first: nothing else may talk to the controller meanwhile
        holds = {t for t in site._background if not t.done()}
        while holds and not wake.is_set():
            await asyncio.wait((*holds, waker), return_when=asyncio.FIRST_COMPLETED)
            holds = {t for t in holds if not t.done()}
        if wake.is_set() or site.state is not HOLD:
            return f"recovery ended by the operator: the site is {site.state}"
        refused = _limits_refuse(site, resend, daq)
        if refused is not None:
            site._event("recovery-failed", refused, step=site.step, attempts=attempts)
            return refused
        elapsed = loop.time() - start
        then = ("the same setpoint " + str(list(resend)) + " mm is sent once over the verified "
                "link" if resend is not None else "the measurement is read again")
        site._transition(Trigger.RECOVERED,
                         f"controller answers again after {elapsed:.3g} s ({attempts} probe(s));"
                         f" {then}", step=site.step, attempts=attempts,
                         elapsed=round(elapsed, 3), measured=list(daq.disp))
        log.warning("site %s: controller answers again after %.3g s; HOLD → RUNNING, %s",
                    site.name, elapsed, then)
        return None
    finally:
        waker.cancel()
        site._wake = None
        site.pending = None
        site.recovering_since = None


def _limits_refuse(site: ExperimentalSite, resend: tuple[float, ...] | None,
                   daq: Daq) -> str | None:
    """Why ``resend`` may not go from where the actuator was measured, or None."""
    limiter = site._ctrl_limiter
    if resend is None or limiter is None:
        return None
    verdict = limiter.check_ctrl(resend, daq.disp, site.time - site._commit_time)
    if verdict is None:
        return None
    what = verdict.describe() or (f"the move needs {len(verdict.commands)} sub-commands under "
                                  "the velocity limit")
    return (f"controller answers again with the actuator at {list(daq.disp)} mm; re-sending "
            f"{list(resend)} mm from there is not within the limits ({what}); not sent")
