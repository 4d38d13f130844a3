"""The site core: what every site kind does alike, composed into each kind's site.

Sessions (claim, open, close, the transport's end, a resumed run), the state table of
``safety.states`` with its HOLD/FAULT entries, the operator's pause/resume/abort, the NaN stop
(``tell_integrator_to_stop``), the listeners with the run record's writer first, the telemetry
status and ``ctl status``'s shared fields. A kind owns its step path (trial → … → out) and
holds one ``SiteCore``; what the core needs back of it is ``StepPath``: where the step is, how
to hold and wake its controller, a new session's signals, its own status fields. No kind
inherits the core nor is named by it, so a second kind (the twin serves through the
experimental step path with its own controller) cannot drift from the first.
"""

from __future__ import annotations

import asyncio
import contextlib
import logging
import math
import time as _time
from collections.abc import Callable
from typing import TYPE_CHECKING, Protocol

from protocol import Signals, SignalSizes

from ..logs import cause_of
from ..record import RecordError, RunRecord
from ..record.site import SiteRecorder
from ..safety import SiteState, TransitionRefused, Trigger, next_state
from ..site_output import SiteNotice
from ..telemetry.schema import SiteStatus
from .base import SiteError
from .listeners import EventListener, Listeners, StepListener
from .site_config import SiteConfigBase
from .sizes import column_major, size_problems

if TYPE_CHECKING:
    from ..telemetry.metrics import SiteMetrics
    from .access import RejectionLog

__all__ = ["ABORT_GRACE", "SiteCore", "StepPath"]

log = logging.getLogger("fresco_bridge.site")

ABORT_GRACE = 5.0
"""After ``ctl abort`` the session's next request is answered NaN (the integrator stops and
sends DIE); a session still open this many seconds later is ended by the bridge (an idle or
half-open client cannot keep an aborted site)."""

RUNNING, PAUSED, HOLD, FAULT = SiteState.RUNNING, SiteState.PAUSED, SiteState.HOLD, SiteState.FAULT


class StepPath(Protocol):
    """What the core needs of its kind's step path."""

    step: int
    """The last committed step (of the current or last session)."""
    time: float
    uncommitted: bool
    """A command went to the controller since the last commit."""

    def new_session(self, resume_at: tuple[int, float] | None) -> None:
        """A session opens: fresh signals, from ``(step, time)`` of a resumed run if given
        (then the specimen goes on), else from rest (a fresh specimen if configured)."""
        ...

    def hold(self) -> None:
        """The site entered HOLD or FAULT: the controller holds its position."""
        ...

    def wake(self) -> None:
        """An operator acted: a request waiting for one (a pause, a recovery) checks again."""
        ...

    def status_fields(self) -> dict[str, object]:
        """The kind's part of ``ctl status`` (its signals, limits, controller)."""
        ...


class SiteCore:
    """The state, session and outlets of one site (any kind)."""

    def __init__(self, cfg: SiteConfigBase, record: RunRecord | None, path: StepPath) -> None:
        self.cfg = cfg
        self.name = cfg.name
        self.path = path
        self.state = SiteState.IDLE
        self.reason = ""
        self.session = 0
        self.peer = ""  # the client holding the site (its session's, or a claim's)
        self.in_session = False
        self.first_step = 0
        """The session's first step: the close line counts the session's own steps."""
        self.damping = column_major(cfg.damping, cfg.dofs)
        self.mass = column_major(cfg.mass, cfg.dofs)
        self.holds = 0
        self.metrics: SiteMetrics | None = None  # set by the bridge when /metrics is served
        self.rejections: RejectionLog | None = None  # refused connections (set by the listener)
        self.listeners = Listeners()
        """Who takes the committed steps, events and forwarded trials of this site."""
        self.recorder = None if record is None else SiteRecorder(record, cfg.name)
        """The one writer of this site's lines in the run record (None: recording off)."""
        if self.recorder is not None:
            self.listeners.add(self.recorder)
            self.recorder.failed = self.record_failed
        self.paused_since: float | None = None
        self.pending: tuple[float, ...] | None = None  # waits for an operator or a recovery
        self.stop_reason: str | None = None  # set: this session's answers are NaN
        self._end_session: Callable[[str], None] | None = None  # the transport's, per session
        self._resume_at: tuple[int, float] | None = None  # (step, time) of a resumed run

    # -- sessions ------------------------------------------------------------------------------
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
        self.enter_hold(f"{error}; step {self.path.step + 1} not committed")
        self._end_session_later(self.session, f"the run record cannot be written ({error}); the "
                                f"client did not leave within {ABORT_GRACE:g} s")

    def open_session(self, peer: str) -> int:
        """Open ``peer``'s session: the site is its from now on (``claim``'s checks first)."""
        self.claim(peer)
        self.session += 1
        self.stop_reason = None
        resume_at, self._resume_at = self._resume_at, None
        self.path.new_session(resume_at)  # the first session after a crash goes on
        self.first_step = self.path.step
        log.info("site %s: session %d opened by %s", self.name, self.session, peer)
        self.transition(Trigger.SESSION_OPEN, f"client {peer} connected", peer=peer)
        self.peer, self.in_session = peer, True
        return self.session

    def close_session(self, reason: str, *, error: bool = False) -> bool:
        """End the session (True); False if none is open."""
        if not self.in_session:
            self.peer, self._end_session = "", None
            return False
        step, first = self.path.step, self.first_step
        (log.warning if error else log.info)(
            "site %s: session %d closed after %d step(s)%s: %s", self.name, self.session,
            step - first, f" (steps {first + 1}-{step} of the resumed run)" if first else "",
            reason,
        )
        if self.path.uncommitted and self.state in (RUNNING, PAUSED):
            self._enter(Trigger.INTEGRATOR_LOST,
                        f"integrator session ended with an uncommitted command at step "
                        f"{step + 1} ({reason})")
        self.transition(Trigger.SESSION_CLOSE, reason, steps=step, error=error)
        self.peer, self.in_session, self._end_session = "", False, None
        return True

    def resume_from(self, session: int, step: int, time: float) -> None:
        """A resumed run: the next session is ``session + 1`` and starts after committed
        ``step`` (pseudo-time ``time``). Nothing is sent to the controller here: the first
        command is the client's, checked against the measured position."""
        self.session = session
        self._resume_at = (step, time)
        self.path.step, self.path.time = step, time  # ``ctl status`` until the session opens
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
        step = self.path.step
        if self.state is HOLD or self.state is FAULT:
            log.warning("site %s: %s while in %s: %s", self.name, trigger, self.state, reason)
            return
        try:
            new = self.transition(trigger, reason, step=step)
        except TransitionRefused as exc:
            log.error("site %s: %s (%s)", self.name, exc, reason)
            return
        if new is HOLD:
            log.error("site %s: HOLD at step %d: %s", self.name, step, reason,
                      extra=cause_of(reason))  # one line per (site, cause) per interval
            self.path.hold()
        else:
            log.warning("site %s: %s at step %d: %s (stays %s)", self.name, trigger, step,
                        reason, new)

    def enter_hold(self, reason: str) -> None:
        self._enter(Trigger.HOLD, reason)

    def recovered(self, reason: str, **extra: object) -> None:
        """HOLD → RUNNING: the guard's recovery found the controller answering again."""
        self.transition(Trigger.RECOVERED, reason, **extra)

    # -- operator ------------------------------------------------------------------------------
    def operator_pause(self, source: str) -> str:
        """Stop forwarding at the next trial; the integrator's request waits for resume/abort."""
        if self.state is PAUSED:
            return f"site {self.name} is already PAUSED ({self.reason})"
        self.transition(Trigger.PAUSE, f"operator pause ({source})")
        log.warning("site %s: PAUSED by the operator (%s) at step %d; the next command waits "
                    "for 'fresco-bridge ctl resume' or 'abort'", self.name, source,
                    self.path.step)
        return f"site {self.name} PAUSED at step {self.path.step}"

    def operator_resume(self, source: str) -> str:
        """PAUSED → RUNNING (the waiting command is checked again) or FAULT → IDLE."""
        old = self.state
        new = self.transition(Trigger.RESUME, f"operator resume ({source})")
        log.warning("site %s: %s → %s by the operator (%s)", self.name, old, new, source)
        self.path.wake()
        return f"site {self.name} {old} → {new}"

    def operator_abort(self, source: str) -> str:
        """FAULT: hold the controller, answer the session NaN (it stops), refuse new ones."""
        old, step = self.state, self.path.step
        self.transition(Trigger.ABORT, f"operator abort ({source})", step=step)
        log.error("site %s: ABORTED by the operator (%s) at step %d (was %s): controller held, "
                  "sessions refused until 'fresco-bridge ctl resume'", self.name, source,
                  step, old)
        self.path.hold()
        self.path.wake()
        if self.peer:
            self._end_session_later(self.session, f"aborted by the operator ({source}); the "
                                    f"client sent no request within {ABORT_GRACE:g} s")
        return f"site {self.name} {old} → FAULT"

    def status(self) -> dict[str, object]:
        """A JSON-able snapshot for ``fresco-bridge ctl status``: the core's fields, then the
        kind's (``StepPath.status_fields``)."""
        since = self.paused_since
        return {
            "site": self.name, "kind": self.cfg.kind, "state": str(self.state),
            "reason": self.reason, "session": self.session, "peer": self.peer or None,
            "step": self.path.step, "time": self.path.time,
            "pending": None if self.pending is None else list(self.pending),
            "paused_for": None if since is None else round(_time.monotonic() - since, 3),
            "holds": self.holds,
            "record": None if self.recorder is None or self.recorder.failure is None
            else str(self.recorder.failure),
            "refused": {} if self.rejections is None else dict(self.rejections.counts),
            **self.path.status_fields(),
        }

    # -- the NaN stop --------------------------------------------------------------------------
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
                  "step %d)", self.name, why, self.session, self.path.step)
        self.event("integrator-stop", f"answering NaN so the integrator stops: {why}",
                   step=self.path.step)

    def stopping(self) -> bool:
        """True when this session can only be told to stop (every answer NaN, the constant ones
        too): HOLD (nothing is forwarded any more, so no true measurement can follow; a
        recoverable controller loss is waited out inside the request before any reply), FAULT
        (operator abort), or a failed recovery."""
        if self.stop_reason is None and self.in_session:
            if self.state is HOLD:
                self.tell_integrator_to_stop(f"HOLD ({self.reason})")
            elif self.state is FAULT:
                self.tell_integrator_to_stop(f"aborted by the operator ({self.reason})")
        return self.stop_reason is not None

    def nan_signals(self, sizes: SignalSizes) -> Signals:
        """The answer of a session being told to stop, each block as the client sized it."""
        nan = (math.nan,) * self.cfg.dofs
        return Signals(disp=nan if sizes.disp else (), vel=nan if sizes.vel else (),
                       accel=nan if sizes.accel else (), force=nan if sizes.force else (),
                       time=(self.path.time,) if sizes.time else ())

    # -- listeners and telemetry ---------------------------------------------------------------
    def add_listener(self, listener: StepListener | EventListener) -> None:
        """Committed steps (``step_committed``), events (``site_event``) and/or forwarded
        trials (``trial_forwarded``) go to ``listener`` from now on, after the earlier ones."""
        self.listeners.add(listener)

    def status_now(self) -> SiteStatus:
        """The site's state for telemetry (retained status)."""
        return SiteStatus(site=self.name, state=str(self.state), session=self.session,
                          step=self.path.step, time=self.path.time, reason=self.reason,
                          holds=self.holds)

    def event(self, kind: str, reason: str, **extra: object) -> None:
        """An event of this site (a state change, a limit hit, a fault…) to its listeners."""
        if self.listeners.events:
            self.listeners.event(SiteNotice(self.name, self.session, self.path.step,
                                            self.path.time, kind, reason, extra),
                                 self.status_now())

    def monitor_warning(self, reason: str, step: int) -> None:
        """An online monitor's warning at committed ``step`` (the taps raise it)."""
        self.event("monitor-warning", reason, step=step)
