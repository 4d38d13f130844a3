"""Shared contract of the specimen hysteresis models: protocol, errors, parameter checks, factory.

Every model follows OpenSees uniaxial-material semantics: ``set_trial(d)`` always starts
from the last *committed* state, so an integrator may try many trial displacements per step
and only ``commit()`` the converged one.
"""

from __future__ import annotations

import math
from typing import Protocol, runtime_checkable

__all__ = [
    "MODEL_DEFAULTS",
    "MODEL_PARAMETERS",
    "HysteresisModel",
    "ModelInputError",
    "ModelParameterError",
    "make_model",
]


@runtime_checkable
class HysteresisModel(Protocol):
    """A path-dependent force-displacement law of a specimen (one degree of freedom)."""

    name: str

    def set_trial(self, d: float) -> tuple[float, float]:
        """Trial displacement from the last committed state; returns (force, tangent)."""
        ...

    def commit(self) -> None:
        """Make the current trial state the committed state."""
        ...

    def revert_to_last_commit(self) -> None:
        """Discard the trial state."""
        ...

    def revert_to_start(self) -> None:
        """Return to the virgin state (d = 0, f = 0)."""
        ...

    @property
    def initial_tangent(self) -> float:
        """Tangent stiffness of the virgin state."""
        ...

    @property
    def committed(self) -> tuple[float, float]:
        """Committed (displacement, force)."""
        ...

    def clone(self) -> HysteresisModel:
        """Independent copy including committed and trial state."""
        ...


class ModelParameterError(ValueError):
    """A model kind or parameter is unknown, missing or out of range."""

    def __init__(self, model: str, message: str, parameter: str | None = None) -> None:
        super().__init__(f"{model}: {message}")
        self.model = model
        self.parameter = parameter


class ModelInputError(ValueError):
    """A trial displacement is not a finite number."""


MODEL_PARAMETERS: dict[str, dict[str, str]] = {
    "elastic": {
        "k": "stiffness, force/displacement (e.g. kN/mm), > 0",
    },
    "bilinear": {
        "k0": "initial (elastic) stiffness, force/displacement (e.g. kN/mm), > 0",
        "fy": "yield force, force (e.g. kN), > 0",
        "alpha": "post-yield to initial stiffness ratio, dimensionless, 0 <= alpha < 1",
    },
    "bouc-wen": {
        "k0": "initial stiffness, force/displacement (e.g. kN/mm), > 0",
        "fy": "yield force scale: hysteretic force is (1-alpha)*fy*z, force (e.g. kN), > 0",
        "alpha": "post-yield to initial stiffness ratio, dimensionless, 0 <= alpha < 1",
        "n": "sharpness of the elastic-plastic transition, dimensionless, >= 1",
        "beta": "weight of the sign(dd*z) term (loading/unloading shape), dimensionless, > 0",
        "gamma": "weight of the constant term, dimensionless, beta + gamma > 0",
        "A": "initial slope of z against d/dy, dimensionless, > 0 (default 1)",
    },
    "bwbn": {
        "k0": "initial stiffness, force/displacement (e.g. kN/mm), > 0",
        "fy": "yield force scale: hysteretic force is (1-alpha)*fy*z, force (e.g. kN), > 0",
        "alpha": "post-yield to initial stiffness ratio, dimensionless, 0 <= alpha < 1",
        "n": "sharpness of the elastic-plastic transition, dimensionless, >= 1",
        "beta": "weight of the sign(dd*z) term, dimensionless, > 0",
        "gamma": "weight of the constant term, dimensionless, beta + gamma > 0",
        "A0": "initial slope of z against d/dy, dimensionless, > 0 (default 1)",
        "delta_a": "decay rate of A per unit normalised energy e, dimensionless, >= 0 (default 0)",
        "delta_nu": "growth rate of nu (strength degradation) per unit e, >= 0 (default 0)",
        "delta_eta": "growth rate of eta (stiffness degradation) per unit e, >= 0 (default 0)",
        "zeta_s": "pinching severity, dimensionless, 0 <= zeta_s < 1 (default 0 = no pinching)",
        "p": "rate of pinching build-up with e, dimensionless, >= 0",
        "q": "pinching centre as a fraction of z_u, dimensionless, 0 <= q < 1",
        "psi0": "initial pinching spread, dimensionless, > 0",
        "delta_psi": "growth of the pinching spread per unit e, dimensionless, >= 0",
        "lam": "coupling of spread and severity (lambda), dimensionless, > 0",
    },
}
"""Model kind -> {parameter: meaning, unit and allowed range}; for docs and config validation."""

MODEL_DEFAULTS: dict[str, dict[str, float]] = {
    "elastic": {},
    "bilinear": {},
    "bouc-wen": {"A": 1.0},
    "bwbn": {"A0": 1.0, "delta_a": 0.0, "delta_nu": 0.0, "delta_eta": 0.0, "zeta_s": 0.0},
}
"""Model kind -> defaults of its optional parameters; every other parameter is required."""


def check_finite(model: str, name: str, value: float) -> float:
    """Return ``value`` as float, or raise if it is not a finite real number."""
    if isinstance(value, bool) or not isinstance(value, int | float):
        raise ModelParameterError(
            model, f"{name} must be a real number, got {value!r} ({type(value).__name__})", name
        )
    result = float(value)
    if not math.isfinite(result):
        raise ModelParameterError(model, f"{name} must be finite, got {value!r}", name)
    return result


def check_positive(model: str, name: str, value: float) -> float:
    """Finite and > 0."""
    result = check_finite(model, name, value)
    if result <= 0.0:
        raise ModelParameterError(model, f"{name} must be > 0, got {value!r}", name)
    return result


def check_non_negative(model: str, name: str, value: float) -> float:
    """Finite and >= 0."""
    result = check_finite(model, name, value)
    if result < 0.0:
        raise ModelParameterError(model, f"{name} must be >= 0, got {value!r}", name)
    return result


def check_range(model: str, name: str, value: float, low: float, high: float) -> float:
    """Finite and low <= value < high."""
    result = check_finite(model, name, value)
    if not low <= result < high:
        raise ModelParameterError(
            model, f"{name} must satisfy {low:g} <= {name} < {high:g}, got {value!r}", name
        )
    return result


def check_at_least(model: str, name: str, value: float, low: float) -> float:
    """Finite and >= low."""
    result = check_finite(model, name, value)
    if result < low:
        raise ModelParameterError(model, f"{name} must be >= {low:g}, got {value!r}", name)
    return result


def trial_input_error(model: str, d: float) -> ModelInputError:
    """The error for a non-finite trial displacement."""
    return ModelInputError(f"{model}: trial displacement must be finite, got {d!r}")


def make_model(kind: str, **params: float) -> HysteresisModel:
    """Build a model by kind name ("elastic", "bilinear", "bouc-wen", "bwbn") and parameters."""
    from sim_actuator.models.bilinear import Bilinear
    from sim_actuator.models.bouc_wen import BoucWen
    from sim_actuator.models.bwbn import BoucWenBaberNoori
    from sim_actuator.models.elastic import Elastic

    constructors: dict[str, type[Elastic | Bilinear | BoucWen | BoucWenBaberNoori]] = {
        "elastic": Elastic,
        "bilinear": Bilinear,
        "bouc-wen": BoucWen,
        "bwbn": BoucWenBaberNoori,
    }
    if kind not in constructors:
        raise ModelParameterError(
            "make_model", f"unknown model kind {kind!r}; allowed: {', '.join(sorted(constructors))}"
        )
    allowed = MODEL_PARAMETERS[kind]
    unknown = [name for name in params if name not in allowed]
    if unknown:
        raise ModelParameterError(
            kind,
            f"unknown parameter(s) {', '.join(unknown)}; allowed: {', '.join(allowed)}",
            unknown[0],
        )
    defaults = MODEL_DEFAULTS[kind]
    missing = [name for name in allowed if name not in params and name not in defaults]
    if missing:
        raise ModelParameterError(
            kind,
            f"missing required parameter(s) {', '.join(missing)}; "
            f"required: {', '.join(n for n in allowed if n not in defaults)}",
            missing[0],
        )
    return constructors[kind](**params)
