"""``[[sites.limits]]``: one table per control point, validated (defaults: no limits at all);
``[sites.correction]``: the outer-loop displacement correction (off when absent)."""

from __future__ import annotations

from typing import Literal

from pydantic import Field, model_validator

from ..config_model import StrictConfig
from .correction import CorrectionSettings
from .limits import INF, ControlPointLimits


class ControlPointLimitsConfig(StrictConfig):
    """Limits of one control point (an actuator DOF, i.e. after the setup). Units mm, kN, s.
    Every value is finite (``StrictConfig``): a NaN bound would switch its limit off."""

    actuator: int = Field(default=1, ge=1, le=64)
    """Control point, 1-based: the actuator index after the setup transformation."""
    disp_min: float | None = None
    """Lowest ctrl displacement (mm) that may be commanded."""
    disp_max: float | None = None
    """Highest ctrl displacement (mm) that may be commanded."""
    disp_increment: float | None = Field(default=None, gt=0)
    """Largest |ctrl − last command sent| (mm) of one command."""
    velocity: float | None = Field(default=None, gt=0)
    """Largest |ctrl − last command sent| / dt (mm/s)."""
    step_time: float | None = Field(default=None, gt=0)
    """dt (s) for the velocity limit; default: trial time minus the last committed time."""
    policy: Literal["reject", "clamp", "pause"] = "reject"
    """Past a ctrl limit: ``reject`` → HOLD, ``clamp`` → forward the clamped command,
    ``pause`` → wait for an operator (``fresco-bridge ctl resume``)."""
    max_substeps: int = Field(default=0, ge=0, le=1000)
    """0: off. N >= 2: a velocity violation within the other limits is sent as k <= N equal
    sub-commands, each within the velocity limit."""
    force_min: float | None = None
    """Lowest measured force (kN, daq limit); beyond it the site goes to HOLD."""
    force_max: float | None = None
    """Highest measured force (kN, daq limit); beyond it the site goes to HOLD."""

    @model_validator(mode="after")
    def _consistent(self) -> ControlPointLimitsConfig:
        for lo, hi, unit in (("disp_min", "disp_max", "mm"), ("force_min", "force_max", "kN")):
            a, b = getattr(self, lo), getattr(self, hi)
            if a is not None and b is not None and not a < b:
                raise ValueError(f"{lo} ({a} {unit}) must be below {hi} ({b} {unit})")
        if self.max_substeps == 1:
            raise ValueError("max_substeps must be 0 (off) or at least 2")
        if self.max_substeps and self.velocity is None:
            raise ValueError("max_substeps needs a velocity limit to split against")
        if self.step_time is not None and self.velocity is None:
            raise ValueError("step_time is only used by the velocity limit; set velocity")
        keys = ("disp_min", "disp_max", "disp_increment", "velocity", "force_min", "force_max")
        if all(getattr(self, k) is None for k in keys):
            raise ValueError(f"limits for actuator {self.actuator} set no limit (one of "
                             f"{', '.join(keys)})")
        return self

    def to_limits(self) -> ControlPointLimits:
        def v(x: float | None, default: float) -> float:
            return default if x is None else float(x)

        return ControlPointLimits(
            actuator=self.actuator - 1,
            disp_min=v(self.disp_min, -INF), disp_max=v(self.disp_max, INF),
            disp_increment=v(self.disp_increment, INF), velocity=v(self.velocity, INF),
            step_time=self.step_time, policy=self.policy, max_substeps=self.max_substeps,
            force_min=v(self.force_min, -INF), force_max=v(self.force_max, INF),
        )


class CorrectionConfig(StrictConfig):
    """``[sites.correction]``: the outer-loop displacement correction (``safety/correction.py``).
    Off when the table is absent. Units mm."""

    tolerance: float | list[float]
    """|target − measured| (mm) within which a control point counts as there: one value for
    every corrected control point, or one per control point."""
    max_correction: float | list[float]
    """The farthest a corrected command may be from the target (mm), one value or one per
    control point; a correction beyond it is never sent (→ ``policy``)."""
    max_iterations: int = Field(default=5, ge=1, le=100)
    """Corrected commands per step at most; still outside the tolerance after them → ``policy``."""
    gain: float = Field(default=1.0, gt=0, le=1.0)
    """Next command = last command + gain·(target − measured), in (0, 1]: 1 removes a linear
    error (compliance, undershoot) in one iteration; above 1 a correction overshoots, and an
    inelastic specimen keeps the excursion in its history (BENCHMARKS.md)."""
    policy: Literal["hold", "accept-with-event"] = "hold"
    """Not converged or beyond ``max_correction``: ``hold`` → HOLD; ``accept-with-event`` →
    the integrator gets the force at the last position reached, and an event is recorded."""
    measured: Literal["daq", "external"] = "daq"
    """Which displacement is compared with the target: the controller's daq displacement, or
    the external channel its ``[sites.controller]`` table names (docs/configuration.md)."""
    actuators: list[int] | None = None
    """The corrected control points (1-based, after the setup); default: every one."""

    @model_validator(mode="after")
    def _consistent(self) -> CorrectionConfig:
        for key in ("tolerance", "max_correction"):
            value = getattr(self, key)
            values = value if isinstance(value, list) else [value]
            if not values:
                raise ValueError(f"{key}: an empty list (give one value, or one per control "
                                 "point)")
            strict = key == "tolerance"
            for i, v in enumerate(values, 1):
                if (strict and not v > 0) or (not strict and not v >= 0):
                    which = f" of control point {i}" if isinstance(value, list) else ""
                    raise ValueError(f"{key}{which}: {v!r} mm must be "
                                     f"{'> 0' if strict else '>= 0'}")
        points = self.actuators
        if points is not None and (not points or len(set(points)) != len(points)
                                   or min(points) < 1):
            raise ValueError(f"actuators {points}: distinct control points, 1-based, at "
                             "least one")
        return self

    def to_settings(self, n_actuators: int) -> CorrectionSettings:
        """The pure settings for a site of ``n_actuators`` control points (``ValueError``
        naming the key that does not fit that count)."""
        def per_point(key: str) -> list[float]:
            value = getattr(self, key)
            if not isinstance(value, list):
                return [float(value)] * n_actuators
            if len(value) != n_actuators:
                raise ValueError(f"correction.{key}: {len(value)} value(s) for "
                                 f"{n_actuators} control point(s)")
            return [float(v) for v in value]

        tolerance, most = per_point("tolerance"), per_point("max_correction")
        if self.actuators is not None:
            beyond = [a for a in self.actuators if a > n_actuators]
            if beyond:
                raise ValueError(f"correction.actuators {beyond}: the setup has "
                                 f"{n_actuators} control point(s)")
            for i in range(n_actuators):
                if i + 1 not in self.actuators:
                    tolerance[i] = INF  # not corrected: its command stays the target
        return CorrectionSettings(tuple(tolerance), tuple(most), self.max_iterations,
                                  self.gain, self.policy)
