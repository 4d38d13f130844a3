"""An experimental site: trial → setup → safety → controller → daq → out.

The site outlives connections. Its sessions, state table (``safety.states``: IDLE / RUNNING /
PAUSED / HOLD / FAULT), operator commands, NaN stop, listeners, record writer and status are the
site core's (``core.py``), composed here as ``self.core``; this module is the step path: the
setup, the limits (``gate.py``), the controller behind its guard (``guard.py``), the correction
(``correcting.py``), the tangent. A non-finite trial, a limit violation under ``reject``, a
measured force past its daq limit, a controller failure or timeout, or an integrator lost with an
uncommitted command puts the site in HOLD: nothing more is forwarded, requests are answered NaN
so the integrator stops. A controller that is only lost or silent is waited for inside the
request instead (``recovery``, up to ``controller_recovery`` s). A run record that cannot be
written is a fault of the site (``SiteCore.record_failed``): the step whose commit failed does
not count.
"""

from __future__ import annotations

import asyncio
import math
import time as _time
from collections.abc import Callable
from typing import TYPE_CHECKING

from protocol import Signals, SignalSizes

from ..controls.base import Controller, Daq, InlineController
from ..record import RecordError, RunRecord
from ..safety import Limiter, SiteState, Trigger, all_finite
from ..setups import Setup, make_setup
from ..site_output import CommittedStep
from ..tangent import TangentEstimate, TangentMethod
from ..telemetry.schema import CorrectionSample
from .base import Later, SiteError
from .core import SiteCore
from .correcting import SiteCorrection
from .gate import CommandGate
from .guard import ControllerGuard
from .site_config import SiteConfigBase

if TYPE_CHECKING:
    from ..telemetry.metrics import SiteMetrics
    from .access import RejectionLog

RUNNING, PAUSED, HOLD, FAULT = SiteState.RUNNING, SiteState.PAUSED, SiteState.HOLD, SiteState.FAULT


class ExperimentalSite:
    """One site whose force comes from a controller: config, setup, limits, controller (behind
    its guard), the current session's signals; the rest is its core's (``SiteCore``)."""

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
        self.core = core = SiteCore(cfg, record, self)
        """Sessions, states, operator, NaN stop, listeners, record, status (``core.py``)."""
        self.damping, self.mass = core.damping, core.mass
        self.listeners, self.recorder = core.listeners, core.recorder
        self.claim: Callable[[str], None] = core.claim
        self.open_session: Callable[[str], int] = core.open_session
        self.attach_session_end: Callable[[Callable[[str], None]], None] = \
            core.attach_session_end
        self.check_sizes: Callable[[SignalSizes, SignalSizes, str], None] = core.check_sizes
        self.resume_from: Callable[[int, int, float], None] = core.resume_from
        self.stopping: Callable[[], bool] = core.stopping
        self.operator_pause: Callable[[str], str] = core.operator_pause
        self.operator_resume: Callable[[str], str] = core.operator_resume
        self.operator_abort: Callable[[str], str] = core.operator_abort
        self.status: Callable[[], dict[str, object]] = core.status
        self.status_now = core.status_now
        self.add_listener = core.add_listener
        self.enter_hold: Callable[[str], None] = core.enter_hold
        self.monitor_warning: Callable[[str, int], None] = core.monitor_warning
        self.tell_integrator_to_stop: Callable[[str], None] = core.tell_integrator_to_stop
        limiter = Limiter([c.to_limits() for c in cfg.limits], self.setup.n_actuators) \
            if cfg.limits else None
        self.limiter = limiter
        self.gate = CommandGate(self, limiter, inline=self._now is not None)
        """The limits and the operator's pause between a target and the controller."""
        self._ctrl_limiter = self.gate.limiter
        self._daq_limiter = limiter if limiter is not None and limiter.has_daq else None
        self.step = 0
        """The last committed step (of the current or last session)."""
        self.time = 0.0
        self._reset_signals()
        correction = getattr(cfg, "correction", None)
        self.correction: SiteCorrection | None = None if correction is None \
            else SiteCorrection(self, correction)
        """``[sites.correction]``: every trial is corrected (``correcting.py``); None: the
        direct path."""

    # -- the core's, as this site's (``Site``, and what the gate, guard and correction read) --
    @property
    def state(self) -> SiteState:
        return self.core.state

    @property
    def reason(self) -> str:
        return self.core.reason

    @property
    def session(self) -> int:
        return self.core.session

    @property
    def peer(self) -> str:
        return self.core.peer

    @property
    def in_session(self) -> bool:
        return self.core.in_session

    @property
    def busy(self) -> bool:
        return self.core.peer != ""

    @property
    def holds(self) -> int:
        return self.core.holds

    @property
    def pending(self) -> tuple[float, ...] | None:
        return self.core.pending

    @pending.setter
    def pending(self, command: tuple[float, ...] | None) -> None:
        self.core.pending = command

    @property
    def metrics(self) -> SiteMetrics | None:
        return self.core.metrics

    @metrics.setter
    def metrics(self, metrics: SiteMetrics | None) -> None:
        self.core.metrics = metrics

    @property
    def rejections(self) -> RejectionLog | None:
        return self.core.rejections

    @rejections.setter
    def rejections(self, rejections: RejectionLog | None) -> None:
        self.core.rejections = rejections

    def close_session(self, reason: str, *, error: bool = False) -> bool:
        return self.core.close_session(reason, error=error)

    def record_refusal(self, message: str, **extra: object) -> None:
        self.core.record_refusal(message, **extra)

    def transition(self, trigger: Trigger, reason: str, **extra: object) -> SiteState:
        return self.core.transition(trigger, reason, **extra)

    def recovered(self, reason: str, **extra: object) -> None:
        self.core.recovered(reason, **extra)

    def event(self, kind: str, reason: str, **extra: object) -> None:
        self.core.event(kind, reason, **extra)

    # -- what the core asks of its step path (``core.StepPath``) --------------------------------
    def _reset_signals(self) -> None:
        n, na = self.cfg.dofs, self.setup.n_actuators
        self.step = 0
        self.time = 0.0
        self.commit_time = 0.0
        self.trial = Signals(disp=(0.0,) * n, vel=(0.0,) * n, accel=(0.0,) * n, time=(0.0,))
        self.target: tuple[float, ...] = (0.0,) * na  # what the integrator asked for (ctrl)
        self.ctrl: tuple[float, ...] = (0.0,) * na  # what the controller was sent last
        self.guard.sent = None
        self.uncommitted = False
        self.daq = Daq((0.0,) * na, (0.0,) * na)
        self._daq_valid = False
        self._acquiring: asyncio.Future[Daq] | None = None
        """The controller read in flight (network controllers): one read per trial, whoever
        asks (the site's own force request, or a trial listener reading the published
        trial's measurement)."""
        self._k_tangent: tuple[float, ...] = (0.0,) * (n * n)
        self._estimate = TangentEstimate(self._tangent_method, na)  # per session
        self._k_initial: tuple[float, ...] | None = None

    def new_session(self, resume_at: tuple[int, float] | None) -> None:
        self._reset_signals()
        if resume_at is not None:  # the first session after a crash: it goes on (its
            self.step, self.time = resume_at  # numbering; the specimen is not reset)
            self.commit_time = self.time
        elif self._reset_on_new_session:
            reset = getattr(self.controller, "reset", None)
            if reset is not None:
                reset()
                self.gate.reference = None

    def hold(self) -> None:
        self.guard.hold()

    def wake(self) -> None:
        self.gate.wake()
        self.guard.wake()

    def status_fields(self) -> dict[str, object]:
        since = self.guard.recovering_since
        return {
            "target": list(self.target), "ctrl": list(self.ctrl),
            "daq_disp": list(self.daq.disp), "daq_force": list(self.daq.force),
            "recovering_for": None if since is None else round(_time.monotonic() - since, 3),
            "limit_events": dict(self.gate.limit_counts),
            "limits": [c.model_dump(exclude_none=True) for c in self.cfg.limits],
            "correction": None if self.correction is None else self.correction.status(),
            **self.controller.status_fields(),
        }

    @property
    def resets_on_new_session(self) -> bool:
        return self._reset_on_new_session

    def forwarded(self) -> None:
        """``_forwarded`` for the correction, once its last command is reached."""
        self._forwarded()

    def _forwarded(self) -> None:
        """The current trial reached the controller: its listeners get it (and a way to read
        its one measurement)."""
        if self.listeners.trials and self.core.state is RUNNING:
            self.listeners.trial(SourceTrial(self, self.core.session, self.step + 1, self.time,
                                             self.ctrl))

    def correction_sample(self) -> CorrectionSample | None:
        """The current trial's displacement correction for telemetry (None: no correction)."""
        return None if self.correction is None else self.correction.sample(self.step)

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
        if self.core.state is FAULT:
            return None
        values = trial.disp + trial.vel + trial.accel + trial.time
        if not all_finite(values):
            if self.core.state is not HOLD:
                bad = [v for v in values if not math.isfinite(v)]
                self.enter_hold(f"non-finite trial value(s) {bad} (disp {list(trial.disp)}); "
                                "not forwarded to the controller")
            return None
        self.trial = trial
        if trial.time:
            self.time = trial.time[0]
        target = trial.disp if self._plain else self.setup.ctrl_disp(trial.disp)
        if not math.isfinite(sum(target)):  # finite trials whose transform overflows
            if self.core.state is not HOLD:
                self.enter_hold(f"setup {self.setup.kind} turned trial {list(trial.disp)} into "
                                f"non-finite ctrl {list(target)}; not forwarded")
            return None
        self.target = target
        if (stalled := self._estimate.trial(target)) is not None:
            self.event("tangent-fallback", stalled)
        if self.core.state is HOLD:
            return None
        self._daq_valid = False
        if self.correction is not None:
            return self.correction.trial(trial, target)
        if self.core.state is RUNNING and (self._ctrl_limiter is None
                                           or self.gate.clear_of_limits(target)):  # hot path
            self.ctrl = target
            if self.recorder is not None:
                self.recorder.trial(self.core.session, self.step, self.time, trial.disp, target)
                if self.core.state is HOLD:  # the record failed (``record_failed``)
                    return None
            if target != self.guard.sent:
                if self._now is None:
                    return self._send_later(target)
                self.uncommitted = True
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
        self.uncommitted = True
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

    def _sent(self, command: tuple[float, ...]) -> bool:
        """After ``command`` went to the controller (or failed: the site is in HOLD)."""
        if self.core.state is HOLD or self.core.state is FAULT:
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
        return daq if self.core.state is RUNNING else None

    def acquire_eager(self) -> Daq | Later[Daq]:
        """The measurement for the current command, acquired once per trial."""
        if self._daq_valid or self.core.state is HOLD:
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
                    self.recorder.measurement(self.core.session, self.step, daq.disp, daq.force)
                self.gate.limit_event(hit, "hold")
                self.enter_hold(f"daq limit exceeded: {hit.describe()}")
                return self.daq
        self.daq = daq
        self._daq_valid = True
        if self.recorder is not None:
            self.recorder.measurement(self.core.session, self.step, daq.disp, daq.force)
        return daq

    async def commit(self) -> None:
        """Code 5 (see ``commit_eager``)."""
        later = self.commit_eager()
        if later is not None:
            await later

    def commit_eager(self) -> Later[None] | None:
        """Code 5 (also while PAUSED: it completes a step already forwarded)."""
        if self.core.state is HOLD or self.core.state is FAULT:
            return None
        daq = self.acquire_eager()  # every committed step has its measurement in the record
        if not isinstance(daq, Daq):
            return self._commit_later(daq)
        if self.core.state is HOLD:
            return None
        if self._now is None:
            return self._commit_later(None)
        self.guard.now("commit", self._now.commit_now)
        self._committed()
        return None

    async def _commit_later(self, daq: Later[Daq] | None) -> None:
        if daq is not None:
            await daq
            if self.core.state is HOLD:
                return
        if self._now is not None:
            self.guard.now("commit", self._now.commit_now)
        else:
            await self.guard.guarded("commit", self.controller.commit)
        self._committed()

    def _committed(self) -> None:
        """The controller committed (or failed to: then the site is in HOLD): the step counts."""
        self.step += 1
        self.uncommitted = False
        commit_time, self.commit_time = self.commit_time, self.time
        if (refused := self._estimate.committed(self.ctrl, self.daq.force)) is not None:
            self.event("tangent-fallback", refused)
        outlets = self.listeners
        lean = outlets.step_values
        try:
            if lean is not None:  # the record and its monitor: no CommittedStep to build
                session, step, time_, ctrl, disp = (self.core.session, self.step, self.time,
                                                    self.ctrl, self.daq.disp)
                for listener_values in lean:
                    listener_values(session, step, time_, ctrl, disp)
            elif outlets.steps:
                committed = CommittedStep(self.name, self.core.session, self.step, self.time,
                                          self.trial.disp, self.ctrl, self.daq.disp,
                                          self.daq.force, str(self.core.state))
                for listener in outlets.steps:
                    listener.step_committed(committed)
        except RecordError as exc:  # the record is the first listener: nobody saw the step
            self.step -= 1
            self.commit_time = commit_time
            self.core.record_failed(exc)

    async def out_signals(self, sizes: SignalSizes) -> Signals:
        """Measured signals in basic DOFs (see ``out_signals_eager``)."""
        out = self.out_signals_eager(sizes)
        return out if isinstance(out, Signals) else await out

    def out_signals_eager(self, sizes: SignalSizes) -> Signals | Later[Signals]:
        """Measured signals in basic DOFs (OpenFresco *out*), blocks as the client sized them;
        NaN once the integrator must stop (see ``_tell_integrator_to_stop``)."""
        if self.core.stopping():
            return self.core.nan_signals(sizes)
        daq = self.acquire_eager()
        if not isinstance(daq, Daq):
            return self._out_later(daq, sizes)
        return self._out(daq, sizes)

    async def _out_later(self, daq: Later[Daq], sizes: SignalSizes) -> Signals:
        return self._out(await daq, sizes)

    def _out(self, daq: Daq, sizes: SignalSizes) -> Signals:
        # the acquisition may have HOLDed the site: ``stopping`` decides then (it answers
        # False whenever this first test does)
        core = self.core
        if (core.stop_reason is not None or core.state is HOLD or core.state is FAULT) \
                and core.stopping():
            return core.nan_signals(sizes)
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

    async def tangent(self) -> tuple[float, ...]:
        """Tangent in basic DOFs (see ``tangent_eager``)."""
        k = self.tangent_eager()
        return k if isinstance(k, tuple) else await k

    def tangent_eager(self) -> tuple[float, ...] | Later[tuple[float, ...]]:
        """Tangent in basic DOFs (the last good one if the controller cannot give it); NaN
        when the integrator must stop."""
        if self.core.stopping():
            return (math.nan,) * (self.cfg.dofs ** 2)
        if self.core.state is HOLD:
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
        if self.core.stopping():
            return (math.nan,) * (self.cfg.dofs ** 2)
        if self._k_initial is None or self.core.state is not HOLD:
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
