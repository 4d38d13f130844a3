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

from pathlib import Path
from typing import Literal

from pydantic import Field, model_validator

from sim_actuator.config import (
    RigConfig,
    RigConfigError,
    build_rig,
    channel_config,
    load_rig_config,
    preset,
)
from sim_actuator.rig import Measurement, Rig, RigError

from ..config_model import ConfigPath, StrictConfig
from .base import ControllerError, Daq, InlineController, PhysicalController, diagonal, wrong_count
from .kind import ControllerConfigBase, ControllerKind


class RigChannelConfig(StrictConfig):
    """One actuator of a multi-actuator rig: its own preset or rig file."""

    preset: str | None = None
    file: ConfigPath | None = None

    @model_validator(mode="after")
    def _one_rig(self) -> RigChannelConfig:
        _rig_config(self.preset, self.file)  # exactly one, and it loads: a config error now
        return self


def _rig_config(preset_name: str | None, file: Path | None) -> RigConfig:
    if (preset_name is None) == (file is None):
        raise ValueError("give exactly one of 'preset' or 'file'")
    try:
        if preset_name is not None:
            return preset(preset_name)
        assert file is not None
        return load_rig_config(file)
    except (RigConfigError, OSError) as exc:
        raise ValueError(str(exc)) from None


class RigControllerConfig(ControllerConfigBase):
    """``kind = "rig"``: ``sim_actuator`` rigs in process, one per actuator (a preset or a rig
    TOML file for all of them, or one ``[[sites.controller.channels]]`` table each)."""

    kind: Literal["rig"] = "rig"
    preset: str | None = None
    """A ``sim-actuator presets`` name, e.g. ``servo-hydraulic`` (every actuator)."""
    file: ConfigPath | None = None
    """A rig description (TOML, the format of ``sim-actuator serve --rig``; every actuator)."""
    channels: list[RigChannelConfig] | None = None
    """One rig per actuator, in control-point order (instead of ``preset``/``file``)."""
    ramp_time: float | None = Field(None, ge=0.0, le=3600.0, allow_inf_nan=False)
    """Ramp time of every move, s (default: each rig's ``default_ramp_time``)."""
    stiffness: float = Field(68.0, gt=0.0, allow_inf_nan=False)
    """Stiffness estimate reported as tangent and initial stiffness per actuator, kN/mm."""
    reset_on_new_session: bool = True
    """A new integrator session starts from new rigs (virgin specimens, fresh noise streams)."""

    @model_validator(mode="after")
    def _one_rig(self) -> RigControllerConfig:
        if self.channels is None:
            _rig_config(self.preset, self.file)  # an unknown preset or a bad file, now
        elif self.preset is not None or self.file is not None:
            raise ValueError("give 'preset' or 'file' (every actuator) or 'channels' (one "
                             "table per actuator), not both")
        elif not self.channels:
            raise ValueError("channels: at least one [[sites.controller.channels]] table")
        return self

    def rig_configs(self, n_actuators: int) -> list[RigConfig]:
        """One rig description per actuator; each channel has its own noise streams."""
        if self.channels is None:
            shared = _rig_config(self.preset, self.file)
            return [channel_config(shared, c) for c in range(n_actuators)]
        if len(self.channels) != n_actuators:
            raise ValueError(f"channels: {len(self.channels)} table(s) for {n_actuators} "
                             "actuator(s) (one [[sites.controller.channels]] per actuator)")
        return [channel_config(_rig_config(ch.preset, ch.file), c)
                for c, ch in enumerate(self.channels)]


class RigController(InlineController, PhysicalController):
    """``n_actuators`` independent actuators of in-process ``sim_actuator`` rigs (each its own
    servo, effects, sensors and specimen); answers at once (called synchronously by the site).
    The actuators move one after the other inside one ``set_ctrl``; a refused move of one
    raises after the ones before it moved (the site HOLDs every actuator)."""

    def __init__(self, config: RigControllerConfig, n_actuators: int = 1) -> None:
        self.config = config
        self.n_actuators = n_actuators
        self.stiffness = config.stiffness
        try:
            self._rig_configs = config.rig_configs(n_actuators)
        except ValueError as exc:
            raise ControllerError(f"simulated rig: {exc}") from None
        self.rigs: list[Rig] = []
        self._last: list[Measurement] = []
        self.reset()

    @property
    def rig(self) -> Rig:
        """The first actuator's rig (the one of a one-actuator site)."""
        return self.rigs[0]

    def set_ctrl_now(self, disp: tuple[float, ...]) -> None:
        if len(disp) != self.n_actuators:
            raise wrong_count("simulated rig", self.n_actuators, disp)
        for channel, (rig, target) in enumerate(zip(self.rigs, disp, strict=True)):
            try:
                self._last[channel] = rig.execute(target, self.config.ramp_time)
            except RigError as exc:
                which = "" if self.n_actuators == 1 else f"actuator {channel + 1}: "
                raise ControllerError(f"simulated rig: {which}move to {target!r} mm failed: "
                                      f"{exc}") from exc

    def get_daq_now(self) -> Daq:
        return Daq(tuple(m.displacement for m in self._last),
                   tuple(m.force for m in self._last))

    def commit_now(self) -> None:
        """A physical rig has no trial state to commit."""

    def tangent_stiffness_now(self) -> tuple[float, ...]:
        return self._diagonal

    def initial_stiffness_now(self) -> tuple[float, ...]:
        return self._diagonal

    async def tangent_stiffness(self) -> tuple[float, ...]:
        return self._diagonal

    async def initial_stiffness(self) -> tuple[float, ...]:
        return self._diagonal

    async def hold(self) -> None:
        """Nothing to stop: moves complete inside ``set_ctrl``; every actuator stays where it
        is (the site forwards nothing while it holds)."""

    def reset(self) -> None:
        """Fresh rigs: virgin specimens, actuators at rest, noise streams from their seeds."""
        self.rigs = [build_rig(c) for c in self._rig_configs]
        self._last = [rig.measure(noisy=False) for rig in self.rigs]
        self._diagonal = diagonal((self.stiffness,) * self.n_actuators)


KIND = ControllerKind(
    name="rig",
    config=RigControllerConfig,
    factory=RigController,
    summary="the whole simulated lab of `sim-actuator` in process, one rig per actuator — servo "
    "delay/lag, friction, backlash, compliance, sensor noise",
    max_actuators=None,
    fits=lambda config, n: None if config.channels is None or len(config.channels) == n else (
        f"controller rig has {len(config.channels)} [[sites.controller.channels]] table(s); "
        f"this site needs one per actuator: {n}"),
)
