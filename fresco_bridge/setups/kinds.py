"""The ``[sites.setup]`` tables: one per OpenFresco setup, with OpenFresco's parameter names, so
a lab's Tcl line ``expSetup ThreeActuators2d 1 -control 1 1000 1000 1000 500 500 -nlGeom``
becomes ``{ kind = "ThreeActuators2d", La1 = 1000.0, …, L2 = 500.0, nlGeom = true }``.

Each table builds its setup for an element of ``n_basic`` basic DOFs. The platform geometry
of each planar kind (where each actuator's two joints are) is read off OpenFresco's exact
stroke formulas and written here as ground and platform points, in the platform's frame:
the control point at the origin, x to the right, y up, θ counter-clockwise.
"""

from __future__ import annotations

from typing import Annotated, Any, Literal

from pydantic import Field, ValidationError

from ..config_model import StrictConfig
from .base import Factors, Setup, SetupError, factor_keys
from .compose import Aggregator, Scaled
from .linear import make_linear
from .planar import PlanarSetup
from .platform import GeometryError, Link, Platform

Length = Annotated[float, Field(gt=0)]
"""An actuator length (La): positive."""
Offset = Annotated[float, Field(ge=0)]
"""A rigid length of the loading beam (L): zero or positive."""
Factor = float | list[float] | None
Side = Literal["left", "right"]


class SetupTable(StrictConfig):
    """Keys every setup has: ``kind`` and OpenFresco's twenty scale factors."""

    kind: str
    trialDispFact: Factor = None
    trialVelFact: Factor = None
    trialAccelFact: Factor = None
    trialForceFact: Factor = None
    trialTimeFact: Factor = None
    outDispFact: Factor = None
    outVelFact: Factor = None
    outAccelFact: Factor = None
    outForceFact: Factor = None
    outTimeFact: Factor = None
    ctrlDispFact: Factor = None
    ctrlVelFact: Factor = None
    ctrlAccelFact: Factor = None
    ctrlForceFact: Factor = None
    ctrlTimeFact: Factor = None
    daqDispFact: Factor = None
    daqVelFact: Factor = None
    daqAccelFact: Factor = None
    daqForceFact: Factor = None
    daqTimeFact: Factor = None

    def __str__(self) -> str:
        return self.kind

    def factors(self) -> Factors:
        given = []
        for key in factor_keys():
            value = getattr(self, key)
            if value is not None:
                given.append((key, tuple(value) if isinstance(value, list) else (value,)))
        return Factors(tuple(given))

    def transformation(self, n_basic: int) -> Setup:
        """The setup without factors (each kind's own)."""
        raise NotImplementedError

    def own_size(self) -> int:
        """The basic DOFs this setup serves on its own (inside an ``Aggregator``)."""
        raise SetupError(f"{self.kind} inside an Aggregator needs sizeTrialOut = [t, o]")

    def build(self, n_basic: int) -> Setup:
        """The setup for an element of ``n_basic`` basic DOFs, factors applied."""
        try:
            inner = self.transformation(n_basic)
        except GeometryError as exc:
            raise SetupError(f"{self.kind}: {exc}") from None
        factors = self.factors()
        return inner if factors.none else Scaled(inner, factors)


class _Sized(SetupTable):
    sizeTrialOut: list[int] | None = None
    """OpenFresco's ``-sizeTrialOut t o``: the element's basic DOFs (default: the site's
    ``dofs``; needed inside an ``Aggregator``). t and o must be equal here."""

    def size(self, n_basic: int) -> int:
        if self.sizeTrialOut is None:
            return n_basic
        t = self.sizeTrialOut
        if len(t) != 2 or t[0] != t[1] or t[0] < 1:
            raise SetupError(f"{self.kind}: sizeTrialOut = {t}: give [t, o] with t = o ≥ 1 "
                             "(the bridge answers as many DOFs as it is sent)")
        return t[0]

    def own_size(self) -> int:
        return super().own_size() if self.sizeTrialOut is None else self.size(0)


class NoTransformationTable(_Sized):
    kind: Literal["NoTransformation"]

    def transformation(self, n_basic: int) -> Setup:
        return make_linear("NoTransformation", self.size(n_basic))


class OneActuatorTable(_Sized):
    kind: Literal["OneActuator"]
    dir: int | None = Field(default=None, ge=1)
    """The basic DOF the actuator drives (OpenFresco's ``$dir``, 1-based); without it a
    1-DOF element or a two-node element (stroke = u_j − u_i)."""

    def transformation(self, n_basic: int) -> Setup:
        return make_linear("OneActuator", self.size(n_basic), self.dir)


def _horizontal(side: Side, point: tuple[float, float], la: float) -> Link:
    """A horizontal actuator on ``point``, its ground end left or right of it."""
    x, y = point
    return Link((x - la if side == "left" else x + la, y), point)


def _vertical(point: tuple[float, float], la: float) -> Link:
    """A vertical actuator on ``point``, its ground end below it."""
    return Link((point[0], point[1] - la), point)


class _Planar(SetupTable):
    nlGeom: bool = False
    """``-nlGeom``: exact geometry (else linearised at rest)."""

    def links(self) -> tuple[Link, ...]:
        raise NotImplementedError

    def driven(self) -> tuple[int, ...]:
        return (0, 1, 2)

    def dofs(self) -> tuple[int, int, int]:
        return (0, 1, 2)

    def n_trial(self) -> int:
        return 3

    def phi(self) -> float:
        return 0.0

    def own_size(self) -> int:
        return self.n_trial()

    def transformation(self, n_basic: int) -> Setup:
        need = self.n_trial()
        if n_basic != need:
            raise SetupError(f"{self.kind} serves an element of {need} basic DOFs (set the "
                             f"site's dofs = {need}); this site has {n_basic}")
        return PlanarSetup(self.kind, Platform(self.links(), self.driven()), need,
                           self.dofs(), nl_geom=self.nlGeom, phi_loc_x=self.phi())


class _Rotated(_Planar):
    phiLocX: float = 0.0
    """``-phiLocX``: the angle (degrees) from the element's local x to the setup's x."""

    def phi(self) -> float:
        return self.phiLocX


class TwoActuators2dTable(_Rotated):
    """Two parallel horizontal actuators, one at the control point, one ``L`` above it; the
    vertical DOF is not driven (held at zero, its force not reported)."""

    kind: Literal["TwoActuators2d"]
    La1: Length
    La2: Length
    L: Length
    posAct: Side = "left"

    def links(self) -> tuple[Link, ...]:
        return (_horizontal(self.posAct, (0.0, 0.0), self.La1),
                _horizontal(self.posAct, (0.0, self.L), self.La2))

    def driven(self) -> tuple[int, ...]:
        return (0, 2)


class _ThreeOnBeam(_Rotated):
    """One horizontal actuator at an end of a loading beam and two vertical ones under it,
    ``L1`` left and ``L2`` right of the control point."""

    La1: Length
    La2: Length
    La3: Length
    L1: Offset
    L2: Offset
    posAct1: Side = "left"

    def links(self) -> tuple[Link, ...]:
        left, right = (-self.L1, 0.0), (self.L2, 0.0)
        end = left if self.posAct1 == "left" else right
        return (_horizontal(self.posAct1, end, self.La1), _vertical(left, self.La2),
                _vertical(right, self.La3))


class ThreeActuators2dTable(_ThreeOnBeam):
    kind: Literal["ThreeActuators2d"]


class InvertedVBrace2dTable(_ThreeOnBeam):
    """The same geometry as ``ThreeActuators2d``; forces are the actuators' resultant (see
    docs/openfresco-setups.md for OpenFresco's six load cells)."""

    kind: Literal["InvertedVBrace2d"]


class _ThreeJointOffset(_Rotated):
    """``ThreeActuators2d`` whose joints sit off the beam's axis: the horizontal actuator at
    ``L1 + L2`` left (or ``L3 + L4`` right), the vertical ones at (−L2, −L5) and (L3, −L6)."""

    La1: Length
    La2: Length
    La3: Length
    L1: Offset
    L2: Offset
    L3: Offset
    L4: Offset
    L5: Offset
    L6: Offset
    posAct1: Side = "left"

    def links(self) -> tuple[Link, ...]:
        end = (-(self.L1 + self.L2), 0.0) if self.posAct1 == "left" else (self.L3 + self.L4, 0.0)
        return (_horizontal(self.posAct1, end, self.La1),
                _vertical((-self.L2, -self.L5), self.La2),
                _vertical((self.L3, -self.L6), self.La3))


class ThreeActuatorsJntOff2dTable(_ThreeJointOffset):
    kind: Literal["ThreeActuatorsJntOff2d"]


class InvertedVBraceJntOff2dTable(_ThreeJointOffset):
    kind: Literal["InvertedVBraceJntOff2d"]


class _Chosen(_Planar):
    """The platform on three DOFs of a larger element (``dofH dofV dofR``, 1-based)."""

    dofH: int = Field(ge=1)
    dofV: int = Field(ge=1)
    dofR: int = Field(ge=1)
    sizeTrial: int = Field(ge=3)
    sizeOut: int = Field(ge=3)

    def dofs(self) -> tuple[int, int, int]:
        return (self.dofH - 1, self.dofV - 1, self.dofR - 1)

    def n_trial(self) -> int:
        if self.sizeTrial != self.sizeOut:
            raise SetupError(f"{self.kind}: sizeTrial = {self.sizeTrial} and sizeOut = "
                             f"{self.sizeOut} must be equal (the bridge answers as many "
                             "DOFs as it is sent)")
        return self.sizeTrial


class ThreeActuatorsTable(_Chosen):
    """``ThreeActuators2d`` with every joint ``L3`` above the control point."""

    kind: Literal["ThreeActuators"]
    La1: Length
    La2: Length
    La3: Length
    L1: Offset
    L2: Offset
    L3: float
    posAct1: Side = "left"

    def links(self) -> tuple[Link, ...]:
        left, right = (-self.L1, self.L3), (self.L2, self.L3)
        end = left if self.posAct1 == "left" else right
        return (_horizontal(self.posAct1, end, self.La1), _vertical(left, self.La2),
                _vertical(right, self.La3))


class ThreeActuatorsJntOffTable(_Chosen):
    """The horizontal actuator at (−(L1 + L2), L6) (right: (L3 + L4, L6)), the vertical ones
    at (−L2, L6 − L5) and (L3, L6 − L7)."""

    kind: Literal["ThreeActuatorsJntOff"]
    La1: Length
    La2: Length
    La3: Length
    L1: Offset
    L2: Offset
    L3: Offset
    L4: Offset
    L5: float
    L6: float
    L7: float
    posAct1: Side = "left"

    def links(self) -> tuple[Link, ...]:
        end = ((-(self.L1 + self.L2), self.L6) if self.posAct1 == "left"
               else (self.L3 + self.L4, self.L6))
        return (_horizontal(self.posAct1, end, self.La1),
                _vertical((-self.L2, self.L6 - self.L5), self.La2),
                _vertical((self.L3, self.L6 - self.L7), self.La3))


class AggregatorTable(SetupTable):
    """Setups side by side on one controller (OpenFresco's ``-setup tag1 tag2 …``)."""

    kind: Literal["Aggregator"]
    setups: list[dict[str, Any]] = Field(min_length=1)
    """The setups' tables, in order; each takes the next trial components and actuators."""

    def parts(self) -> list[SetupTable]:
        return [parse_setup_table(t, where=f"setups[{i}]") for i, t in enumerate(self.setups)]

    def transformation(self, n_basic: int) -> Setup:
        setup = Aggregator([table.build(table.own_size()) for table in self.parts()])
        if setup.n_basic != n_basic:
            raise SetupError(f"Aggregator: its setups serve {setup.n_basic} basic DOFs; this "
                             f"site has dofs = {n_basic}")
        return setup

    def own_size(self) -> int:
        raise SetupError("Aggregator: an Aggregator inside an Aggregator (list its setups "
                         "directly)")


SETUP_TABLES: dict[str, type[SetupTable]] = {
    "NoTransformation": NoTransformationTable,
    "OneActuator": OneActuatorTable,
    "TwoActuators2d": TwoActuators2dTable,
    "ThreeActuators2d": ThreeActuators2dTable,
    "ThreeActuators": ThreeActuatorsTable,
    "ThreeActuatorsJntOff2d": ThreeActuatorsJntOff2dTable,
    "ThreeActuatorsJntOff": ThreeActuatorsJntOffTable,
    "InvertedVBrace2d": InvertedVBrace2dTable,
    "InvertedVBraceJntOff2d": InvertedVBraceJntOff2dTable,
    "Aggregator": AggregatorTable,
}
"""OpenFresco's setup name -> its table, in documentation order."""

NOT_COVERED = ("FourActuators3d",)
"""OpenFresco setups the bridge does not build (docs/openfresco-setups.md says why)."""


def setup_kinds_markdown() -> str:
    """docs/configuration.md's table cell for ``[sites.setup] kind``: each kind and its keys
    (beside ``kind`` and the twenty scale factors every kind has)."""
    common = set(SetupTable.model_fields)
    parts = []
    for name, table in SETUP_TABLES.items():
        keys = ", ".join(f"`{k}`" for k in table.model_fields if k not in common)
        parts.append(f"`{name}`" + (f": {keys}" if keys else ""))
    return "<br>".join(parts)


def parse_setup_table(value: Any, where: str = "") -> SetupTable:
    """A ``[sites.setup]`` table as its kind's model; ValueError naming the key and reason."""
    at = f"{where}." if where else ""
    if not isinstance(value, dict):
        raise ValueError(f"{where or 'setup'}: a setup name or a table with kind = …")
    kind = value.get("kind")
    table = SETUP_TABLES.get(kind) if isinstance(kind, str) else None
    if table is None:
        known = ", ".join(SETUP_TABLES)
        why = (f"{kind} is not supported by the bridge (see docs/openfresco-setups.md)"
               if kind in NOT_COVERED else f"unknown setup kind {kind!r}")
        raise ValueError(f"{at}kind: {why}; expected one of {known}")
    try:
        return table.model_validate(value)
    except ValidationError as exc:
        problems = []
        for err in exc.errors():
            key = ".".join(str(p) for p in err["loc"]) or "kind"
            msg = ("unknown key (typo?)" if err["type"] == "extra_forbidden"
                   else err["msg"].removeprefix("Value error, "))
            problems.append(f"{at}{key}: {msg}")
        raise ValueError(f"{kind}: " + "; ".join(problems)) from None
