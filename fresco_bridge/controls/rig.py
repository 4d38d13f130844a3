"""In-process simulated test rig: ``sim_actuator``'s actuator, load path and sensors, no server.

The ``sim`` controller is a bare hysteresis model with material semantics (exactly OpenSees'
``Steel01``); this one is the whole simulated lab of ``sim-actuator serve`` — servo delay and
lag, amplitude error, friction, backlash, frame compliance, sensor noise and bias, stroke and
force capacity — in the bridge's own process, for a quick look at what those effects do to a
test without starting servers. Like a physical rig it has no trial/commit semantics (every
move really happens) and cannot report its stiffness: tangent and initial stiffness are the
configured estimate, as with the Modbus and MTS adapters. The same rig served over Modbus gives
the same numbers to float32 resolution (tested).
"""

from __future__ import annotations

from typing import Literal

from pydantic import Field, model_validator

from sim_actuator.config import RigConfig, RigConfigError, build_rig, load_rig_config, preset
from sim_actuator.rig import Measurement, Rig, RigError

from ..config_model import ConfigPath
from .base import ControllerError, Daq, InlineController, PhysicalController
from .kind import ControllerConfigBase, ControllerKind


class RigControllerConfig(ControllerConfigBase):
    """``kind = "rig"``: a ``sim_actuator`` rig (a preset or a rig TOML file) in process."""

    kind: Literal["rig"] = "rig"
    preset: str | None = None
    """A ``sim-actuator presets`` name, e.g. ``servo-hydraulic``."""
    file: ConfigPath | None = None
    """A rig description (TOML, the format of ``sim-actuator serve --rig``)."""
    ramp_time: float | None = Field(None, ge=0.0, le=3600.0, allow_inf_nan=False)
    """Ramp time of every move, s (default: the rig's ``default_ramp_time``)."""
    stiffness: float = Field(68.0, gt=0.0, allow_inf_nan=False)
    """Stiffness estimate reported as tangent and initial stiffness, kN/mm."""
    reset_on_new_session: bool = True
    """A new integrator session starts from a new rig (virgin specimen, fresh noise streams)."""

    @model_validator(mode="after")
    def _one_rig(self) -> RigControllerConfig:
        if (self.preset is None) == (self.file is None):
            raise ValueError("give exactly one of 'preset' or 'file'")
        self.rig_config()  # an unknown preset or a bad file is a config error, now
        return self

    def rig_config(self) -> RigConfig:
        try:
            if self.preset is not None:
                return preset(self.preset)
            assert self.file is not None
            return load_rig_config(self.file)
        except (RigConfigError, OSError) as exc:
            raise ValueError(str(exc)) from None


class RigController(InlineController, PhysicalController):
    """One actuator of an in-process ``sim_actuator`` rig; answers at once (called
    synchronously by the site)."""

    n_actuators = 1

    def __init__(self, config: RigControllerConfig) -> None:
        self.config = config
        self.stiffness = config.stiffness
        self._rig_config = config.rig_config()
        self.rig: Rig = build_rig(self._rig_config)
        self._last: Measurement = self.rig.measure(noisy=False)

    def set_ctrl_now(self, disp: tuple[float, ...]) -> None:
        try:
            self._last = self.rig.execute(disp[0], self.config.ramp_time)
        except RigError as exc:
            raise ControllerError(f"simulated rig: move to {disp[0]!r} mm failed: {exc}") from exc

    def get_daq_now(self) -> Daq:
        return Daq((self._last.displacement,), (self._last.force,))

    def commit_now(self) -> None:
        """A physical rig has no trial state to commit."""

    def tangent_stiffness_now(self) -> tuple[float, ...]:
        return (self.stiffness,)

    def initial_stiffness_now(self) -> tuple[float, ...]:
        return (self.stiffness,)

    async def hold(self) -> None:
        """Nothing to stop: moves complete inside ``set_ctrl``; the actuator stays where it is."""

    def reset(self) -> None:
        """A fresh rig: virgin specimen, actuator at rest, noise streams from their seeds."""
        self.rig = build_rig(self._rig_config)
        self._last = self.rig.measure(noisy=False)


KIND = ControllerKind(
    name="rig",
    config=RigControllerConfig,
    factory=lambda config, n: RigController(config),
    summary="the whole simulated lab of `sim-actuator` in process — servo delay/lag, friction, "
    "backlash, compliance, sensor noise",
)
