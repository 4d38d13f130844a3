"""An experimental site: trial → setup → safety → controller → daq → out.

The site outlives connections: it owns the controller, the limits and the state machine of
``safety.states`` (IDLE / RUNNING / PAUSED / HOLD / FAULT, one table). A non-finite trial, a
limit violation under ``reject``, a measured force past its daq limit, a controller failure or
timeout, or an integrator lost with an uncommitted command puts it in HOLD: nothing more is
forwarded, requests are answered NaN so the integrator stops, and the reason is logged,
recorded and published. A controller that is only lost or silent is waited for inside the
request instead (``recovery``, up to ``controller_recovery`` s): the run goes on with fresh data
or the integrator is told to stop (NaN answers until its DIE), never answered from a stale
measurement. PAUSED makes the integrator's next command wait for an operator; FAULT (operator
abort) tells the integrator to stop the same way and refuses new sessions until resumed.

A run record that cannot be written (a full disk, less than ``record.min_free_mb`` free, an
I/O error) is a fault of the site: the step whose commit failed does not count, the site HOLDs,
the integrator is told to stop and its session is ended after ``ABORT_GRACE`` s if it does not
leave by itself; new clients are refused (``claim``) until the record can be written again.
"""

from __future__ import annotations

import asyncio
import contextlib
import logging
import math
import time as _time
from collections.abc import Callable
from typing import TYPE_CHECKING

from protocol import Signals, SignalSizes

from ..controls.base import Controller, Daq, InlineController
from ..logs import cause_of
from ..record import RecordError, RunRecord
from ..record.site import SiteRecorder
from ..safety import (
    Limiter,
    LimitHit,
    SiteState,
    TransitionRefused,
    Trigger,
    all_finite,
    next_state,
)
from ..setups import Setup, make_setup
from ..site_output import CommittedStep, SiteNotice
from ..tangent import TangentEstimate, TangentMethod
from ..telemetry.schema import CorrectionSample, SiteStatus
from .base import Later, SiteError
from .correcting import SiteCorrection
from .gate import CommandGate
from .guard import ControllerGuard
from .listeners import EventListener, Listeners, StepListener
from .site_config import SiteConfigBase
from .sizes import column_major, size_problems

if TYPE_CHECKING:
    from ..telemetry.metrics import SiteMetrics
    from .access import RejectionLog

log = logging.getLogger("fresco_bridge.site")

ABORT_GRACE = 5.0
"""After ``ctl abort`` the session's next request is answered NaN (the integrator stops and
sends DIE); a session still open this many seconds later is ended by the bridge (an idle or
half-open client cannot keep an aborted site)."""

RUNNING, PAUSED, HOLD, FAULT = SiteState.RUNNING, SiteState.PAUSED, SiteState.HOLD, SiteState.FAULT


class ExperimentalSite:
    """One site: config, setup, limits, controller (behind its guard), state, the current
    session's signals, and the listeners its committed steps and events go to."""

    def __init__(
        self,
        cfg: SiteConfigBase,
        controller: Controller,
        record: RunRecord | None,
        *,
        controller_timeout: float,
        controller_recovery: float = 0.0,
    ) -> None:
        self.cfg = cfg
        self.name = cfg.name
        self.controller = controller
        self._reset_on_new_session = bool(getattr(getattr(cfg, "controller", None),
                                                  "reset_on_new_session", False))
        """``[sites.controller] reset_on_new_session``: a new session starts a fresh specimen
        (not the session that continues a resumed run)."""
        self._tangent_method: TangentMethod = getattr(cfg, "tangent", "controller")
        """``[[sites]] tangent`` of an experimental site (``tangent.py``); a kind without the
        key (a twin) answers its controller's tangent."""
        self.setup: Setup = make_setup(cfg.setup, cfg.dofs)
        self._plain = self.setup.identity
        """ctrl = trial, out = daq (T = I, no tracking-error spread): the step path skips the
        setup's calls."""
        if self.setup.n_actuators != controller.n_actuators:
            raise SiteError(
                f"site {cfg.name}: setup {cfg.setup} needs {self.setup.n_actuators} actuator(s), "
                f"the controller has {controller.n_actuators}"
            )
        self.guard = ControllerGuard(self, controller, timeout=controller_timeout,
                                     recovery=controller_recovery)
        self._now = controller if isinstance(controller, InlineController) else None
        """The controller's synchronous calls, when it is in process (the eager hot path)."""
        self.state = SiteState.IDLE
        self.reason = ""
        self.session = 0
        self.peer = ""  # the client holding the site (its session's, or a claim's)
        self.in_session = False
        self.damping = column_major(cfg.damping, cfg.dofs)
        self.mass = column_major(cfg.mass, cfg.dofs)
        self.holds = 0
        self.metrics: SiteMetrics | None = None  # set by the bridge when /metrics is served
        self.listeners = Listeners()
        """Who takes the committed steps, events and forwarded trials of this site."""
        self.recorder = None if record is None else SiteRecorder(record, cfg.name)
        """The one writer of this site's lines in the run record (None: recording off)."""
        if self.recorder is not None:
            self.add_listener(self.recorder)
            self.recorder.failed = self.record_failed
        limiter = Limiter([c.to_limits() for c in cfg.limits], self.setup.n_actuators) \
            if cfg.limits else None
        self.limiter = limiter
        self.gate = CommandGate(self, limiter, inline=self._now is not None)
        """The limits and the operator's pause between a target and the controller."""
        self._ctrl_limiter = self.gate.limiter
        self._daq_limiter = limiter if limiter is not None and limiter.has_daq else None
        self.paused_since: float | None = None
        self.pending: tuple[float, ...] | None = None  # waits for an operator or a recovery
        self._end_session: Callable[[str], None] | None = None  # the transport's, per session
        self._resume_at: tuple[int, float] | None = None  # (step, time) of a resumed run
        self.rejections: RejectionLog | None = None  # refused connections (set by the listener)
        self._reset_signals()
        correction = getattr(cfg, "correction", None)
        self.correction: SiteCorrection | None = None if correction is None \
            else SiteCorrection(self, correction)
        """``[sites.correction]``: every trial is corrected (``correcting.py``); None: the
        direct path."""

    # -- sessions ------------------------------------------------------------------------------
    def _reset_signals(self) -> None:
        n, na = self.cfg.dofs, self.setup.n_actuators
        self.step = self._session_first_step = 0
        self.time = 0.0
        self.commit_time = 0.0
        self.trial = Signals(disp=(0.0,) * n, vel=(0.0,) * n, accel=(0.0,) * n, time=(0.0,))
        self.target: tuple[float, ...] = (0.0,) * na  # what the integrator asked for (ctrl)
        self.ctrl: tuple[float, ...] = (0.0,) * na  # what the controller was sent last
        self.guard.sent = None
        self._uncommitted = False
        self.daq = Daq((0.0,) * na, (0.0,) * na)
        self._daq_valid = False
        self._acquiring: asyncio.Future[Daq] | None = None
        """The controller read in flight (network controllers): one read per trial, whoever
        asks (the site's own force request, or a trial listener reading the published
        trial's measurement)."""
        self._k_tangent: tuple[float, ...] = (0.0,) * (n * n)
        self._estimate = TangentEstimate(self._tangent_method, na)  # per session
        self._k_initial: tuple[float, ...] | None = None
        self.stop_reason: str | None = None  # set: this session's answers are NaN

    @property
    def resets_on_new_session(self) -> bool:
        return self._reset_on_new_session

    @property
    def busy(self) -> bool:
        return self.peer != ""

    def claim(self, peer: str) -> None:
        """Refuse ``peer`` (SiteError) if the site cannot take a session now (busy, a state
        that accepts none). Nothing is held: the site becomes the client's only when it
        introduces itself (``open_session``, sizes that fit), so a connection that never
        completes its size ID keeps nobody out. Nothing is logged or recorded."""
        if self.busy:
            raise SiteError(f"site {self.name} is busy with {self.peer} (one client per site)")
        self._check_accepting(peer)

    def _check_accepting(self, peer: str) -> None:
        try:
            next_state(self.state, Trigger.SESSION_OPEN, False)
        except TransitionRefused as exc:
            raise SiteError(f"site {self.name} is in {self.state} ({self.reason}); not accepting "
                            f"client {peer}: {exc}") from None
        if self.recorder is not None:
            failure = self.recorder.check_writable()
            if self.metrics is not None:
                self.metrics.record_writable(failure is None)
            if failure is not None:
                raise SiteError(f"site {self.name} is not accepting client {peer}: {failure}")

    def record_failed(self, error: RecordError) -> None:
        """The run record could not take a line of this site: HOLD (the controller holds, the
        integrator is told to stop) and end the session if it does not end by itself. Outside
        a session, or once held, only the metrics and ``ctl status`` say it."""
        if self.metrics is not None:
            self.metrics.record_writable(False)
        if not self.in_session or not (self.state is RUNNING or self.state is PAUSED):
            return
        self.enter_hold(f"{error}; step {self.step + 1} not committed")
        self._end_session_later(self.session, f"the run record cannot be written ({error}); the "
                                f"client did not leave within {ABORT_GRACE:g} s")

    def open_session(self, peer: str) -> int:
        """Open ``peer``'s session: the site is its from now on (``claim``'s checks first)."""
        self.claim(peer)
        self.session += 1
        self._reset_signals()
        resumed = self._resume_at is not None
        if self._resume_at is not None:  # the first session after a crash: it goes on (its
            self.step, self.time = self._resume_at  # numbering; the specimen is not reset)
            self.commit_time = self.time
            self._resume_at = None
        self._session_first_step = self.step  # the close line counts the session's own steps
        reset = getattr(self.controller, "reset", None)
        if reset is not None and self._reset_on_new_session and not resumed:
            reset()
            self.gate.reference = None
        log.info("site %s: session %d opened by %s", self.name, self.session, peer)
        self.transition(Trigger.SESSION_OPEN, f"client {peer} connected", peer=peer)
        self.peer, self.in_session = peer, True
        return self.session

    def close_session(self, reason: str, *, error: bool = False) -> bool:
        """End the session (True); False if none is open."""
        if not self.in_session:
            self.peer, self._end_session = "", None
            return False
        (log.warning if error else log.info)(
            "site %s: session %d closed after %d step(s)%s: %s", self.name, self.session,
            self.step - self._session_first_step, f" (steps {self._session_first_step + 1}-"
            f"{self.step} of the resumed run)" if self._session_first_step else "", reason,
        )
        if self._uncommitted and self.state in (RUNNING, PAUSED):
            self._enter(Trigger.INTEGRATOR_LOST,
                        f"integrator session ended with an uncommitted command at step "
                        f"{self.step + 1} ({reason})")
        self.transition(Trigger.SESSION_CLOSE, reason, steps=self.step, error=error)
        self.peer, self.in_session, self._end_session = "", False, None
        return True

    def resume_from(self, session: int, step: int, time: float) -> None:
        """A resumed run: the next session is ``session + 1`` and starts after committed
        ``step`` (pseudo-time ``time``). Nothing is sent to the controller here: the first
        command is the client's, checked against the measured position."""
        self.session = session
        self._resume_at = (step, time)
        self.step, self.time = step, time  # what ``ctl status`` shows until the session opens
        self.event("resumed", f"run resumed after an interruption: site {self.name} continues "
                    f"from committed step {step} (t = {time:g} s) with session {session + 1}",
                    step=step, time=time)

    def attach_session_end(self, end: Callable[[str], None]) -> None:
        """The open session's transport: how the bridge itself ends it (abort, deadline)."""
        self._end_session = end

    def _end_session_later(self, session: int, reason: str) -> None:
        """End ``session`` after ``ABORT_GRACE`` s if it is still open (an idle client)."""
        def end() -> None:
            if self.session == session and self.peer and self._end_session is not None:
                log.warning("site %s: session %d still open %g s after the abort: ended",
                            self.name, session, ABORT_GRACE)
                self._end_session(reason)

        with contextlib.suppress(RuntimeError):  # no loop (the site alone): nothing to end
            asyncio.get_running_loop().call_later(ABORT_GRACE, end)

    def record_refusal(self, message: str, **extra: object) -> None:
        """A refused connection (counted and logged by the transport) goes into the record."""
        if self.recorder is not None:
            self.recorder.event(self.session, "refused", message, **extra)

    def check_sizes(self, ctrl: SignalSizes, daq: SignalSizes, who: str) -> None:
        """OpenFresco's rule: every non-zero size equals the element's DOFs, time sizes are 1."""
        problems = size_problems(self.cfg.dofs, ctrl, daq)
        if problems:
            raise SiteError(f"{who} sizes do not fit site {self.name}: " + "; ".join(problems))

    # -- states --------------------------------------------------------------------------------
    def transition(self, trigger: Trigger, reason: str, **extra: object) -> SiteState:
        """Move along ``safety.states.TRANSITIONS``; record and publish it with its reason."""
        old = self.state
        new = next_state(old, trigger, self.in_session)
        self.state = new
        if new is not old:
            self.reason = reason if new in (PAUSED, HOLD, FAULT) else ""
            self.paused_since = _time.monotonic() if new is PAUSED else None
        entered_hold = new is HOLD and old is not HOLD
        if entered_hold:
            self.holds += 1  # counted before the event: the status sent with it includes it
        kind = "hold" if entered_hold else str(trigger)
        self.event(kind, reason, cause=str(trigger), **{"from": str(old), "to": str(new)},
                   **extra)
        return new

    def _enter(self, trigger: Trigger, reason: str) -> None:
        """A fault trigger (HOLD, integrator lost): never raises, HOLDs the controller."""
        if self.state is HOLD or self.state is FAULT:
            log.warning("site %s: %s while in %s: %s", self.name, trigger, self.state, reason)
            return
        try:
            new = self.transition(trigger, reason, step=self.step)
        except TransitionRefused as exc:
            log.error("site %s: %s (%s)", self.name, exc, reason)
            return
        if new is HOLD:
            log.error("site %s: HOLD at step %d: %s", self.name, self.step, reason,
                      extra=cause_of(reason))  # one line per (site, cause) per interval
            self.guard.hold()
        else:
            log.warning("site %s: %s at step %d: %s (stays %s)", self.name, trigger, self.step,
                        reason, new)

    def enter_hold(self, reason: str) -> None:
        self._enter(Trigger.HOLD, reason)

    def recovered(self, reason: str, **extra: object) -> None:
        """HOLD → RUNNING: the guard's recovery found the controller answering again."""
        self.transition(Trigger.RECOVERED, reason, **extra)

    def _wake_waiter(self) -> None:
        self.gate.wake()
        self.guard.wake()

    # -- operator ------------------------------------------------------------------------------
    def operator_pause(self, source: str) -> str:
        """Stop forwarding at the next trial; the integrator's request waits for resume/abort."""
        if self.state is PAUSED:
            return f"site {self.name} is already PAUSED ({self.reason})"
        self.transition(Trigger.PAUSE, f"operator pause ({source})")
        log.warning("site %s: PAUSED by the operator (%s) at step %d; the next command waits "
                    "for 'fresco-bridge ctl resume' or 'abort'", self.name, source, self.step)
        return f"site {self.name} PAUSED at step {self.step}"

    def operator_resume(self, source: str) -> str:
        """PAUSED → RUNNING (the waiting command is checked again) or FAULT → IDLE."""
        old = self.state
        new = self.transition(Trigger.RESUME, f"operator resume ({source})")
        log.warning("site %s: %s → %s by the operator (%s)", self.name, old, new, source)
        self._wake_waiter()
        return f"site {self.name} {old} → {new}"

    def operator_abort(self, source: str) -> str:
        """FAULT: hold the controller, answer the session NaN (it stops), refuse new ones."""
        old = self.state
        self.transition(Trigger.ABORT, f"operator abort ({source})", step=self.step)
        log.error("site %s: ABORTED by the operator (%s) at step %d (was %s): controller held, "
                  "sessions refused until 'fresco-bridge ctl resume'", self.name, source,
                  self.step, old)
        self.guard.hold()
        self._wake_waiter()
        if self.peer:
            self._end_session_later(self.session, f"aborted by the operator ({source}); the "
                                    f"client sent no request within {ABORT_GRACE:g} s")
        return f"site {self.name} {old} → FAULT"

    def status(self) -> dict[str, object]:
        """A JSON-able snapshot for ``fresco-bridge ctl status``."""
        since = self.paused_since
        return {
            "site": self.name, "kind": self.cfg.kind, "state": str(self.state),
            "reason": self.reason,
            "session": self.session, "peer": self.peer or None, "step": self.step,
            "time": self.time, "target": list(self.target), "ctrl": list(self.ctrl),
            "daq_disp": list(self.daq.disp), "daq_force": list(self.daq.force),
            "pending": None if self.pending is None else list(self.pending),
            "paused_for": None if since is None else round(_time.monotonic() - since, 3),
            "recovering_for": None if self.guard.recovering_since is None
            else round(_time.monotonic() - self.guard.recovering_since, 3),
            "holds": self.holds, "limit_events": dict(self.gate.limit_counts),
            "record": None if self.recorder is None or self.recorder.failure is None
            else str(self.recorder.failure),
            "refused": {} if self.rejections is None else dict(self.rejections.counts),
            "limits": [c.model_dump(exclude_none=True) for c in self.cfg.limits],
            "correction": None if self.correction is None else self.correction.status(),
            **self.controller.status_fields(),
        }

    def tell_integrator_to_stop(self, why: str) -> None:
        """From now on this session's answers are NaN, until the client sends DIE or leaves.

        Closing the connection cannot stop OpenSees: its genericClient ignores a failed recv
        and spins at full CPU forever (observed). A NaN force can: Newton fails to converge
        (``analyze`` returns < 0, the script stops and sends DIE), a non-iterative scheme ends
        with NaN results — never a plausible run built on forces the specimen did not give.
        """
        if self.stop_reason is not None:
            return
        self.stop_reason = why
        log.error("site %s: %s; answering NaN from now on so the integrator stops (session %d, "
                  "step %d)", self.name, why, self.session, self.step)
        self.event("integrator-stop", f"answering NaN so the integrator stops: {why}",
                   step=self.step)

    def _stopping(self) -> bool:
        """True when this session can only be told to stop: HOLD (nothing is forwarded any more,
        so no true measurement can follow; a recoverable controller loss is waited out inside
        the request before any reply), FAULT (operator abort), or a failed recovery."""
        if self.stop_reason is None and self.in_session:
            if self.state is HOLD:
                self.tell_integrator_to_stop(f"HOLD ({self.reason})")
            elif self.state is FAULT:
                self.tell_integrator_to_stop(f"aborted by the operator ({self.reason})")
        return self.stop_reason is not None

    def _nan_signals(self, sizes: SignalSizes) -> Signals:
        nan = (math.nan,) * self.cfg.dofs
        return Signals(disp=nan if sizes.disp else (), vel=nan if sizes.vel else (),
                       accel=nan if sizes.accel else (), force=nan if sizes.force else (),
                       time=(self.time,) if sizes.time else ())

    # -- listeners ------------------------------------------------------------------------------
    def add_listener(self, listener: StepListener | EventListener) -> None:
        """Committed steps (``step_committed``), events (``site_event``) and/or forwarded
        trials (``trial_forwarded``) go to ``listener`` from now on, after the earlier ones."""
        self.listeners.add(listener)

    def forwarded(self) -> None:
        """``_forwarded`` for the correction, once its last command is reached."""
        self._forwarded()

    def _forwarded(self) -> None:
        """The current trial reached the controller: its listeners get it (and a way to read
        its one measurement)."""
        if self.listeners.trials and self.state is RUNNING:
            self.listeners.trial(SourceTrial(self, self.session, self.step + 1, self.time,
                                             self.ctrl))

    def status_now(self) -> SiteStatus:
        """The site's state for telemetry (retained status)."""
        return SiteStatus(site=self.name, state=str(self.state), session=self.session,
                          step=self.step, time=self.time, reason=self.reason, holds=self.holds)

    def event(self, kind: str, reason: str, **extra: object) -> None:
        """An event of this site (a state change, a limit hit, a fault…) to its listeners."""
        if self.listeners.events:
            self.listeners.event(SiteNotice(self.name, self.session, self.step, self.time, kind,
                                            reason, extra), self.status_now())

    def correction_sample(self) -> CorrectionSample | None:
        return None if self.correction is None else self.correction.sample(self.step)

    def monitor_warning(self, reason: str, step: int) -> None:
        """An online monitor's warning at committed ``step`` (the taps raise it)."""
        self.event("monitor-warning", reason, step=step)

    # -- the step ------------------------------------------------------------------------------
    # Each request has one implementation, ``*_eager``: it runs to the end at once when it can
    # (an in-process controller, called through ``guard.now``) and returns its result; when it
    # must wait (a controller on the network, an operator, a recovery) it returns a coroutine
    # (``Later``) that finishes it. The handlers call these; the coroutines of the same names
    # (``set_trial``…) are the API for everything else that drives a site.
    async def set_trial(self, trial: Signals) -> None:
        """Code 3: validate, transform, check limits, forward (see ``set_trial_eager``)."""
        later = self.set_trial_eager(trial)
        if later is not None:
            await later

    def set_trial_eager(self, trial: Signals) -> Later[None] | None:
        """Code 3: validate, transform, check limits, forward. Never forwards an unsafe command.

        In FAULT nothing happens here: the replies of the session are NaN from now on.
        """
        if self.state is FAULT:
            return None
        values = trial.disp + trial.vel + trial.accel + trial.time
        if not all_finite(values):
            if self.state is not HOLD:
                bad = [v for v in values if not math.isfinite(v)]
                self.enter_hold(f"non-finite trial value(s) {bad} (disp {list(trial.disp)}); "
                                "not forwarded to the controller")
            return None
        self.trial = trial
        if trial.time:
            self.time = trial.time[0]
        target = trial.disp if self._plain else self.setup.ctrl_disp(trial.disp)
        if not math.isfinite(sum(target)):  # finite trials whose transform overflows
            if self.state is not HOLD:
                self.enter_hold(f"setup {self.setup.kind} turned trial {list(trial.disp)} into "
                                f"non-finite ctrl {list(target)}; not forwarded")
            return None
        self.target = target
        if (stalled := self._estimate.trial(target)) is not None:
            self.event("tangent-fallback", stalled)
        if self.state is HOLD:
            return None
        self._daq_valid = False
        if self.correction is not None:
            return self.correction.trial(trial, target)
        if self.state is RUNNING and (self._ctrl_limiter is None
                                      or self.gate.clear_of_limits(target)):  # the hot path
            self.ctrl = target
            if self.recorder is not None:
                self.recorder.trial(self.session, self.step, self.time, trial.disp, target)
                if self.state is HOLD:  # the record failed (``record_failed``)
                    return None
            if target != self.guard.sent:
                if self._now is None:
                    return self._send_later(target)
                self._uncommitted = True
                self.guard.now("set_ctrl", self._now.set_ctrl_now, target)
                self._sent(target)
            if self.listeners.trials:
                self._forwarded()
            return None
        return self._gated(trial, target)

    async def _gated(self, trial: Signals, target: tuple[float, ...]) -> None:
        await self.gate.set_trial_later(trial, target)
        if self.guard.sent == self.ctrl:
            self._forwarded()

    async def _send_later(self, command: tuple[float, ...]) -> None:
        if await self.send(command):
            self._forwarded()

    async def send(self, command: tuple[float, ...]) -> bool:
        """One command to the controller; False if the site left RUNNING/PAUSED meanwhile."""
        self._uncommitted = True
        if self._now is not None:
            self.guard.now("set_ctrl", self._now.set_ctrl_now, command)
        else:
            await self.guard.guarded("set_ctrl", lambda: self.controller.set_ctrl(command),
                                     command)
        return self._sent(command)

    @property
    def sent(self) -> tuple[float, ...] | None:
        """The last setpoint the controller acknowledged in this session."""
        return self.guard.sent

    async def read_position(self) -> Daq | None:
        """A fresh measurement for the limits' reference (None: the controller failed)."""
        return await self.guard.guarded("get_daq (reference position)", self.controller.get_daq)

    def resend_refused(self, command: tuple[float, ...],
                       measured: tuple[float, ...]) -> str | None:
        """Why the guard may not re-send ``command`` from ``measured`` (the limits), or None."""
        return self.gate.resend_refused(command, measured)

    @property
    def limit_counts(self) -> dict[str, int]:
        """Limit hits by limit (``ctl status``, metrics)."""
        return self.gate.limit_counts

    def limit_event(self, hit: LimitHit, action: str) -> None:
        self.gate.limit_event(hit, action)

    def _sent(self, command: tuple[float, ...]) -> bool:
        """After ``command`` went to the controller (or failed: the site is in HOLD)."""
        if self.state is HOLD or self.state is FAULT:
            self.gate.reference = None  # where the actuator stopped is not known
            return False
        self.guard.sent = self.gate.reference = command
        return True

    async def measure(self) -> Daq | None:
        """A fresh measurement at the command the controller holds now, checked and recorded
        as any (the correction's read); None when the site is no longer RUNNING."""
        self._daq_valid = False
        daq = self.acquire_eager()
        if not isinstance(daq, Daq):
            daq = await daq
        return daq if self.state is RUNNING else None

    def acquire_eager(self) -> Daq | Later[Daq]:
        """The measurement for the current command, acquired once per trial."""
        if self._daq_valid or self.state is HOLD:
            return self.daq
        if self._now is not None:
            return self._measured(self.guard.now("get_daq", self._now.get_daq_now))
        return self._acquire_later()

    async def _acquire_later(self) -> Daq:
        pending = self._acquiring
        if pending is not None:
            try:
                return await asyncio.shield(pending)
            except asyncio.CancelledError:
                task = asyncio.current_task()
                if not pending.cancelled() or (task is not None and task.cancelling()):
                    raise  # this caller is cancelled, not the read it waited for
            return await self._acquire_later()  # that read was abandoned: its own
        fut: asyncio.Future[Daq] = asyncio.get_running_loop().create_future()
        self._acquiring = fut
        try:
            daq = self._measured(await self.guard.guarded("get_daq", self.controller.get_daq))
        except BaseException:
            fut.cancel()  # a caller waiting on it reads again
            raise
        finally:
            self._acquiring = None
        fut.set_result(daq)
        return daq

    def _measured(self, daq: Daq | None) -> Daq:
        """Check and record what the controller measured (None: it failed, the site HOLDs)."""
        if daq is None:
            return self.daq
        if not (all_finite(daq.disp) and all_finite(daq.force)):
            self.enter_hold(f"controller returned non-finite measurements {daq}")
            return self.daq
        if self._daq_limiter is not None:
            hit = self._daq_limiter.check_daq(daq.force)
            if hit is not None:
                if self.recorder is not None:  # a real measurement: keep it in the record
                    self.recorder.measurement(self.session, self.step, daq.disp, daq.force)
                self.gate.limit_event(hit, "hold")
                self.enter_hold(f"daq limit exceeded: {hit.describe()}")
                return self.daq
        self.daq = daq
        self._daq_valid = True
        if self.recorder is not None:
            self.recorder.measurement(self.session, self.step, daq.disp, daq.force)
        return daq

    async def commit(self) -> None:
        """Code 5 (see ``commit_eager``)."""
        later = self.commit_eager()
        if later is not None:
            await later

    def commit_eager(self) -> Later[None] | None:
        """Code 5 (also while PAUSED: it completes a step already forwarded)."""
        if self.state is HOLD or self.state is FAULT:
            return None
        daq = self.acquire_eager()  # every committed step has its measurement in the record
        if not isinstance(daq, Daq):
            return self._commit_later(daq)
        if self.state is HOLD:
            return None
        if self._now is None:
            return self._commit_later(None)
        self.guard.now("commit", self._now.commit_now)
        self._committed()
        return None

    async def _commit_later(self, daq: Later[Daq] | None) -> None:
        if daq is not None:
            await daq
            if self.state is HOLD:
                return
        if self._now is not None:
            self.guard.now("commit", self._now.commit_now)
        else:
            await self.guard.guarded("commit", self.controller.commit)
        self._committed()

    def _committed(self) -> None:
        """The controller committed (or failed to: then the site is in HOLD): the step counts."""
        self.step += 1
        self._uncommitted = False
        commit_time, self.commit_time = self.commit_time, self.time
        if (refused := self._estimate.committed(self.ctrl, self.daq.force)) is not None:
            self.event("tangent-fallback", refused)
        outlets = self.listeners
        lean = outlets.step_values
        try:
            if lean is not None:  # the record and its monitor: no CommittedStep to build
                session, step, time_, ctrl, disp = (self.session, self.step, self.time,
                                                    self.ctrl, self.daq.disp)
                for listener_values in lean:
                    listener_values(session, step, time_, ctrl, disp)
            elif outlets.steps:
                committed = CommittedStep(self.name, self.session, self.step, self.time,
                                          self.trial.disp, self.ctrl, self.daq.disp,
                                          self.daq.force, str(self.state))
                for listener in outlets.steps:
                    listener.step_committed(committed)
        except RecordError as exc:  # the record is the first listener: nobody saw the step
            self.step -= 1
            self.commit_time = commit_time
            self.record_failed(exc)

    async def out_signals(self, sizes: SignalSizes) -> Signals:
        """Measured signals in basic DOFs (see ``out_signals_eager``)."""
        out = self.out_signals_eager(sizes)
        return out if isinstance(out, Signals) else await out

    def out_signals_eager(self, sizes: SignalSizes) -> Signals | Later[Signals]:
        """Measured signals in basic DOFs (OpenFresco *out*), blocks as the client sized them;
        NaN once the integrator must stop (see ``_tell_integrator_to_stop``)."""
        if self._stopping():
            return self._nan_signals(sizes)
        daq = self.acquire_eager()
        if not isinstance(daq, Daq):
            return self._out_later(daq, sizes)
        return self._out(daq, sizes)

    async def _out_later(self, daq: Later[Daq], sizes: SignalSizes) -> Signals:
        return self._out(await daq, sizes)

    def _out(self, daq: Daq, sizes: SignalSizes) -> Signals:
        # the acquisition may have HOLDed the site: ``_stopping`` decides then (it answers
        # False whenever this first test does)
        if (self.stop_reason is not None or self.state is HOLD or self.state is FAULT) \
                and self._stopping():
            return self._nan_signals(sizes)
        trial, setup, plain = self.trial, self.setup, self._plain
        return Signals(  # disp, vel, accel, force, time: each block the client sized
            (daq.disp if plain else setup.out_disp(trial.disp, self.target, daq.disp))
            if sizes.disp else (),
            trial.vel if sizes.vel else (),
            trial.accel if sizes.accel else (),
            (daq.force if plain else setup.basic_force(daq.force, daq.disp))
            if sizes.force else (),
            (self.time,) if sizes.time else (),
        )

    def stopping(self) -> bool:
        """True when this session's answers are NaN, the constant ones (damping, mass) too."""
        return self._stopping()

    async def tangent(self) -> tuple[float, ...]:
        """Tangent in basic DOFs (see ``tangent_eager``)."""
        k = self.tangent_eager()
        return k if isinstance(k, tuple) else await k

    def tangent_eager(self) -> tuple[float, ...] | Later[tuple[float, ...]]:
        """Tangent in basic DOFs (the last good one if the controller cannot give it); NaN
        when the integrator must stop."""
        if self._stopping():
            return (math.nan,) * (self.cfg.dofs ** 2)
        if self.state is HOLD:
            return self._k_tangent
        if self._now is None:
            return self._tangent_later()
        return self._tangent_from(self.guard.now("tangent_stiffness",
                                                 self._now.tangent_stiffness_now))

    async def _tangent_later(self) -> tuple[float, ...]:
        return self._tangent_from(await self.guard.guarded(
            "tangent_stiffness", self.controller.tangent_stiffness))

    def _tangent_from(self, k: tuple[float, ...] | None) -> tuple[float, ...]:
        if k is not None:
            self._k_tangent = self.setup.basic_matrix(self._estimate.answer(k))
        return self._k_tangent

    async def initial(self) -> tuple[float, ...]:
        if self._stopping():
            return (math.nan,) * (self.cfg.dofs ** 2)
        if self._k_initial is None or self.state is not HOLD:
            k = (self.guard.now("initial_stiffness", self._now.initial_stiffness_now)
                 if self._now is not None else
                 await self.guard.guarded("initial_stiffness", self.controller.initial_stiffness))
            if k is not None:
                self._k_initial = self.setup.basic_matrix(k)
        return self._k_initial if self._k_initial is not None else self._k_tangent


class SourceTrial:
    """A trial of an ``ExperimentalSite`` as its trial listeners get it (``ForwardedTrial``):
    its step, time and command, and its one measurement, read through the site's
    single-flight acquisition while it is the site's current trial."""

    __slots__ = ("_site", "ctrl", "session", "step", "time")

    def __init__(self, site: ExperimentalSite, session: int, step: int, time: float,
                 ctrl: tuple[float, ...]) -> None:
        self._site = site
        self.session, self.step, self.time, self.ctrl = session, step, time, ctrl

    def _current(self) -> bool:
        site = self._site
        return (site.state is RUNNING and site.session == self.session
                and site.step + 1 == self.step and site.time == self.time
                and site.ctrl == self.ctrl and site.guard.sent == self.ctrl)

    async def read(self) -> Daq | None:
        if not self._current():
            return None
        daq = self._site.acquire_eager()
        if not isinstance(daq, Daq):
            daq = await daq
        return daq if self._current() else None
