"""Protocol-neutral controller state machine shared by the Modbus and MTS-like servers.

It owns a :class:`~sim_actuator.rig.Rig` and drives its moves on the asyncio loop without
blocking it: a move is stepped in chunks of substeps, yielding to the loop between chunks
(``time_scale`` 0, the default, runs as fast as possible; ``time_scale`` s = wall seconds per
simulated second otherwise). When ``time_scale`` is 0 the first chunk runs inside
:meth:`RigController.execute`, so short moves (and every move of an ideal rig, which takes a
single increment) are already DONE when ``execute`` returns. When ``time_scale`` > 0 every move
is stepped substep by substep in pace with the wall clock (no ideal-chain shortcut), so an
interlock stops it where the piston physically is.

States: IDLE (nothing run since start/reset/interlock release), MOVING, DONE (last move
completed), FAULT (latched: stroke or force limit), INTERLOCK (program interlock engaged;
engaging it during a move stops the move where it is).
"""

from __future__ import annotations

import asyncio
import contextlib
import math

from sim_actuator.rig import (
    FaultCode,
    Measurement,
    Move,
    MoveOutcome,
    Rig,
    RigCommandError,
    RigFault,
)
from sim_actuator.wire.states import ControllerState

__all__ = [
    "CommandRejected",
    "ControllerBusy",
    "ControllerError",
    "ControllerFaulted",
    "ControllerInterlocked",
    "ControllerState",
    "LimitExceeded",
    "RigController",
    "UnknownMove",
]


class ControllerError(Exception):
    """A request the controller refuses; ``code`` is the MTS-stub error token."""

    code = "ERROR"


class ControllerBusy(ControllerError):
    """A different move is running."""

    code = "BUSY"


class ControllerFaulted(ControllerError):
    """A fault is latched; reset first."""

    code = "FAULT"


class ControllerInterlocked(ControllerError):
    """The program interlock is engaged."""

    code = "INTERLOCK"


class CommandRejected(ControllerError):
    """The command is malformed (not finite, bad ramp time); nothing changed."""

    code = "BAD_VALUE"


class LimitExceeded(ControllerError):
    """The command is beyond the stroke; the controller is now in FAULT, nothing moved."""

    code = "LIMIT"


class UnknownMove(ControllerError):
    """A move id that is not the current or last move."""

    code = "UNKNOWN_RAMP"


class RigController:
    """Rig + state machine + heartbeat; every method is called from the event loop."""

    def __init__(self, rig: Rig, *, time_scale: float = 0.0, chunk_substeps: int = 32) -> None:
        if not (math.isfinite(time_scale) and time_scale >= 0.0):
            raise ValueError(f"time_scale must be finite and >= 0, got {time_scale!r}")
        if chunk_substeps < 1:
            raise ValueError(f"chunk_substeps must be >= 1, got {chunk_substeps!r}")
        self.rig = rig
        self.time_scale = float(time_scale)
        self.chunk_substeps = int(chunk_substeps)
        self.heartbeat = 0
        self.sequence = 0
        """Completed moves (wraps at 2**16 on the Modbus register)."""
        self.move_id = 0
        """Id of the current or last accepted move (0: none yet)."""
        self.target = rig.command
        self.ramp_time = rig.default_ramp_time
        self.interlock = False
        self.outcome = MoveOutcome.DONE
        """How the last move ended (RUNNING while one is)."""
        self.measurement: Measurement = rig.measure(noisy=False)
        self._phase = ControllerState.IDLE
        self._move: Move | None = None
        self._drive_task: asyncio.Task[None] | None = None
        self._heartbeat_task: asyncio.Task[None] | None = None
        self._idle = asyncio.Event()
        self._idle.set()

    # -- state --------------------------------------------------------------------------------

    @property
    def fault(self) -> FaultCode:
        """The latched fault of the rig (NONE when healthy)."""
        return self.rig.fault

    @property
    def state(self) -> ControllerState:
        """FAULT and INTERLOCK take precedence over the move phase."""
        if self._phase is ControllerState.MOVING:
            return ControllerState.MOVING
        if self.rig.fault is not FaultCode.NONE:
            return ControllerState.FAULT
        if self.interlock:
            return ControllerState.INTERLOCK
        return self._phase

    # -- commands -----------------------------------------------------------------------------

    def execute(self, target: float, ramp_time: float) -> int:
        """Start a move (absolute target); return its id. Same target while moving: no-op."""
        if self._phase is ControllerState.MOVING:
            if target == self.target and ramp_time == self.ramp_time:
                return self.move_id
            raise ControllerBusy(
                f"move {self.move_id} to {self.target!r} mm is still running; "
                f"wait for it before commanding {target!r} mm"
            )
        if self.rig.fault is not FaultCode.NONE:
            raise ControllerFaulted(f"fault {self.rig.fault.name} is latched; reset first")
        if self.interlock:
            raise ControllerInterlocked("the program interlock is engaged; release it first")
        try:
            move = self.rig.begin_move(target, ramp_time, shortcut=self.time_scale == 0.0)
        except RigCommandError as exc:
            raise CommandRejected(str(exc)) from None
        except RigFault as exc:
            raise LimitExceeded(str(exc)) from None
        self.move_id += 1
        self.target, self.ramp_time = target, ramp_time
        self._move = move
        self.outcome = MoveOutcome.RUNNING
        self._phase = ControllerState.MOVING
        self._idle.clear()
        if self.time_scale == 0.0 and move.advance(self.chunk_substeps):
            self._complete(move)
        else:
            self._drive_task = asyncio.get_running_loop().create_task(self._drive(move))
        return self.move_id

    async def wait(self, timeout: float) -> bool:
        """Wait until no move is running; False if ``timeout`` (wall seconds) passed first."""
        if self._idle.is_set():
            return True
        try:
            await asyncio.wait_for(self._idle.wait(), timeout)
        except TimeoutError:
            return False
        return True

    def reset(self) -> None:
        """Clear a latched fault (bumpless: the servo stays where it is)."""
        if self.rig.fault is not FaultCode.NONE and self._phase is not ControllerState.MOVING:
            self.rig.reset_fault()
            self._phase = ControllerState.IDLE

    def set_interlock(self, engaged: bool) -> None:
        """Engage (stops a running move where it is) or release the program interlock."""
        if engaged and not self.interlock:
            self.interlock = True
            if self._move is not None and self._phase is ControllerState.MOVING:
                if self._drive_task is not None:
                    self._drive_task.cancel()
                    self._drive_task = None
                self._move.abort()
                self._complete(self._move)
        elif not engaged and self.interlock:
            self.interlock = False
            self._phase = ControllerState.IDLE

    def feedback(self, move_id: int = -1) -> tuple[int, Measurement]:
        """Feedback of move ``move_id`` (its end measurement) or, for -1, a fresh reading now."""
        if move_id == -1:
            return self.move_id, self.rig.measure()
        if move_id != self.move_id or move_id == 0:
            raise UnknownMove(
                f"move {move_id} is unknown; the last move is {self.move_id} "
                "(use -1 for the current feedback)"
            )
        if self._phase is ControllerState.MOVING:
            raise ControllerBusy(f"move {move_id} is still running")
        return move_id, self.measurement

    # -- background tasks ---------------------------------------------------------------------

    def start_heartbeat(self, rate_hz: float = 10.0) -> None:
        """Start incrementing :attr:`heartbeat` at ``rate_hz`` (so a master can see staleness)."""
        if not (math.isfinite(rate_hz) and rate_hz > 0.0):
            raise ValueError(f"heartbeat rate must be > 0 Hz, got {rate_hz!r}")
        if self._heartbeat_task is None:
            self._heartbeat_task = asyncio.get_running_loop().create_task(
                self._beat(1.0 / rate_hz)
            )

    async def close(self) -> None:
        """Stop the background tasks (a running move is left where it is)."""
        tasks = [t for t in (self._drive_task, self._heartbeat_task) if t is not None]
        self._drive_task = self._heartbeat_task = None
        for task in tasks:
            task.cancel()
        for task in tasks:
            with contextlib.suppress(asyncio.CancelledError):
                await task

    async def _beat(self, period: float) -> None:
        loop = asyncio.get_running_loop()
        start, n = loop.time(), 0
        while True:
            n += 1
            await asyncio.sleep(max(0.0, start + n * period - loop.time()))
            self.heartbeat = (self.heartbeat + 1) & 0xFFFF

    async def _drive(self, move: Move) -> None:
        loop = asyncio.get_running_loop()
        wall_start, dt = loop.time(), self.rig.dt
        while True:
            done = move.advance(self.chunk_substeps)
            if self.time_scale > 0.0:
                due = wall_start + self.time_scale * move.substeps_done * dt
                await asyncio.sleep(max(0.0, due - loop.time()))
            elif not done:
                await asyncio.sleep(0)
            if done:
                break
        self._drive_task = None
        self._complete(move)

    def _complete(self, move: Move) -> None:
        if move.measurement is not None:
            self.measurement = move.measurement
        self.outcome = move.outcome
        if move.outcome is MoveOutcome.DONE:
            self.sequence += 1
            self._phase = ControllerState.DONE
        else:  # TRIPPED (fault latched in the rig) or ABORTED (interlock engaged)
            self._phase = ControllerState.IDLE
        self._move = None
        self._idle.set()
