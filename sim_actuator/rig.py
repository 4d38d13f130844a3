"""The simulated test rig: ramp-and-hold moves on an explicit simulated clock.

A move ramps the servo reference linearly from where the last move left it to the new end
point over ``ramp_time``, then holds it for ``settle_time``, then the sensors are read (the
pseudo-dynamic hold-and-measure cycle). The rig advances in fixed substeps of ``dt``; at every
substep the actuator stages produce the piston position and the load path solves equilibrium
and commits the specimen, so the specimen follows the physical path (unlike the bridge's
in-process controller, which uses material trial/commit semantics).

Exactness with an ideal chain: when the actuator is ideal and no load-path effect is active,
nothing between the reference and the specimen depends on the intermediate substeps, and the
path of the move is monotone. The rig then gives the specimen the whole move as one increment
(one ``set_trial`` and ``commit``), exactly what the in-process controller does per step, so the
measured (d, f) equals the bare model at the target to the last bit (with noise and bias off);
the clock still advances by the full move duration. The lab end-to-end test relies on this.

Faults latch until :meth:`Rig.reset_fault`: a command beyond the stroke is refused with no
motion (STROKE_LIMIT); a load-cell force beyond capacity trips the move within the substep where
it happens (FORCE_LIMIT) and the servo is re-initialised at rest where it stopped.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from enum import IntEnum

from sim_actuator.actuator import Actuator
from sim_actuator.checks import NON_NEGATIVE
from sim_actuator.effects import LoadPath, LoadPathState, Sensor
from sim_actuator.wire.states import FaultCode

__all__ = [
    "FaultCode",
    "Measurement",
    "Move",
    "MoveOutcome",
    "Rig",
    "RigBusyError",
    "RigCommandError",
    "RigError",
    "RigFault",
]

_QUANTUM = 1e-9  # relative slack when converting durations to whole substeps


class MoveOutcome(IntEnum):
    """How a move ended."""

    RUNNING = 0
    DONE = 1
    TRIPPED = 2
    ABORTED = 3


class RigError(Exception):
    """Base class of the rig's errors."""


class RigCommandError(RigError, ValueError):
    """A command is malformed (not finite, negative or too long ramp); nothing happened."""


class RigBusyError(RigError):
    """A move is still running."""


class RigFault(RigError):
    """The rig is (now) in a latched fault; ``code`` says which, ``measurement`` if it moved."""

    def __init__(self, code: FaultCode, message: str,
                 measurement: Measurement | None = None) -> None:
        super().__init__(f"{code.name}: {message}")
        self.code = code
        self.measurement = measurement


@dataclass(frozen=True, slots=True)
class Measurement:
    """Sensor readings at one instant, plus the true values behind them (for diagnosis)."""

    time: float
    """Simulated time, s."""
    command: float
    """Commanded target of the last move, mm."""
    displacement: float
    """LVDT reading (true value + bias + noise), mm."""
    force: float
    """Load-cell reading (true value + bias + noise), kN."""
    actuator_displacement: float
    """True piston stroke x, mm."""
    specimen_displacement: float
    """True specimen displacement u, mm."""
    specimen_force: float
    """True force through the connection into the specimen, kN."""
    load_cell_force: float
    """True load-cell force (connection + friction), kN."""


class Rig:
    """Actuator + load path + sensors on a simulated clock; see the module docstring."""

    def __init__(
        self,
        *,
        actuator: Actuator,
        load_path: LoadPath,
        lvdt: Sensor | None = None,
        load_cell: Sensor | None = None,
        lvdt_location: str = "actuator",
        settle_time: float = 0.0,
        default_ramp_time: float = 1.0,
        max_ramp_time: float = 600.0,
    ) -> None:
        if not math.isclose(actuator.dt, load_path.dt, rel_tol=1e-12):
            raise ValueError(f"actuator dt {actuator.dt!r} != load path dt {load_path.dt!r}")
        if lvdt_location not in ("actuator", "specimen"):
            raise ValueError(
                f"lvdt_location must be 'actuator' or 'specimen', got {lvdt_location!r}"
            )
        for name, value in (("settle_time", settle_time), ("max_ramp_time", max_ramp_time)):
            NON_NEGATIVE.check(name, value)  # ParameterRangeError is a ValueError
        self.actuator = actuator
        self.load_path = load_path
        self.lvdt = lvdt if lvdt is not None else Sensor()
        self.load_cell = load_cell if load_cell is not None else Sensor()
        self.lvdt_location = lvdt_location
        self.settle_time = float(settle_time)
        self.max_ramp_time = float(max_ramp_time)
        self.default_ramp_time = self._check_ramp_time(default_ramp_time)
        self.dt = actuator.dt
        self._substeps = 0
        d0 = load_path.state.fixture
        self._reference = d0 / actuator.amplitude
        self._position = d0
        self._command = d0
        self.actuator.reset(d0)
        self.fault = FaultCode.NONE
        self.moves_completed = 0
        self._move: Move | None = None

    # -- read-only state ----------------------------------------------------------------------

    @property
    def time(self) -> float:
        """Simulated time, s (whole substeps times dt)."""
        return self._substeps * self.dt

    @property
    def reference(self) -> float:
        """Current servo reference, mm."""
        return self._reference

    @property
    def position(self) -> float:
        """True piston stroke x, mm."""
        return self._position

    @property
    def command(self) -> float:
        """Target of the last accepted move, mm."""
        return self._command

    @property
    def moving(self) -> bool:
        """True while a move is running."""
        return self._move is not None and self._move.outcome is MoveOutcome.RUNNING

    @property
    def state(self) -> LoadPathState:
        """True load-path state after the last substep."""
        return self.load_path.state

    @property
    def is_kinematic(self) -> bool:
        """True when the ideal-chain shortcut applies (see the module docstring)."""
        return self.actuator.is_ideal and self.load_path.is_kinematic

    # -- commands ------------------------------------------------------------------------------

    def validate(self, target: float, ramp_time: float | None = None) -> float:
        """Check a command without moving; return the ramp time to use.

        Raises :class:`RigCommandError` (nothing latched) or :class:`RigFault` (latched).
        """
        if not math.isfinite(target):
            raise RigCommandError(f"target displacement must be finite, got {target!r}")
        ramp = self.default_ramp_time if ramp_time is None else self._check_ramp_time(ramp_time)
        if self.fault is not FaultCode.NONE:
            raise RigFault(self.fault, "the rig is in a latched fault; reset it first")
        if self.moving:
            raise RigBusyError("a move is still running")
        stroke = self.actuator.stroke
        if abs(target) > stroke:
            self.fault = FaultCode.STROKE_LIMIT
            raise RigFault(
                FaultCode.STROKE_LIMIT,
                f"target {target!r} mm is beyond the actuator stroke +-{stroke!r} mm; not moved",
            )
        return ramp

    def begin_move(self, target: float, ramp_time: float | None = None, *,
                   shortcut: bool = True) -> Move:
        """Start a ramp-and-hold move to ``target``; step it with :meth:`Move.advance`.

        ``shortcut=False`` steps even an ideal chain substep by substep, so that the move can be
        stopped partway (a server pacing moves in wall time needs that).
        """
        ramp = self.validate(target, ramp_time)
        start = self._reference
        end = self.actuator.end_point(target, self._command)
        if abs(self.actuator.amplitude * end) > self.actuator.stroke:
            self.fault = FaultCode.STROKE_LIMIT
            raise RigFault(
                FaultCode.STROKE_LIMIT,
                f"target {target!r} mm would drive the piston to "
                f"{self.actuator.amplitude * end!r} mm, beyond the stroke; not moved",
            )
        self._command = target
        self._move = Move(self, target=target, start=start, end=end, ramp_time=ramp,
                          shortcut=shortcut)
        return self._move

    def execute(self, target: float, ramp_time: float | None = None) -> Measurement:
        """Run a whole move synchronously and return the measurement at its end.

        Raises :class:`RigFault` if the move trips (its ``measurement`` is the trip instant).
        """
        move = self.begin_move(target, ramp_time)
        move.advance()
        assert move.measurement is not None
        if move.outcome is MoveOutcome.TRIPPED:
            raise RigFault(FaultCode.FORCE_LIMIT, move.trip_message, move.measurement)
        return move.measurement

    def measure(self, *, noisy: bool = True) -> Measurement:
        """Read both sensors now; the clock does not advance.

        Each call draws fresh noise; ``noisy=False`` reads true value + bias and draws nothing,
        so the noise streams stay aligned with an identical rig that did not look.
        """
        state = self.load_path.state
        true_d = self._position if self.lvdt_location == "actuator" else (
            state.specimen_displacement
        )
        return Measurement(
            time=self.time,
            command=self._command,
            displacement=self.lvdt.read(true_d, noisy=noisy),
            force=self.load_cell.read(state.load_cell_force, noisy=noisy),
            actuator_displacement=self._position,
            specimen_displacement=state.specimen_displacement,
            specimen_force=state.connection_force,
            load_cell_force=state.load_cell_force,
        )

    def reset_fault(self) -> None:
        """Clear a latched fault; the servo stays at rest where it is (bumpless)."""
        if self.moving:
            raise RigBusyError("cannot reset a fault while a move is running")
        self.fault = FaultCode.NONE

    # -- internals -----------------------------------------------------------------------------

    def _check_ramp_time(self, ramp_time: float) -> float:
        value = float(ramp_time)
        if not (math.isfinite(value) and 0.0 <= value <= self.max_ramp_time):
            raise RigCommandError(
                f"ramp time must be finite and within [0, {self.max_ramp_time!r}] s, "
                f"got {ramp_time!r}"
            )
        return value

    def _substeps_for(self, duration: float) -> int:
        return max(0, math.ceil(duration / self.dt - _QUANTUM * max(1.0, duration / self.dt)))

    def _stop_at_rest(self) -> None:
        """Hold the piston where it is: every servo stage at rest there (after trip or abort)."""
        self.actuator.reset(self._position)
        self._reference = self._position / self.actuator.amplitude
        self.load_path.settle_at_rest()


class Move:
    """One ramp-and-hold move, stepped in chunks so a server can stay responsive."""

    def __init__(self, rig: Rig, *, target: float, start: float, end: float,
                 ramp_time: float, shortcut: bool = True) -> None:
        self.rig = rig
        self.shortcut = shortcut
        self.target = target
        self.start = start
        self.end = end
        self.ramp_time = ramp_time
        self._ramp_steps = rig._substeps_for(ramp_time)
        self.n_substeps = max(1, self._ramp_steps + rig._substeps_for(rig.settle_time))
        self.substeps_done = 0
        self.outcome = MoveOutcome.RUNNING
        self.measurement: Measurement | None = None
        self.trip_message = ""

    @property
    def duration(self) -> float:
        """Simulated duration of the whole move, s."""
        return self.n_substeps * self.rig.dt

    def advance(self, max_substeps: int | None = None) -> bool:
        """Advance up to ``max_substeps`` substeps (all if None); True once the move has ended."""
        if self.outcome is not MoveOutcome.RUNNING:
            return True
        rig = self.rig
        if self.shortcut and rig.is_kinematic and self._shortcut():
            return True
        last = self.n_substeps if max_substeps is None else min(
            self.n_substeps, self.substeps_done + max(1, max_substeps)
        )
        actuator, load_path = rig.actuator, rig.load_path
        capacity = actuator.force_capacity
        start, end, span = self.start, self.end, self.end - self.start
        ramp_steps, ramp_time, dt = self._ramp_steps, self.ramp_time, rig.dt
        for k in range(self.substeps_done + 1, last + 1):
            reference = end if k >= ramp_steps else start + span * (k * dt / ramp_time)
            rig._reference = reference
            rig._position = actuator.step(reference)
            rig._substeps += 1
            self.substeps_done = k
            state = load_path.step(rig._position)
            if abs(state.load_cell_force) > capacity:
                self._trip(state.load_cell_force, capacity)
                return True
        if self.substeps_done >= self.n_substeps:
            self._finish(MoveOutcome.DONE)
            return True
        return False

    def abort(self) -> None:
        """Stop now (interlock): the servo holds the current position; no fault latched."""
        if self.outcome is MoveOutcome.RUNNING:
            self.rig._stop_at_rest()
            self._finish(MoveOutcome.ABORTED)

    def _shortcut(self) -> bool:
        """Ideal chain: one specimen increment to the end point, if within force capacity."""
        rig = self.rig
        specimen = rig.load_path.specimen
        force, _ = specimen.set_trial(self.end)
        if abs(force) > rig.actuator.force_capacity:
            return False  # take the substep path so the trip happens where it would
        rig.load_path.impose(self.end)
        rig._reference = rig._position = self.end
        rig._substeps += self.n_substeps - self.substeps_done
        self.substeps_done = self.n_substeps
        self._finish(MoveOutcome.DONE)
        return True

    def _trip(self, force: float, capacity: float) -> None:
        rig = self.rig
        rig.fault = FaultCode.FORCE_LIMIT
        self.trip_message = (
            f"load-cell force {force!r} kN exceeded the capacity +-{capacity!r} kN at "
            f"t = {rig.time!r} s, piston at {rig.position!r} mm; move stopped"
        )
        rig._stop_at_rest()
        self._finish(MoveOutcome.TRIPPED)

    def _finish(self, outcome: MoveOutcome) -> None:
        self.outcome = outcome
        self.measurement = self.rig.measure()
        if outcome is MoveOutcome.DONE:
            self.rig.moves_completed += 1
