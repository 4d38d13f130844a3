"""Shared contract of the specimen hysteresis models: protocols, parameter declarations, the
state base every model builds on, and the errors.

Every model follows OpenSees uniaxial-material semantics: ``set_trial(d)`` always starts
from the last *committed* state, so an integrator may try many trial displacements per step
and only ``commit()`` the converged one.

A model kind is one class deriving from :class:`HysteresisBase`: it declares its ``name``, its
parameters (``PARAMS``: meaning, unit, default or required, allowed range), the named tuple of
its state (``STATE``) and its law (``set_trial``, the virgin state, the initial tangent). The
base holds the committed and trial states as immutable tuples, so commit, revert, clone,
``state()`` and ``with_params()`` are written once here. The registry
(``sim_actuator.models.registry``) lists the kinds; this module imports none of them.
"""

from __future__ import annotations

import copy
import math
import sys
from abc import ABC, abstractmethod
from collections.abc import Callable, Mapping
from dataclasses import dataclass
from typing import Any, ClassVar, NamedTuple, Protocol, Self, cast, runtime_checkable

from sim_actuator.checks import Bound, ParameterRangeError

__all__ = [
    "HysteresisBase",
    "HysteresisModel",
    "ModelInputError",
    "ModelKind",
    "ModelParameterError",
    "ModelState",
    "Param",
    "ParametricModel",
    "trial_input_error",
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


ModelState = tuple[float, ...]
"""A model's committed state: an immutable named tuple of floats, its first field ``d``."""


@runtime_checkable
class ParametricModel(HysteresisModel, Protocol):
    """A hysteresis law with named parameters and an explicit state: what a filter needs to
    propagate candidate parameter sets from one committed state (e.g. UKF sigma points:
    ``model.with_params(p, model.state()).set_trial(d)``)."""

    @property
    def parameters(self) -> dict[str, float]:
        """The law's parameters by name (as the registry declares them)."""
        ...

    def state(self) -> ModelState:
        """The committed state as an immutable value (a named tuple of floats)."""
        ...

    def with_params(
        self, params: Mapping[str, float], state: ModelState | None = None
    ) -> ParametricModel:
        """A new, independent model of the same kind with ``params`` (the others unchanged),
        starting from committed ``state`` (virgin when None)."""
        ...


class ModelParameterError(ValueError):
    """A model kind or parameter is unknown, missing or out of range."""

    def __init__(self, model: str, message: str, parameter: str | None = None) -> None:
        super().__init__(f"{model}: {message}")
        self.model = model
        self.parameter = parameter


class ModelInputError(ValueError):
    """A trial displacement is not a finite number."""


def trial_input_error(model: str, d: float) -> ModelInputError:
    """The error for a non-finite trial displacement."""
    return ModelInputError(f"{model}: trial displacement must be finite, got {d!r}")


@dataclass(frozen=True, slots=True)
class Param:
    """One parameter of a model kind: what it means, its unit, its range, its default."""

    name: str
    meaning: str
    unit: str
    """``kN/mm``, ``kN``, ``mm``…, or ``-`` (dimensionless). Models are unit-agnostic: a
    consistent set is what matters (the bridge uses mm and kN)."""
    bound: Bound
    default: float | None = None
    """None: the parameter is required."""

    def describe(self) -> str:
        """One line for docs and error hints: meaning, unit, range, default."""
        unit = "dimensionless" if self.unit == "-" else self.unit
        default = "" if self.default is None else f" (default {self.default:g})"
        return f"{self.meaning}, {unit}, {self.bound.describe(self.name)}{default}"

    def check(self, model: str, value: object) -> float:
        """``value`` as a float, or :class:`ModelParameterError` naming model and parameter."""
        try:
            return self.bound.check(self.name, value)
        except ParameterRangeError as exc:
            raise ModelParameterError(model, str(exc), self.name) from None


def refuse_unknown(model: str, given: Mapping[str, object], params: tuple[Param, ...]) -> None:
    """:class:`ModelParameterError` naming the given names that are not parameters of ``model``."""
    allowed = [p.name for p in params]
    unknown = [name for name in given if name not in allowed]
    if unknown:
        raise ModelParameterError(
            model,
            f"unknown parameter(s) {', '.join(unknown)}; allowed: {', '.join(allowed)}",
            unknown[0],
        )


class HysteresisBase(ABC):
    """The state base of every model kind: committed and trial states as immutable tuples
    (so commit and revert are one assignment, a clone shares them), declared parameters."""

    __slots__ = ("_committed", "_trial")

    name: str
    PARAMS: ClassVar[tuple[Param, ...]]
    STATE: ClassVar[type[NamedTuple]]
    """The named tuple ``state()`` returns; its fields are the internal state tuple's, the
    first two ``d`` and ``f`` (committed displacement and force) unless the kind overrides
    ``committed``."""

    _committed: tuple[float, ...]
    _trial: tuple[float, ...]

    # -- what each kind provides -------------------------------------------------------------
    @abstractmethod
    def _virgin(self) -> tuple[float, ...]:
        """The state before any load (d = 0, f = 0), in ``STATE``'s field order."""

    @property
    @abstractmethod
    def initial_tangent(self) -> float:
        """Tangent stiffness of the virgin state."""

    @abstractmethod
    def set_trial(self, d: float) -> tuple[float, float]:
        """Trial displacement from the last committed state; returns (force, tangent)."""

    def _check_relations(self) -> None:  # noqa: B027 (optional hook, empty by default)
        """Constraints between parameters (each one's own range is checked before)."""

    def _settings(self) -> dict[str, Any]:
        """Construction options that are not parameters (kept by ``with_params``)."""
        return {}

    # -- written once for every kind ---------------------------------------------------------
    def _init_params(self, **values: float) -> None:
        """Check and set the declared parameters, then start from the virgin state."""
        for param in self.PARAMS:
            object.__setattr__(self, param.name, param.check(self.name, values[param.name]))
        self._check_relations()

    def _start(self) -> None:
        self._committed = self._trial = self._virgin()

    def __repr__(self) -> str:
        inner = ", ".join(f"{k}={v!r}" for k, v in self.parameters.items())
        return f"{type(self).__name__}({inner})"

    @property
    def parameters(self) -> dict[str, float]:
        """The construction parameters, for rebuilding or reporting."""
        return {p.name: float(getattr(self, p.name)) for p in self.PARAMS}

    def commit(self) -> None:
        """Make the current trial state the committed state."""
        self._committed = self._trial

    def revert_to_last_commit(self) -> None:
        """Discard the trial state."""
        self._trial = self._committed

    def revert_to_start(self) -> None:
        """Return to the virgin state (d = 0, f = 0)."""
        self._committed = self._trial = self._virgin()

    @property
    def committed(self) -> tuple[float, float]:
        """Committed (displacement, force)."""
        state = self._committed
        return state[0], state[1]

    def clone(self) -> Self:
        """Independent copy including committed and trial state."""
        return copy.copy(self)

    def state(self) -> ModelState:
        """The committed state as an immutable named tuple (``STATE``)."""
        return cast(ModelState, self.STATE._make(self._committed))

    def with_params(self, params: Mapping[str, float], state: ModelState | None = None) -> Self:
        """A new, independent model of this kind with ``params`` (parameters not given keep
        this model's values), starting from the committed ``state`` (virgin when None).

        ``state`` must come from ``state()`` of a model of the same kind; the new model's next
        ``set_trial`` integrates the new law from it (its committed force is the state's).
        """
        refuse_unknown(self.name, params, self.PARAMS)
        factory = cast(Callable[..., Self], type(self))
        model = factory(**{**self.parameters, **params}, **self._settings())
        if state is not None:
            model._committed = model._trial = self._checked_state(state)
        return model

    def _checked_state(self, state: object) -> tuple[float, ...]:
        if type(state) is not self.STATE:
            raise ModelParameterError(
                self.name,
                f"state must be a {self.STATE.__name__} (from state() of a {self.name} model), "
                f"got {type(state).__name__}",
            )
        values = cast(tuple[float, ...], state)
        for field, value in zip(self.STATE._fields, values, strict=True):
            if not math.isfinite(value):
                raise ModelParameterError(
                    self.name, f"state.{field} must be finite, got {value!r}"
                )
        return values


@dataclass(frozen=True, slots=True)
class ModelKind:
    """A model kind as the registry lists it: its class, parameters and factory."""

    cls: type[HysteresisBase]
    factory: Callable[..., ParametricModel] | None = None
    """Builds a model from keyword parameters; default: the class itself."""

    @property
    def name(self) -> str:
        return self.cls.name

    @property
    def params(self) -> tuple[Param, ...]:
        return self.cls.PARAMS

    @property
    def summary(self) -> str:
        """First line of the kind's module docstring (for docs/configuration.md's table)."""
        doc = sys.modules[self.cls.__module__].__doc__ or self.cls.__doc__ or self.name
        return doc.strip().splitlines()[0].replace("``", "`")

    @property
    def defaults(self) -> dict[str, float]:
        return {p.name: p.default for p in self.params if p.default is not None}

    def build(self, params: Mapping[str, float]) -> ParametricModel:
        """Check names (unknown, missing) then build; values are checked by the class."""
        refuse_unknown(self.name, params, self.params)
        required = [p.name for p in self.params if p.default is None]
        missing = [name for name in required if name not in params]
        if missing:
            raise ModelParameterError(
                self.name,
                f"missing required parameter(s) {', '.join(missing)}; "
                f"required: {', '.join(required)}",
                missing[0],
            )
        factory = self.factory or cast(Callable[..., ParametricModel], self.cls)
        return factory(**params)
