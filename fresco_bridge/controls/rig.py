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
    SpecimenConfig,
    build_rig,
    channel_config,
    load_rig_config,
    preset,
)
from sim_actuator.models import HysteresisModel, make_model
from sim_actuator.platform import Geometry, Platform, PlatformError
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


class PlatformConfig(StrictConfig):
    """The specimen several actuators load together (``[sites.controller.platform]``): one law
    per DOF of the platform the site's setup moves (``ThreeActuators2d``: x, y, θ), loaded
    through the setup's own geometry — linear, or exact with ``nlGeom``
    (``sim_actuator/platform.py``)."""

    specimen: list[SpecimenConfig] = Field(min_length=1)
    """One law per platform DOF, ``{ kind = "elastic", params = { k = 10.0 } }``."""

    @model_validator(mode="after")
    def _laws(self) -> PlatformConfig:
        self.laws()  # an unknown law or bad parameters is a config error, now
        return self

    def laws(self) -> list[HysteresisModel]:
        try:
            return [make_model(s.kind, **s.params) for s in self.specimen]
        except (TypeError, ValueError) as exc:
            raise ValueError(f"specimen: {exc}") from None

    def build(self, geometry: Geometry) -> Platform:
        try:
            return Platform(geometry, self.laws())
        except PlatformError as exc:
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
    platform: PlatformConfig | None = None
    """The actuators load one platform specimen (coupled) through the site's setup geometry
    instead of a specimen each; their rigs' own specimens are then not used, and load-path
    effects (friction, backlash, frame compliance) are not simulated through a platform: a
    config error."""
    ramp_time: float | None = Field(None, ge=0.0, le=3600.0, allow_inf_nan=False)
    """Ramp time of every move, s (default: each rig's ``default_ramp_time``)."""
    stiffness: float = Field(68.0, gt=0.0, allow_inf_nan=False)
    """Stiffness estimate reported as tangent and initial stiffness per actuator, kN/mm."""
    reset_on_new_session: bool = True
    """A new integrator session starts from new rigs (virgin specimens, fresh noise streams)."""
    external: Literal["specimen"] | None = None
    """``"specimen"``: an external channel (``Daq.external``) reads each rig's true specimen
    displacement, behind frame compliance, pin play and servo undershoot (an ideal transducer
    on the specimen), for the outer-loop correction's ``measured = "external"``."""

    def external_channel(self) -> str | None:
        return None if self.external is None else "specimen displacement"

    @model_validator(mode="after")
    def _one_rig(self) -> RigControllerConfig:
        if self.channels is None:
            _rig_config(self.preset, self.file)  # an unknown preset or a bad file, now
        elif self.preset is not None or self.file is not None:
            raise ValueError("give 'preset' or 'file' (every actuator) or 'channels' (one "
                             "table per actuator), not both")
        elif not self.channels:
            raise ValueError("channels: at least one [[sites.controller.channels]] table")
        if self.platform is not None:
            n = len(self.platform.specimen)
            if self.channels is not None and len(self.channels) != n:
                raise ValueError(f"platform: {n} specimen laws (one per platform DOF, one "
                                 f"actuator each), {len(self.channels)} channel table(s)")
            for c, rig in enumerate(self.rig_configs(n), 1):
                fx = rig.effects
                if fx.friction.coulomb or fx.friction.viscous or fx.backlash.gap or \
                        fx.frame.stiffness is not None:
                    raise ValueError(f"platform: the rig of actuator {c} ({rig.name}) has "
                                     "load-path effects (friction, backlash or frame "
                                     "compliance), which a shared platform does not simulate; "
                                     "use a rig without them (servo and sensor effects are "
                                     "fine)")
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

    platform: Platform | None

    def __init__(self, config: RigControllerConfig, n_actuators: int = 1,
                 geometry: Geometry | None = None) -> None:
        self.config = config
        self.n_actuators = n_actuators
        problem = _fits(config, n_actuators, geometry)
        if problem is not None:
            raise ControllerError(problem)
        self.geometry = geometry
        self.stiffness = config.stiffness
        self.external_channel = config.external_channel()
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
        if self.platform is not None:  # every actuator feels the others' moves: read them all
            for channel, rig in enumerate(self.rigs):
                rig.load_path.impose(rig.position)
                self._last[channel] = rig.measure()

    def get_daq_now(self) -> Daq:
        last = self._last
        disp, force = tuple(m.displacement for m in last), tuple(m.force for m in last)
        if self.external_channel is None:
            return Daq(disp, force)
        return Daq(disp, force, tuple(m.specimen_displacement for m in last))

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
        spec, geometry = self.config.platform, self.geometry
        platform = None if spec is None or geometry is None else spec.build(geometry)
        self.platform = platform
        self.rigs = [build_rig(c, None if platform is None else platform.channel(i))
                     for i, c in enumerate(self._rig_configs)]
        self._last = [rig.measure(noisy=False) for rig in self.rigs]
        self._diagonal = diagonal((self.stiffness,) * self.n_actuators)


def _fits(config: RigControllerConfig, n: int, geometry: Geometry | None) -> str | None:
    if config.channels is not None and len(config.channels) != n:
        return (f"controller rig has {len(config.channels)} [[sites.controller.channels]] "
                f"table(s); this site needs one per actuator: {n}")
    if config.platform is None:
        return None
    if geometry is None:
        return ("controller rig: [sites.controller.platform] loads its specimen through the "
                "setup's platform, and this setup has none (use a planar setup: "
                "TwoActuators2d, ThreeActuators2d, …)")
    laws = len(config.platform.specimen)
    if laws != geometry.n_actuators or laws != n:
        return (f"controller rig: the platform specimen has {laws} law(s); the setup's "
                f"platform has {geometry.n_actuators} DOF(s) driven by {n} actuator(s) (one "
                "law per platform DOF)")
    return None


KIND = ControllerKind(
    name="rig",
    config=RigControllerConfig,
    factory=RigController,
    summary="the whole simulated lab of `sim-actuator` in process, one rig per actuator — servo "
    "delay/lag, friction, backlash, compliance, sensor noise",
    max_actuators=None,
    fits=_fits,
)
