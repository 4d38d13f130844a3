"""``[[sites.limits]]``: one table per control point, validated (defaults: no limits at all)."""

from __future__ import annotations

from typing import Literal

from pydantic import Field, model_validator

from ..config_model import StrictConfig
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
