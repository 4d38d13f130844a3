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
"""

from __future__ import annotations

import asyncio
import logging
import math
import time as _time
from collections.abc import Awaitable, Callable, Coroutine
from typing import TYPE_CHECKING, Any, TypeVar

from protocol import Signals, SignalSizes

from ..config import SiteConfig
from ..controls.base import Controller, ControllerError, ControllerLinkError, Daq
from ..record import RunRecord
from ..safety import Limiter, LimitHit, SiteState, TransitionRefused, Trigger, next_state
from ..setups import LinearSetup, make_setup
from ..telemetry import NullTelemetry, SiteEvent, SiteStatus, StepSample
from .recovery import recover
from .sizes import column_major, size_problems

if TYPE_CHECKING:
    from ..indicators import OnlineMonitor
    from ..telemetry.base import Telemetry
    from ..telemetry.metrics import SiteMetrics

log = logging.getLogger("fresco_bridge.site")
T = TypeVar("T")

PAUSE_LOG_INTERVAL = 30.0
"""While a command waits for an operator, a warning is logged this often (s)."""

RUNNING, PAUSED, HOLD, FAULT = SiteState.RUNNING, SiteState.PAUSED, SiteState.HOLD, SiteState.FAULT


class SiteError(Exception):
    """A session cannot be served by this site (sizes that do not fit, site busy, aborted)."""


class ExperimentalSite:
    """One site: config, setup, limits, controller, state, and the current session's signals."""

    def __init__(
        self,
        cfg: SiteConfig,
        controller: Controller,
        record: RunRecord | None,
        *,
        controller_timeout: float,
        controller_recovery: float = 0.0,
    ) -> None:
        self.cfg = cfg
        self.name = cfg.name
        self.controller = controller
        self.record = record
        self.setup: LinearSetup = make_setup(cfg.setup, cfg.dofs)
        if self.setup.n_actuators != controller.n_actuators:
            raise SiteError(
                f"site {cfg.name}: setup {cfg.setup} needs {self.setup.n_actuators} actuator(s), "
                f"the controller has {controller.n_actuators}"
            )
        self.timeout = controller_timeout
        self.recovery = controller_recovery  # s to wait for a lost controller; 0: plain HOLD
        self.recovering_since: float | None = None
        self.state = SiteState.IDLE
        self.reason = ""
        self.session = 0
        self.peer = ""
        self.damping = column_major(cfg.damping, cfg.dofs)
        self.mass = column_major(cfg.mass, cfg.dofs)
        self.holds = 0
        self.telemetry: Telemetry = NullTelemetry()
        self.monitor: OnlineMonitor | None = None
        self.metrics: SiteMetrics | None = None  # set by the bridge when /metrics is served
        self._live = False  # telemetry on: publish steps, status and events
        limiter = Limiter([c.to_limits() for c in cfg.limits], self.setup.n_actuators) \
            if cfg.limits else None
        self.limiter = limiter
        self._ctrl_limiter = limiter if limiter is not None and limiter.has_ctrl else None
        self._daq_limiter = limiter if limiter is not None and limiter.has_daq else None
        self.limit_counts: dict[str, int] = {}
        self._reference: tuple[float, ...] | None = None  # last command the controller got
        self._wake: asyncio.Event | None = None
        self.paused_since: float | None = None
        self.pending: tuple[float, ...] | None = None  # waits for an operator or a recovery
        self._background: set[asyncio.Task[None]] = set()
        self._reset_signals()

    @property
    def hold_reason(self) -> str:
        return self.reason

    # -- sessions ------------------------------------------------------------------------------
    def _reset_signals(self) -> None:
        n, na = self.cfg.dofs, self.setup.n_actuators
        self.step = 0
        self.time = 0.0
        self._commit_time = 0.0
        self.trial = Signals(disp=(0.0,) * n, vel=(0.0,) * n, accel=(0.0,) * n, time=(0.0,))
        self.target: tuple[float, ...] = (0.0,) * na  # what the integrator asked for (ctrl)
        self.ctrl: tuple[float, ...] = (0.0,) * na  # what the controller was sent last
        self._sent_ctrl: tuple[float, ...] | None = None
        self._uncommitted = False
        self.daq = Daq((0.0,) * na, (0.0,) * na)
        self._daq_valid = False
        self._k_tangent: tuple[float, ...] = (0.0,) * (n * n)
        self._k_initial: tuple[float, ...] | None = None
        self.stop_reason: str | None = None  # set: this session's answers are NaN

    @property
    def busy(self) -> bool:
        return self.peer != ""

    def open_session(self, peer: str) -> int:
        if self.busy:
            raise SiteError(f"site {self.name} is busy with {self.peer} (one client per site)")
        try:
            next_state(self.state, Trigger.SESSION_OPEN, False)
        except TransitionRefused as exc:
            raise SiteError(f"site {self.name} is in {self.state} ({self.reason}); not accepting "
                            f"client {peer}: {exc}") from None
        self.session += 1
        self._reset_signals()
        reset = getattr(self.controller, "reset", None)
        if reset is not None and getattr(self.cfg.controller, "reset_on_new_session", False):
            reset()
            self._reference = None
        log.info("site %s: session %d opened by %s", self.name, self.session, peer)
        self._transition(Trigger.SESSION_OPEN, f"client {peer} connected", peer=peer)
        self.peer = peer
        return self.session

    def close_session(self, reason: str, *, error: bool = False) -> None:
        if not self.peer:
            return
        (log.warning if error else log.info)(
            "site %s: session %d closed after %d step(s): %s", self.name, self.session,
            self.step, reason,
        )
        if self._uncommitted and self.state in (RUNNING, PAUSED):
            self._enter(Trigger.INTEGRATOR_LOST,
                        f"integrator session ended with an uncommitted command at step "
                        f"{self.step + 1} ({reason})")
        self._transition(Trigger.SESSION_CLOSE, reason, steps=self.step, error=error)
        self.peer = ""

    def check_sizes(self, ctrl: SignalSizes, daq: SignalSizes, who: str) -> None:
        """OpenFresco's rule: every non-zero size equals the element's DOFs, time sizes are 1."""
        problems = size_problems(self.cfg.dofs, ctrl, daq)
        if problems:
            raise SiteError(f"{who} sizes do not fit site {self.name}: " + "; ".join(problems))

    # -- states --------------------------------------------------------------------------------
    def _transition(self, trigger: Trigger, reason: str, **extra: object) -> SiteState:
        """Move along ``safety.states.TRANSITIONS``; record and publish it with its reason."""
        old = self.state
        new = next_state(old, trigger, self.peer != "")
        self.state = new
        if new is not old:
            self.reason = reason if new in (PAUSED, HOLD, FAULT) else ""
            self.paused_since = _time.monotonic() if new is PAUSED else None
        kind = "hold" if new is HOLD and old is not HOLD else str(trigger)
        self._event(kind, reason, cause=str(trigger), **{"from": str(old), "to": str(new)},
                    **extra)
        return new

    def _enter(self, trigger: Trigger, reason: str) -> None:
        """A fault trigger (HOLD, integrator lost): never raises, HOLDs the controller."""
        if self.state is HOLD or self.state is FAULT:
            log.warning("site %s: %s while in %s: %s", self.name, trigger, self.state, reason)
            return
        try:
            new = self._transition(trigger, reason, step=self.step)
        except TransitionRefused as exc:
            log.error("site %s: %s (%s)", self.name, exc, reason)
            return
        if new is HOLD:
            self.holds += 1
            log.error("site %s: HOLD at step %d: %s", self.name, self.step, reason)
            self._controller_hold()
        else:
            log.warning("site %s: %s at step %d: %s (stays %s)", self.name, trigger, self.step,
                        reason, new)

    def enter_hold(self, reason: str) -> None:
        self._enter(Trigger.HOLD, reason)

    def _controller_hold(self) -> None:
        """Stop the actuator where it is; the adapter itself releases the interlock it engaged
        at the next command the site forwards (a new session or an operator's resume)."""
        if self.controller.inline:
            _run_inline(self.controller.hold())
        else:
            task = asyncio.get_running_loop().create_task(self._hold_in_background(),
                                                          name=f"{self.name}.hold")
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
                      "does)", self.name, reason)
            self._event("controller-hold-failed", reason, step=self.step)

    def _wake_waiter(self) -> None:
        if self._wake is not None:
            self._wake.set()

    # -- operator ------------------------------------------------------------------------------
    def operator_pause(self, source: str) -> str:
        """Stop forwarding at the next trial; the integrator's request waits for resume/abort."""
        if self.state is PAUSED:
            return f"site {self.name} is already PAUSED ({self.reason})"
        self._transition(Trigger.PAUSE, f"operator pause ({source})")
        log.warning("site %s: PAUSED by the operator (%s) at step %d; the next command waits "
                    "for 'fresco-bridge ctl resume' or 'abort'", self.name, source, self.step)
        return f"site {self.name} PAUSED at step {self.step}"

    def operator_resume(self, source: str) -> str:
        """PAUSED → RUNNING (the waiting command is checked again) or FAULT → IDLE."""
        old = self.state
        new = self._transition(Trigger.RESUME, f"operator resume ({source})")
        log.warning("site %s: %s → %s by the operator (%s)", self.name, old, new, source)
        self._wake_waiter()
        return f"site {self.name} {old} → {new}"

    def operator_abort(self, source: str) -> str:
        """FAULT: hold the controller, answer the session NaN (it stops), refuse new ones."""
        old = self.state
        self._transition(Trigger.ABORT, f"operator abort ({source})", step=self.step)
        log.error("site %s: ABORTED by the operator (%s) at step %d (was %s): controller held, "
                  "sessions refused until 'fresco-bridge ctl resume'", self.name, source,
                  self.step, old)
        self._controller_hold()
        self._wake_waiter()
        return f"site {self.name} {old} → FAULT"

    def status(self) -> dict[str, object]:
        """A JSON-able snapshot for ``fresco-bridge ctl status``."""
        since = self.paused_since
        return {
            "site": self.name, "state": str(self.state), "reason": self.reason,
            "session": self.session, "peer": self.peer or None, "step": self.step,
            "time": self.time, "target": list(self.target), "ctrl": list(self.ctrl),
            "daq_disp": list(self.daq.disp), "daq_force": list(self.daq.force),
            "pending": None if self.pending is None else list(self.pending),
            "paused_for": None if since is None else round(_time.monotonic() - since, 3),
            "recovering_for": None if self.recovering_since is None
            else round(_time.monotonic() - self.recovering_since, 3),
            "holds": self.holds, "limit_events": dict(self.limit_counts),
            "limits": [c.model_dump(exclude_none=True) for c in self.cfg.limits],
        }

    def _tell_integrator_to_stop(self, why: str) -> None:
        """From now on this session's answers are NaN, until the client sends DIE or leaves.

        Closing the connection cannot stop OpenSees: its genericClient ignores a failed recv
        and spins at full CPU forever (measured). A NaN force can: Newton fails to converge
        (``analyze`` returns < 0, the script stops and sends DIE), a non-iterative scheme ends
        with NaN results — never a plausible run built on forces the specimen did not give.
        """
        if self.stop_reason is not None:
            return
        self.stop_reason = why
        log.error("site %s: %s; answering NaN from now on so the integrator stops (session %d, "
                  "step %d)", self.name, why, self.session, self.step)
        self._event("integrator-stop", f"answering NaN so the integrator stops: {why}",
                    step=self.step)

    def _stopping(self) -> bool:
        """True when this session can only be told to stop: HOLD (nothing is forwarded any more,
        so no true measurement can follow; a recoverable controller loss is waited out inside
        the request before any reply), FAULT (operator abort), or a failed recovery."""
        if self.stop_reason is None and self.peer:
            if self.state is HOLD:
                self._tell_integrator_to_stop(f"HOLD ({self.reason})")
            elif self.state is FAULT:
                self._tell_integrator_to_stop(f"aborted by the operator ({self.reason})")
        return self.stop_reason is not None

    def _nan_signals(self, sizes: SignalSizes) -> Signals:
        nan = (math.nan,) * self.cfg.dofs
        return Signals(disp=nan if sizes.disp else (), vel=nan if sizes.vel else (),
                       accel=nan if sizes.accel else (), force=nan if sizes.force else (),
                       time=(self.time,) if sizes.time else ())

    async def _wait_for_operator(self, command: tuple[float, ...]) -> None:
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

    # -- telemetry -----------------------------------------------------------------------------
    def attach_telemetry(self, telemetry: Telemetry, monitor: OnlineMonitor | None) -> None:
        self.telemetry, self.monitor, self._live = telemetry, monitor, True
        self._publish_status()

    def _publish_status(self) -> None:
        if self._live:
            self.telemetry.publish_status(SiteStatus(
                site=self.name, state=str(self.state), session=self.session, step=self.step,
                time=self.time, reason=self.reason, holds=self.holds,
            ))

    def _event(self, kind: str, reason: str, **extra: object) -> None:
        if self.record is not None:
            self.record.event(self.name, self.session, kind, reason, **extra)
        if self._live:
            self.telemetry.publish_event(SiteEvent(
                site=self.name, kind=kind, reason=reason, session=self.session, step=self.step,
                time=self.time,
                extra={k: v for k, v in extra.items() if isinstance(v, str | int | float | bool)},
            ))
            self._publish_status()

    def _limit_event(self, hit: LimitHit, action: str) -> None:
        """Every limit hit is counted, logged, recorded and published (also when clamped)."""
        self.limit_counts[hit.limit] = self.limit_counts.get(hit.limit, 0) + 1
        log.warning("site %s: LIMIT at step %d: %s (policy %s: %s)", self.name, self.step + 1,
                    hit.describe(), hit.policy, action)
        self._event("limit", hit.describe(), **hit.as_record(), action=action, step=self.step)

    # -- controller calls ----------------------------------------------------------------------
    def _call(self, coro: Coroutine[Any, Any, T]) -> Awaitable[T]:
        """Every controller call gets the deadline; in-process ones complete at once."""
        if self.controller.inline:
            return coro
        return asyncio.wait_for(coro, self.timeout)

    async def _guard(self, what: str, call: Callable[[], Coroutine[Any, Any, T]],
                     command: tuple[float, ...] | None = None) -> T | None:
        """``call()`` under the deadline; a failure HOLDs (None). A lost or silent controller
        is waited for first (``recovery``), then the call is made again: ``command`` is the
        setpoint ``call`` sends, a read re-sends the last setpoint before reading again."""
        deadline: float | None = None
        resend: tuple[float, ...] | None = None
        while True:
            started, doing = self.state, what
            try:
                if resend is not None:
                    doing = f"set_ctrl {list(resend)} (re-sent after the controller came back)"
                    await self._call(self.controller.set_ctrl(resend))
                    resend = None
                    doing = what
                return await self._call(call())
            except TimeoutError:
                reason, lost = f"controller did not answer {doing} within {self.timeout:g} s", True
            except ControllerError as exc:
                reason = f"controller failed on {doing}: {exc}"
                lost = isinstance(exc, ControllerLinkError)
            self.enter_hold(reason)
            if not lost or self.recovery <= 0.0 or started is not RUNNING or self.state is not HOLD:
                return None
            loop = asyncio.get_running_loop()
            deadline = loop.time() + self.recovery if deadline is None else deadline
            if resend is None:
                resend = command if command is not None else self._sent_ctrl
            why = await recover(self, reason, deadline, resend)
            if self.state is FAULT:
                return None  # aborted meanwhile: the reply is NaN (``_stopping``)
            if why is not None:
                self._tell_integrator_to_stop(why)
                return None
            if command is not None:
                resend = None  # ``call`` itself sends ``command`` again

    # -- the step ------------------------------------------------------------------------------
    async def set_trial(self, trial: Signals) -> None:
        """Code 3: validate, transform, check limits, forward. Never forwards an unsafe command.

        In FAULT nothing happens here: the replies of the session are NaN from now on.
        """
        if self.state is FAULT:
            return
        values = trial.disp + trial.vel + trial.accel + trial.time
        if not all(math.isfinite(v) for v in values):
            if self.state is not HOLD:
                bad = [v for v in values if not math.isfinite(v)]
                self.enter_hold(f"non-finite trial value(s) {bad} (disp {list(trial.disp)}); "
                                "not forwarded to the controller")
            return
        self.trial = trial
        if trial.time:
            self.time = trial.time[0]
        target = self.setup.ctrl_disp(trial.disp)
        if not math.isfinite(sum(target)):  # finite trials whose transform overflows
            if self.state is not HOLD:
                self.enter_hold(f"setup {self.setup.kind} turned trial {list(trial.disp)} into "
                                f"non-finite ctrl {list(target)}; not forwarded")
            return
        self.target = target
        if self.state is HOLD:
            return
        self._daq_valid = False
        if self.state is RUNNING and self._ctrl_limiter is None:  # the hot path: no limits
            ctrl = target
            self.ctrl = ctrl
            if self.record is not None:
                self.record.trial(self.name, self.session, self.step, self.time, trial.disp, ctrl)
            if ctrl != self._sent_ctrl:
                await self._send(ctrl)
            return
        commands = await self._commands_for(target)
        if commands is None:
            return
        ctrl = self.ctrl = commands[-1]
        if self.record is not None:
            self.record.trial(self.name, self.session, self.step, self.time, trial.disp, ctrl)
        for command in commands:
            if command != self._sent_ctrl and not await self._send(command):
                return

    async def _send(self, command: tuple[float, ...]) -> bool:
        """One command to the controller; False if the site left RUNNING/PAUSED meanwhile."""
        self._uncommitted = True
        await self._guard("set_ctrl", lambda: self.controller.set_ctrl(command), command)
        if self.state is HOLD or self.state is FAULT:
            self._reference = None  # where the actuator stopped is not known
            return False
        self._sent_ctrl = self._reference = command
        return True

    async def _commands_for(
        self, target: tuple[float, ...]
    ) -> tuple[tuple[float, ...], ...] | None:
        """Wait out a pause, apply the limits: the commands to send in order, or None."""
        while True:
            if self.state is PAUSED:
                await self._wait_for_operator(target)
            if self._ctrl_limiter is None:
                commands: tuple[tuple[float, ...], ...] | None = (target,)
            else:
                commands = await self._limited(target)
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

    async def _limited(self, target: tuple[float, ...]) -> tuple[tuple[float, ...], ...] | None:
        """The commands to send for ``target`` under the limits, or None (HOLD)."""
        limiter = self._ctrl_limiter
        assert limiter is not None
        if self._reference is None and limiter.needs_reference:
            daq = await self._guard("get_daq (reference position)", self.controller.get_daq)
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
                self._limit_event(hit, action)
            if action == "reject":
                self.enter_hold(f"limit exceeded, command {list(target)} not forwarded: "
                                f"{verdict.describe()}")
                return None
            if action == "pause":
                self._transition(Trigger.PAUSE, f"limit exceeded, command {list(target)} "
                                 f"waits for an operator: {verdict.describe()}", step=self.step)
                await self._wait_for_operator(target)
                if self.state is not RUNNING:
                    return None  # aborted
                approved = True  # the operator saw it: increment/velocity waived, absolute not
                continue
            if action == "substep":
                log.info("site %s: step %d sent as %d sub-commands (velocity limit)",
                         self.name, self.step + 1, len(verdict.commands))
                self._event("substep", f"{len(verdict.commands)} sub-commands within the "
                            "velocity limit", substeps=len(verdict.commands),
                            target=list(verdict.commands[-1]), step=self.step)
            return verdict.commands

    async def acquire(self) -> Daq:
        """The measurement for the current command, acquired once per trial."""
        if self._daq_valid or self.state is HOLD:
            return self.daq
        daq = await self._guard("get_daq", self.controller.get_daq)
        if daq is None:
            return self.daq
        if not all(math.isfinite(v) for v in daq.disp + daq.force):
            self.enter_hold(f"controller returned non-finite measurements {daq}")
            return self.daq
        if self._daq_limiter is not None:
            hit = self._daq_limiter.check_daq(daq.force)
            if hit is not None:
                if self.record is not None:  # a real measurement: keep it in the record
                    self.record.measurement(self.name, self.session, self.step, daq.disp,
                                            daq.force)
                self._limit_event(hit, "hold")
                self.enter_hold(f"daq limit exceeded: {hit.describe()}")
                return self.daq
        self.daq = daq
        self._daq_valid = True
        if self.record is not None:
            self.record.measurement(self.name, self.session, self.step, daq.disp, daq.force)
        return daq

    async def commit(self) -> None:
        """Code 5 (also while PAUSED: it completes a step already forwarded)."""
        if self.state is HOLD or self.state is FAULT:
            return
        await self.acquire()  # every committed step has its measurement in the record
        if self.state is HOLD:
            return
        await self._guard("commit", self.controller.commit)
        self.step += 1
        self._uncommitted = False
        self._commit_time = self.time
        if self.record is not None:
            self.record.commit(self.name, self.session, self.step, self.time)
        if self._live:
            self._publish_step()

    def _publish_step(self) -> None:
        """Telemetry tap: a bounded-queue append, never a wait (the step loop stays fast)."""
        sample = None
        if self.monitor is not None:
            sample = self.monitor.update(self.ctrl[0], self.daq.disp[0])
            if sample.warning:
                self._event("monitor-warning", sample.warning, step=self.step)
        self.telemetry.publish_step(StepSample(
            self.name, self.session, self.step, self.time, self.trial.disp, self.ctrl,
            self.daq.disp, self.daq.force, str(self.state), None, sample,
        ))

    async def out_signals(self, sizes: SignalSizes) -> Signals:
        """Measured signals in basic DOFs (OpenFresco *out*), blocks as the client sized them;
        NaN once the integrator must stop (see ``_tell_integrator_to_stop``)."""
        if self._stopping():
            return self._nan_signals(sizes)
        daq = await self.acquire()
        if self._stopping():
            return self._nan_signals(sizes)
        disp = self.setup.out_disp(self.trial.disp, self.target, daq.disp)
        force = self.setup.basic_force(daq.force)
        return Signals(
            disp=disp if sizes.disp else (),
            vel=self.trial.vel if sizes.vel else (),
            accel=self.trial.accel if sizes.accel else (),
            force=force if sizes.force else (),
            time=(self.time,) if sizes.time else (),
        )

    async def tangent(self) -> tuple[float, ...]:
        """Tangent in basic DOFs (the last good one if the controller cannot give it); NaN
        when the integrator must stop."""
        if self._stopping():
            return (math.nan,) * (self.cfg.dofs ** 2)
        if self.state is not HOLD:
            k = await self._guard("tangent_stiffness", self.controller.tangent_stiffness)
            if k is not None:
                self._k_tangent = self.setup.basic_matrix(k)
        return self._k_tangent

    async def initial(self) -> tuple[float, ...]:
        if self._stopping():
            return (math.nan,) * (self.cfg.dofs ** 2)
        if self._k_initial is None or self.state is not HOLD:
            k = await self._guard("initial_stiffness", self.controller.initial_stiffness)
            if k is not None:
                self._k_initial = self.setup.basic_matrix(k)
        return self._k_initial if self._k_initial is not None else self._k_tangent


def _run_inline(coro: Coroutine[Any, Any, Any]) -> None:
    from ..eager import Suspended, start_eager

    r = start_eager(coro)
    if isinstance(r, Suspended):
        r.task()
