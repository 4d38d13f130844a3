"""The outer-loop displacement correction of one step, against the controller contract.

Command the target, wait until the controller reports it reached, read the measured
displacement (the daq channel, or the controller's external one), and while the pure verdict
(``safety/correction.py``) proposes another command, send that — every command through a
``CommandPath``, the site's one way to move the controller (limits, state table, guard). The
loop never talks to the controller itself, so a correction cannot bypass a limit.

``LimitedPath`` is that path without a site: the ctrl and daq limits (``reject``/``pause`` →
HOLD, since there is no operator to wait for; ``clamp`` and sub-commands as the site does them)
and the state table. The experimental site passes its own gate instead.

Wiring a site: build ``CorrectionLoop(path, config.to_settings(n), controller,
external=config.measured == "external")`` once, with ``path`` the site's gate (``send``: limits,
pause, guard; ``acquire``: the site's daq read and checks; ``hold``: ``enter_hold``); per trial,
``await loop.run(ctrl)`` where the site sent ``ctrl`` and acquired; answer with ``step.daq``,
record ``step.as_record()``, report ``corrections``/``residual`` and warn on ``step.warn``.
"""

from __future__ import annotations

import contextlib
import math
from dataclasses import dataclass
from typing import Protocol

from ..controls.base import Controller, ControllerError, Daq
from ..safety import Limiter, SiteState, Trigger, next_state
from ..safety.correction import (
    REFUSED,
    CorrectionSettings,
    Terminal,
    correct,
    needs_warning,
    residual,
)

__all__ = ["CommandPath", "CorrectionLoop", "Iteration", "LimitedPath", "StepCorrection"]


class CommandPath(Protocol):
    """How a site moves its controller; the correction loop uses nothing else."""

    async def send(self, ctrl: tuple[float, ...]) -> tuple[float, ...] | None:
        """Forward ``ctrl`` through the limits and the state table and wait until it is reached;
        the command the controller holds now (``ctrl``, or what a ``clamp`` made of it), or
        None when nothing more may be forwarded (the path has put the site in HOLD, or it is
        not running)."""
        ...

    async def acquire(self) -> Daq | None:
        """The measurement at the command reached (daq limits checked); None: the path HOLDs."""
        ...

    async def hold(self, reason: str) -> None:
        """Enter HOLD through the state table (the correction's own verdict)."""
        ...


@dataclass(frozen=True, slots=True)
class Iteration:
    """One command at the controller and the displacement measured there (mm)."""

    command: tuple[float, ...]
    measured: tuple[float, ...]


@dataclass(frozen=True, slots=True)
class StepCorrection:
    """One step's correction: what the record keeps and status reports."""

    target: tuple[float, ...]
    iterations: tuple[Iteration, ...]
    """The target's own command first (or the command already held for it), then every
    corrected one."""
    verdict: Terminal
    daq: Daq | None
    """The last measurement (the integrator's answer), None if refused before any."""
    warn: bool
    """More than half of ``max_iterations`` corrections were needed."""
    residual: float
    """Largest |target − measured| of the corrected control points at the end, mm (NaN
    without a measurement)."""

    @property
    def corrections(self) -> int:
        """Corrected commands sent after the target."""
        return max(0, len(self.iterations) - 1)

    def as_record(self) -> dict[str, object]:
        return {"target": list(self.target), "outcome": self.verdict.outcome,
                "corrections": self.corrections, "residual": self.residual,
                "iterations": [{"command": list(i.command), "measured": list(i.measured)}
                               for i in self.iterations]}


class CorrectionLoop:
    """The correction of one site's steps; ``run(target)`` per step."""

    def __init__(self, path: CommandPath, settings: CorrectionSettings, controller: Controller,
                 *, external: bool = False) -> None:
        if settings.n != controller.n_actuators:
            raise ValueError(f"correction: {settings.n} control point(s), the controller "
                             f"drives {controller.n_actuators}")
        if external and controller.external_channel is None:
            raise ValueError("correction: measured = \"external\", but the controller has no "
                             "external channel configured (see docs/configuration.md, "
                             "\"Which displacement is measured\")")
        self.path = path
        self.settings = settings
        self.external = external

    def measured(self, daq: Daq) -> tuple[float, ...]:
        """The displacement the correction compares with the target."""
        if not self.external:
            return daq.disp
        if daq.external is None:
            raise ControllerError("correction: the controller's measurement has no external "
                                  "channel")
        return daq.external

    async def run(self, target: tuple[float, ...], *,
                  held: tuple[float, ...] | None = None) -> StepCorrection:
        """Move to ``target`` and correct until a verdict; a HOLD verdict is entered through
        the path before returning. ``held``: the command the controller holds already for this
        same target (an integrator that sends its trial again): nothing is sent first, the
        correction goes on from there (sending the target again would move the specimen back
        short of it, an excursion the integrator did not ask for)."""
        settings, path = self.settings, self.path
        iterations: list[Iteration] = []
        daq: Daq | None = None
        reached = await path.send(target) if held is None else held
        while reached is not None:
            daq = await path.acquire()
            if daq is None:
                break
            measured = self.measured(daq)
            iterations.append(Iteration(reached, measured))
            verdict = correct(settings, target, reached, measured, len(iterations) - 1)
            if isinstance(verdict, Terminal):
                if verdict.hold:
                    await path.hold(f"displacement correction: {verdict.describe()}")
                return self._step(target, iterations, verdict, daq)
            reached = await path.send(verdict)
        return self._step(target, iterations, REFUSED, daq)

    def _step(self, target: tuple[float, ...], iterations: list[Iteration], verdict: Terminal,
              daq: Daq | None) -> StepCorrection:
        settings = self.settings
        left = residual(settings, target, iterations[-1].measured) if iterations else math.nan
        return StepCorrection(target, tuple(iterations), verdict, daq,
                              needs_warning(settings, max(0, len(iterations) - 1)), left)


class LimitedPath:
    """A ``CommandPath`` without a site: limits and state table in front of one controller."""

    def __init__(self, controller: Controller, limiter: Limiter, *, dt: float = 0.0) -> None:
        self.controller = controller
        self.limiter = limiter
        self.dt = dt
        """Step time for velocity limits without their own ``step_time`` (<= 0: unknown)."""
        self.state = next_state(SiteState.IDLE, Trigger.SESSION_OPEN, in_session=False)
        self.reason = ""
        self.reference: tuple[float, ...] | None = None
        self.sent: list[tuple[float, ...]] = []
        """Every command forwarded to the controller, in order."""

    async def send(self, ctrl: tuple[float, ...]) -> tuple[float, ...] | None:
        if self.state != SiteState.RUNNING:
            return None
        verdict = self.limiter.check_ctrl(ctrl, self.reference, self.dt) \
            if self.limiter.has_ctrl else None
        commands = (ctrl,) if verdict is None else verdict.commands
        if not commands:  # reject, or pause with nobody to resume it
            await self.hold(verdict.describe() if verdict is not None else "refused")
            return None
        for command in commands:
            try:
                await self.controller.set_ctrl(command)
            except ControllerError as exc:
                await self.hold(str(exc))
                return None
            self.sent.append(command)
            self.reference = command
        return commands[-1]

    async def acquire(self) -> Daq | None:
        if self.state != SiteState.RUNNING:
            return None
        try:
            daq = await self.controller.get_daq()
        except ControllerError as exc:
            await self.hold(str(exc))
            return None
        hit = self.limiter.check_daq(daq.force) if self.limiter.has_daq else None
        if hit is not None:
            await self.hold(hit.describe())
            return None
        return daq

    async def hold(self, reason: str) -> None:
        self.state = next_state(self.state, Trigger.HOLD, in_session=True)
        self.reason = reason
        with contextlib.suppress(ControllerError):  # nothing more is forwarded either way; the
            await self.controller.hold()           # reason above stays the cause
