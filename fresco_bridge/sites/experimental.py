"""An experimental site: trial → setup → controller → daq → out, with HOLD on any fault.

The site outlives connections: it owns the controller and the state machine
IDLE → RUNNING → (HOLD) → IDLE. A non-finite trial, a controller failure or timeout puts it in
HOLD: nothing more is forwarded to the controller, requests are answered from the last good
measurement, and the reason is logged and recorded. The next integrator session starts it again.
"""

from __future__ import annotations

import asyncio
import enum
import logging
import math
from collections.abc import Awaitable, Coroutine
from typing import TYPE_CHECKING, Any, TypeVar

from protocol import Signals, SignalSizes

from ..config import SiteConfig
from ..controls.base import Controller, ControllerError, Daq
from ..record import RunRecord
from ..setups import LinearSetup, make_setup
from ..telemetry import NullTelemetry, SiteEvent, SiteStatus, StepSample

if TYPE_CHECKING:
    from ..indicators import OnlineMonitor
    from ..telemetry.metrics import SiteMetrics
    from ..telemetry.mqtt import Telemetry

log = logging.getLogger("fresco_bridge.site")
T = TypeVar("T")


class SiteError(Exception):
    """A session cannot be served by this site (sizes that do not fit, site busy)."""


class SiteState(enum.StrEnum):
    IDLE = "IDLE"
    RUNNING = "RUNNING"
    HOLD = "HOLD"
    FAULT = "FAULT"


def _column_major(rows: list[list[float]] | None, n: int) -> tuple[float, ...]:
    if rows is None:
        return (0.0,) * (n * n)
    return tuple(float(rows[r][c]) for c in range(n) for r in range(n))


class ExperimentalSite:
    """One site: config, setup, controller, state, and the current session's signals."""

    def __init__(
        self,
        cfg: SiteConfig,
        controller: Controller,
        record: RunRecord | None,
        *,
        controller_timeout: float,
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
        self.state = SiteState.IDLE
        self.hold_reason = ""
        self.session = 0
        self.peer = ""
        self.damping = _column_major(cfg.damping, cfg.dofs)
        self.mass = _column_major(cfg.mass, cfg.dofs)
        self.holds = 0
        self.telemetry: Telemetry = NullTelemetry()
        self.monitor: OnlineMonitor | None = None
        self.metrics: SiteMetrics | None = None  # set by the bridge when /metrics is served
        self._live = False  # telemetry on: publish steps, status and events
        self._reset_signals()

    # -- sessions ------------------------------------------------------------------------------
    def _reset_signals(self) -> None:
        n, na = self.cfg.dofs, self.setup.n_actuators
        self.step = 0
        self.time = 0.0
        self.trial = Signals(disp=(0.0,) * n, vel=(0.0,) * n, accel=(0.0,) * n, time=(0.0,))
        self.ctrl: tuple[float, ...] = (0.0,) * na
        self._sent_ctrl: tuple[float, ...] | None = None
        self.daq = Daq((0.0,) * na, (0.0,) * na)
        self._daq_valid = False
        self._k_tangent: tuple[float, ...] = (0.0,) * (n * n)
        self._k_initial: tuple[float, ...] | None = None

    @property
    def busy(self) -> bool:
        return self.state in (SiteState.RUNNING, SiteState.HOLD) and self.peer != ""

    def open_session(self, peer: str) -> int:
        if self.busy:
            raise SiteError(f"site {self.name} is busy with {self.peer} (one client per site)")
        if self.state is SiteState.FAULT:
            raise SiteError(f"site {self.name} is in FAULT ({self.hold_reason}); not accepting")
        self.session += 1
        self.peer = peer
        self.state = SiteState.RUNNING
        self.hold_reason = ""
        self._reset_signals()
        reset = getattr(self.controller, "reset", None)
        if reset is not None and getattr(self.cfg.controller, "reset_on_new_session", False):
            reset()
        log.info("site %s: session %d opened by %s", self.name, self.session, peer)
        self._event("session-open", f"client {peer} connected", peer=peer)
        return self.session

    def close_session(self, reason: str, *, error: bool = False) -> None:
        if not self.peer:
            return
        (log.warning if error else log.info)(
            "site %s: session %d closed after %d step(s): %s", self.name, self.session,
            self.step, reason,
        )
        self._event("session-close", reason, steps=self.step, error=error)
        self.peer = ""
        if self.state is not SiteState.FAULT:
            self.state = SiteState.IDLE

    def check_sizes(self, ctrl: SignalSizes, daq: SignalSizes, who: str) -> None:
        """OpenFresco's rule: every non-zero size equals the element's DOFs, time sizes are 1."""
        n = self.cfg.dofs
        problems = []
        if ctrl.disp != n:
            problems.append(f"ctrl disp size {ctrl.disp} != {n} DOF(s) served by the site")
        for label, v in (("ctrl vel", ctrl.vel), ("ctrl accel", ctrl.accel),
                         ("daq disp", daq.disp), ("daq vel", daq.vel),
                         ("daq accel", daq.accel), ("daq force", daq.force)):
            if v not in (0, n):
                problems.append(f"{label} size {v} is neither 0 nor {n}")
        if ctrl.force:
            problems.append(f"ctrl force size {ctrl.force}: force control is not supported")
        for label, v in (("ctrl time", ctrl.time), ("daq time", daq.time)):
            if v not in (0, 1):
                problems.append(f"{label} size {v} is neither 0 nor 1")
        if problems:
            raise SiteError(f"{who} sizes do not fit site {self.name}: " + "; ".join(problems))

    # -- safety ----------------------------------------------------------------------------------
    def enter_hold(self, reason: str) -> None:
        if self.state is SiteState.HOLD:
            return
        self.state = SiteState.HOLD
        self.hold_reason = reason
        self.holds += 1
        log.error("site %s: HOLD at step %d: %s", self.name, self.step, reason)
        self._event("hold", reason, step=self.step)
        hold = self.controller.hold()
        if self.controller.inline:
            _run_inline(hold)
        else:
            asyncio.get_running_loop().create_task(self._call(hold), name=f"{self.name}.hold")

    def attach_telemetry(self, telemetry: Telemetry, monitor: OnlineMonitor | None) -> None:
        self.telemetry, self.monitor, self._live = telemetry, monitor, True
        self._publish_status()

    def _publish_status(self) -> None:
        if self._live:
            self.telemetry.publish_status(SiteStatus(
                site=self.name, state=str(self.state), session=self.session, step=self.step,
                time=self.time, reason=self.hold_reason, holds=self.holds,
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

    def _call(self, coro: Coroutine[Any, Any, T]) -> Awaitable[T]:
        """Every controller call gets the deadline; in-process ones complete at once."""
        if self.controller.inline:
            return coro
        return asyncio.wait_for(coro, self.timeout)

    async def _guard(self, coro: Coroutine[Any, Any, T], what: str) -> T | None:
        try:
            return await self._call(coro)
        except TimeoutError:
            self.enter_hold(f"controller did not answer {what} within {self.timeout:g} s")
        except ControllerError as exc:
            self.enter_hold(f"controller failed on {what}: {exc}")
        return None

    # -- the step ------------------------------------------------------------------------------
    async def set_trial(self, trial: Signals) -> None:
        """Code 3: validate, transform, forward. Never forwards a non-finite command."""
        values = trial.disp + trial.vel + trial.accel + trial.time
        if not all(math.isfinite(v) for v in values):
            if self.state is not SiteState.HOLD:
                bad = [v for v in values if not math.isfinite(v)]
                self.enter_hold(f"non-finite trial value(s) {bad} (disp {list(trial.disp)}); "
                                "not forwarded to the controller")
            return
        self.trial = trial
        if trial.time:
            self.time = trial.time[0]
        ctrl = self.setup.ctrl_disp(trial.disp)
        if self.state is SiteState.HOLD:
            return
        self.ctrl = ctrl
        self._daq_valid = False
        if self.record is not None:
            self.record.trial(self.name, self.session, self.step, self.time, trial.disp, ctrl)
        if ctrl != self._sent_ctrl:
            await self._guard(self.controller.set_ctrl(ctrl), "set_ctrl")
            self._sent_ctrl = ctrl

    async def acquire(self) -> Daq:
        """The measurement for the current command, acquired once per trial."""
        if self._daq_valid or self.state is SiteState.HOLD:
            return self.daq
        daq = await self._guard(self.controller.get_daq(), "get_daq")
        if daq is None:
            return self.daq
        if not all(math.isfinite(v) for v in daq.disp + daq.force):
            self.enter_hold(f"controller returned non-finite measurements {daq}")
            return self.daq
        self.daq = daq
        self._daq_valid = True
        if self.record is not None:
            self.record.measurement(self.name, self.session, self.step, daq.disp, daq.force)
        return daq

    async def commit(self) -> None:
        if self.state is SiteState.HOLD:
            return
        await self.acquire()  # every committed step has its measurement in the record
        await self._guard(self.controller.commit(), "commit")
        self.step += 1
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
                self._event("monitor-warning", sample.warning)
        self.telemetry.publish_step(StepSample(
            self.name, self.session, self.step, self.time, self.trial.disp, self.ctrl,
            self.daq.disp, self.daq.force, str(self.state), None, sample,
        ))

    async def out_signals(self, sizes: SignalSizes) -> Signals:
        """Measured signals in basic DOFs (OpenFresco *out*), blocks as the client sized them."""
        daq = await self.acquire()
        disp = self.setup.out_disp(self.trial.disp, self.ctrl, daq.disp)
        force = self.setup.basic_force(daq.force)
        return Signals(
            disp=disp if sizes.disp else (),
            vel=self.trial.vel if sizes.vel else (),
            accel=self.trial.accel if sizes.accel else (),
            force=force if sizes.force else (),
            time=(self.time,) if sizes.time else (),
        )

    async def tangent(self) -> tuple[float, ...]:
        """Tangent in basic DOFs; in HOLD (or on failure) the last good one."""
        if self.state is not SiteState.HOLD:
            k = await self._guard(self.controller.tangent_stiffness(), "tangent_stiffness")
            if k is not None:
                self._k_tangent = self.setup.basic_matrix(k)
        return self._k_tangent

    async def initial(self) -> tuple[float, ...]:
        if self._k_initial is None or self.state is not SiteState.HOLD:
            k = await self._guard(self.controller.initial_stiffness(), "initial_stiffness")
            if k is not None:
                self._k_initial = self.setup.basic_matrix(k)
        return self._k_initial if self._k_initial is not None else self._k_tangent


def _run_inline(coro: Coroutine[Any, Any, Any]) -> None:
    from ..eager import Suspended, start_eager

    r = start_eager(coro)
    if isinstance(r, Suspended):
        r.task()
