"""The one list of model kinds; every table of kinds and parameters derives from it.

Adding a kind: one new file in this package (a :class:`~sim_actuator.models.base.HysteresisBase`
subclass declaring ``name``, ``PARAMS``, ``STATE`` and its law) plus one line below.
"""

from __future__ import annotations

from collections.abc import Mapping
from types import MappingProxyType

from sim_actuator.models.base import ModelKind, ModelParameterError, ParametricModel
from sim_actuator.models.bilinear import Bilinear
from sim_actuator.models.bouc_wen import BoucWen
from sim_actuator.models.bwbn import BoucWenBaberNoori
from sim_actuator.models.elastic import Elastic
from sim_actuator.models.menegotto_pinto import MenegottoPinto

__all__ = [
    "MODEL_DEFAULTS",
    "MODEL_KINDS",
    "MODEL_PARAMETERS",
    "make_model",
    "model_kind",
    "model_kinds_markdown",
]

MODEL_KINDS: Mapping[str, ModelKind] = MappingProxyType({kind.name: kind for kind in (
    ModelKind(Elastic),
    ModelKind(Bilinear),
    ModelKind(BoucWen),
    ModelKind(BoucWenBaberNoori),
    ModelKind(MenegottoPinto),
)})  # fmt: skip
"""Model kind name -> its declaration (class, parameters, factory), in documentation order."""

MODEL_PARAMETERS: Mapping[str, Mapping[str, str]] = MappingProxyType({
    name: MappingProxyType({p.name: p.describe() for p in kind.params})
    for name, kind in MODEL_KINDS.items()
})  # fmt: skip
"""Model kind -> {parameter: meaning, unit, allowed range, default}; for docs and hints."""

MODEL_DEFAULTS: Mapping[str, Mapping[str, float]] = MappingProxyType({
    name: MappingProxyType(kind.defaults) for name, kind in MODEL_KINDS.items()
})  # fmt: skip
"""Model kind -> defaults of its optional parameters; every other parameter is required."""


def model_kind(kind: str) -> ModelKind:
    """The declaration of ``kind``, or :class:`ModelParameterError` naming the allowed kinds."""
    try:
        return MODEL_KINDS[kind]
    except (KeyError, TypeError):
        raise ModelParameterError(
            "make_model", f"unknown model kind {kind!r}; allowed: {', '.join(sorted(MODEL_KINDS))}"
        ) from None


def make_model(kind: str, **params: float) -> ParametricModel:
    """Build a model by kind name (see :data:`MODEL_KINDS`) and parameters."""
    return model_kind(kind).build(params)


def model_kinds_markdown() -> str:
    """docs/configuration.md's table cell for ``controller.model`` (and the rig's
    ``[specimen] kind``): every kind, its parameters (optional ones in brackets), its summary."""
    parts = []
    for kind in MODEL_KINDS.values():
        params = ", ".join(p.name if p.default is None else f"[{p.name}]" for p in kind.params)
        parts.append(f"`{kind.name}` ({params}): {kind.summary}")
    return "<br>".join(parts)
