"""Rig descriptions (TOML or dict) validated with pydantic, named presets, and the rig builder.

Units throughout: mm, kN, s (Hz for rates and frequencies). Unknown keys are errors, so a typo
never silently falls back to a default. See ``sim_actuator/README.md`` for every parameter.
"""

from __future__ import annotations

import tomllib
from collections.abc import Mapping
from pathlib import Path
from typing import Annotated, Any, Literal

import numpy as np
from pydantic import (
    AfterValidator,
    BaseModel,
    ConfigDict,
    Field,
    ValidationError,
    model_validator,
)

from sim_actuator.actuator import Actuator, FirstOrderLag, IdealServo, SecondOrderServo, ServoStage
from sim_actuator.effects import LoadPath, Sensor, SpecimenModel
from sim_actuator.models import MODEL_KINDS, ModelParameterError, make_model
from sim_actuator.rig import Rig

__all__ = [
    "PRESETS",
    "ActuatorConfig",
    "EffectsConfig",
    "ModelKindName",
    "RigConfig",
    "RigConfigError",
    "SensorsConfig",
    "SpecimenConfig",
    "build_rig",
    "channel_config",
    "load_rig_config",
    "parse_rig_config",
    "preset",
]


class RigConfigError(ValueError):
    """A rig description is invalid; the message lists every problem with its location."""


class _Strict(BaseModel):
    model_config = ConfigDict(extra="forbid", allow_inf_nan=False, frozen=True)


PositiveFloat = Annotated[float, Field(gt=0.0)]
NonNegativeFloat = Annotated[float, Field(ge=0.0)]


def _known_model_kind(kind: str) -> str:
    if kind not in MODEL_KINDS:
        raise ValueError(f"unknown model kind {kind!r}; allowed: {', '.join(MODEL_KINDS)}")
    return kind


ModelKindName = Annotated[str, AfterValidator(_known_model_kind)]
"""A hysteresis model kind of the registry (``sim_actuator.models.MODEL_KINDS``)."""


class SpecimenConfig(_Strict):
    """Specimen hysteresis model: ``kind`` and its parameters (see sim_actuator.models)."""

    kind: ModelKindName
    params: dict[str, float] = Field(default_factory=dict)

    @model_validator(mode="after")
    def _model_builds(self) -> SpecimenConfig:
        try:
            make_model(self.kind, **self.params)
        except ModelParameterError as exc:
            raise ValueError(str(exc)) from exc
        return self


class IdealServoConfig(_Strict):
    """The piston follows the (delayed, scaled) reference exactly."""

    kind: Literal["ideal"] = "ideal"


class FirstOrderServoConfig(_Strict):
    """First-order lag ``tau*x' + x = u``."""

    kind: Literal["first_order"]
    tau: PositiveFloat
    """Time constant, s."""


class SecondOrderServoConfig(_Strict):
    """Second-order servo ``x'' + 2*zeta*wn*x' + wn^2*x = wn^2*u`` with ``wn = 2*pi*fn``."""

    kind: Literal["second_order"]
    natural_frequency: PositiveFloat
    """Natural frequency fn, Hz."""
    damping: PositiveFloat
    """Damping ratio zeta, dimensionless."""


ServoConfig = Annotated[
    IdealServoConfig | FirstOrderServoConfig | SecondOrderServoConfig,
    Field(discriminator="kind"),
]


class ActuatorConfig(_Strict):
    """Servo-hydraulic actuator: capacities and command-path errors."""

    stroke: PositiveFloat = 100.0
    """Half stroke: |target| must not exceed it, mm."""
    force_capacity: PositiveFloat = 500.0
    """|load-cell force| above it trips the move, kN."""
    amplitude: PositiveFloat = 1.0
    """Amplitude factor: the piston goes to amplitude * reference."""
    undershoot: NonNegativeFloat = 0.0
    """End point falls short by this against the direction of motion, mm."""
    delay: NonNegativeFloat = 0.0
    """Pure transport delay, s."""
    servo: ServoConfig = Field(default_factory=IdealServoConfig)


class FrictionConfig(_Strict):
    """Fixture friction seen by the load cell."""

    coulomb: NonNegativeFloat = 0.0
    """Coulomb friction force, kN."""
    viscous: NonNegativeFloat = 0.0
    """Viscous coefficient, kN*s/mm."""


class BacklashConfig(_Strict):
    """Play in the pin connection."""

    gap: NonNegativeFloat = 0.0
    """Clearance on each side, mm (zero-force travel 2*gap after the force returns to zero)."""


class FrameConfig(_Strict):
    """Reaction-frame compliance in series with the actuator."""

    stiffness: PositiveFloat | None = None
    """Frame stiffness, kN/mm; None means rigid."""


class EffectsConfig(_Strict):
    """Unmodelled effects in the load path."""

    friction: FrictionConfig = Field(default_factory=FrictionConfig)
    backlash: BacklashConfig = Field(default_factory=BacklashConfig)
    frame: FrameConfig = Field(default_factory=FrameConfig)


class SensorConfig(_Strict):
    """A transducer channel."""

    noise_std: NonNegativeFloat = 0.0
    """Standard deviation of Gaussian noise per reading (mm or kN)."""
    bias: float = 0.0
    """Constant offset (mm or kN)."""


class LvdtConfig(SensorConfig):
    """Displacement transducer and what it measures."""

    location: Literal["actuator", "specimen"] = "actuator"
    """'actuator': the piston stroke the servo controls; 'specimen': the specimen itself."""


class SensorsConfig(_Strict):
    """Displacement and force transducers."""

    lvdt: LvdtConfig = Field(default_factory=LvdtConfig)
    load_cell: SensorConfig = Field(default_factory=SensorConfig)


class RigConfig(_Strict):
    """A whole rig: clock, specimen, actuator, effects, sensors."""

    name: str = "custom"
    description: str = ""
    seed: Annotated[int, Field(ge=0)] = 0
    """Seed of the sensor-noise streams (one independent stream per sensor)."""
    substep_rate: Annotated[float, Field(gt=0.0, le=100_000.0)] = 1000.0
    """Internal simulation rate, Hz."""
    settle_time: NonNegativeFloat = 0.05
    """Hold after each ramp before the sensors are read, s."""
    default_ramp_time: NonNegativeFloat = 0.1
    """Ramp time used until a client sets one, s."""
    max_ramp_time: PositiveFloat = 60.0
    """Longest ramp a client may ask for, s."""
    specimen: SpecimenConfig
    actuator: ActuatorConfig = Field(default_factory=ActuatorConfig)
    effects: EffectsConfig = Field(default_factory=EffectsConfig)
    sensors: SensorsConfig = Field(default_factory=SensorsConfig)

    @model_validator(mode="after")
    def _consistent(self) -> RigConfig:
        if self.default_ramp_time > self.max_ramp_time:
            raise ValueError(
                f"default_ramp_time {self.default_ramp_time!r} s exceeds "
                f"max_ramp_time {self.max_ramp_time!r} s"
            )
        if self.actuator.delay * self.substep_rate > 1_000_000:
            raise ValueError(
                f"actuator.delay {self.actuator.delay!r} s is over a million substeps long"
            )
        return self


def _format_errors(source: str, exc: ValidationError) -> str:
    lines = [f"{source}: invalid rig description ({exc.error_count()} problem(s)):"]
    for err in exc.errors():
        loc = ".".join(str(part) for part in err["loc"]) or "<root>"
        shown = err["type"] != "missing" and not isinstance(err["input"], Mapping)
        got = f" (got {err['input']!r})" if shown else ""
        message = err["msg"].removeprefix("Value error, ")
        lines.append(f"  {loc}: {message}{got}")
    return "\n".join(lines)


def parse_rig_config(data: Mapping[str, Any], source: str = "<rig>") -> RigConfig:
    """Validate a rig description; raise :class:`RigConfigError` naming every bad field."""
    try:
        return RigConfig.model_validate(dict(data))
    except ValidationError as exc:
        raise RigConfigError(_format_errors(source, exc)) from None


def load_rig_config(path: str | Path) -> RigConfig:
    """Read and validate a TOML rig description."""
    file = Path(path)
    try:
        text = file.read_text(encoding="utf-8")
    except OSError as exc:
        raise RigConfigError(f"{file}: cannot read rig description: {exc.strerror}") from None
    try:
        data = tomllib.loads(text)
    except tomllib.TOMLDecodeError as exc:
        raise RigConfigError(f"{file}: not valid TOML: {exc}") from None
    return parse_rig_config(data, source=str(file))


def _servo(config: ActuatorConfig, dt: float) -> ServoStage:
    servo = config.servo
    if isinstance(servo, FirstOrderServoConfig):
        return FirstOrderLag(servo.tau, dt)
    if isinstance(servo, SecondOrderServoConfig):
        return SecondOrderServo(servo.natural_frequency, servo.damping, dt)
    return IdealServo()


def channel_config(config: RigConfig, channel: int) -> RigConfig:
    """The rig of channel ``channel`` (0-based) of a multi-actuator rig built from ``config``:
    the same description with its own noise streams (seed + channel), so channel 0 is the
    one-actuator rig itself and no two channels share a noise sample."""
    if channel < 0:
        raise ValueError(f"channel must be >= 0, got {channel}")
    return config if channel == 0 else config.model_copy(update={"seed": config.seed + channel})


def build_rig(config: RigConfig, specimen: SpecimenModel | None = None) -> Rig:
    """A fresh rig (virgin specimen, clock at zero) from a validated description; ``specimen``
    replaces the described one (an actuator of a platform several rigs load together)."""
    dt = 1.0 / config.substep_rate
    if specimen is None:
        specimen = make_model(config.specimen.kind, **config.specimen.params)
    act = config.actuator
    actuator = Actuator(
        dt=dt,
        stroke=act.stroke,
        force_capacity=act.force_capacity,
        amplitude=act.amplitude,
        undershoot=act.undershoot,
        delay=act.delay,
        servo=_servo(act, dt),
    )
    fx = config.effects
    load_path = LoadPath(
        specimen,
        dt=dt,
        gap=fx.backlash.gap,
        coulomb=fx.friction.coulomb,
        viscous=fx.friction.viscous,
        frame_stiffness=fx.frame.stiffness,
    )
    lvdt_rng, load_cell_rng = (
        np.random.default_rng(child) for child in np.random.SeedSequence(config.seed).spawn(2)
    )
    sensors = config.sensors
    return Rig(
        actuator=actuator,
        load_path=load_path,
        lvdt=Sensor(noise_std=sensors.lvdt.noise_std, bias=sensors.lvdt.bias, rng=lvdt_rng),
        load_cell=Sensor(
            noise_std=sensors.load_cell.noise_std, bias=sensors.load_cell.bias, rng=load_cell_rng
        ),
        lvdt_location=sensors.lvdt.location,
        settle_time=config.settle_time,
        default_ramp_time=config.default_ramp_time,
        max_ramp_time=config.max_ramp_time,
    )


# The source paper's specimen: Bilinear with k0 = 68000 N/mm, alpha = 0.008, Fy = 35000 N.
_PAPER_BILINEAR: dict[str, Any] = {
    "kind": "bilinear", "params": {"k0": 68.0, "fy": 35.0, "alpha": 0.008},
}

# The bending damper sized like the demo's, as a degrading, pinching BWBN (illustrative).
_DAMPER_BWBN: dict[str, Any] = {"kind": "bwbn", "params": {
    "k0": 8.0, "fy": 12.0, "alpha": 0.05, "n": 1.0, "beta": 0.5, "gamma": 0.5,
    "A0": 1.0, "delta_a": 0.0, "delta_nu": 0.002, "delta_eta": 0.002,
    "zeta_s": 0.3, "p": 0.05, "q": 0.1, "psi0": 0.2, "delta_psi": 0.005,
    "lam": 0.5}}

PRESETS: dict[str, RigConfig] = {
    cfg.name: cfg
    for cfg in (
        parse_rig_config({
            "name": "ideal-elastic",
            "description": "elastic specimen k = 68 kN/mm, ideal actuator, no effects",
            "specimen": {"kind": "elastic", "params": {"k": 68.0}},
        }),
        parse_rig_config({
            "name": "ideal-bilinear",
            "description": "source paper's bilinear specimen, ideal actuator, no effects",
            "specimen": _PAPER_BILINEAR,
        }),
        parse_rig_config({
            "name": "servo-hydraulic",
            "description": "paper's bilinear specimen; 20 ms delay (ATS default a1) and a "
                           "15 ms first-order servo lag; no load-path effects",
            "specimen": _PAPER_BILINEAR,
            "actuator": {"delay": 0.02, "servo": {"kind": "first_order", "tau": 0.015}},
        }),
        parse_rig_config({
            "name": "lab-realistic",
            "description": "servo-hydraulic preset plus fixture friction, pin backlash, "
                           "frame compliance and sensor noise (illustrative values)",
            "seed": 1,
            "specimen": _PAPER_BILINEAR,
            "actuator": {"delay": 0.02, "servo": {"kind": "first_order", "tau": 0.015}},
            "effects": {
                "friction": {"coulomb": 0.3, "viscous": 0.0},
                "backlash": {"gap": 0.01},
                "frame": {"stiffness": 2000.0},
            },
            "sensors": {
                "lvdt": {"noise_std": 0.002},
                "load_cell": {"noise_std": 0.02},
            },
        }),
        parse_rig_config({
            "name": "damper-bwbn",
            "description": "bending damper sized like the demo's (k0 8 kN/mm, fy 12 kN, "
                           "alpha 0.05) as BWBN with energy-driven stiffness/strength "
                           "degradation and pinching (illustrative values, not calibrated), "
                           "on the servo-hydraulic actuator",
            "specimen": _DAMPER_BWBN,
            "actuator": {"delay": 0.02, "servo": {"kind": "first_order", "tau": 0.015}},
        }),
        parse_rig_config({
            "name": "damper-lab",
            "description": "the damper-bwbn specimen as a lab sees it: the servo-hydraulic "
                           "actuator (20 ms delay, 15 ms lag), a little pin backlash "
                           "(0.05 mm each side) and sensor noise (LVDT 0.002 mm, load cell "
                           "0.02 kN); the demo's tested damper (illustrative values)",
            "seed": 1,
            "specimen": _DAMPER_BWBN,
            "actuator": {"delay": 0.02, "servo": {"kind": "first_order", "tau": 0.015}},
            "effects": {"backlash": {"gap": 0.05}},
            "sensors": {
                "lvdt": {"noise_std": 0.002},
                "load_cell": {"noise_std": 0.02},
            },
        }),
    )
}
"""Named rig descriptions for ``sim-actuator serve --preset NAME``."""


def preset(name: str) -> RigConfig:
    """A preset by name, or :class:`RigConfigError` listing the known names."""
    try:
        return PRESETS[name]
    except KeyError:
        raise RigConfigError(
            f"unknown rig preset {name!r}; known presets: {', '.join(sorted(PRESETS))}"
        ) from None
