"""The one list of controller kinds; the config's union, its error texts, the daemon's factory
and the configuration table of docs/configuration.md derive from it.

Adding a kind: one new module in this package (its config model, adapter and ``KIND``) plus
one line below.
"""

from __future__ import annotations

from collections.abc import Mapping
from types import MappingProxyType

from .base import Controller
from .generic_tcp import KIND as GENERIC_TCP
from .kind import ControllerConfigBase, ControllerKind
from .modbus import KIND as MODBUS
from .mts import KIND as MTS
from .rig import KIND as RIG
from .sim import KIND as SIM

__all__ = ["CONTROLLER_KINDS", "controller_kind", "controller_kinds_markdown", "make_controller"]

CONTROLLER_KINDS: Mapping[str, ControllerKind] = MappingProxyType({kind.name: kind for kind in (
    SIM,
    RIG,
    MODBUS,
    MTS,
    GENERIC_TCP,
)})  # fmt: skip
"""Controller kind name -> its declaration, in documentation order (``sim`` is the default)."""


def known_kinds() -> str:
    """``sim, rig, modbus, mts or generic-tcp``: the kinds, as error texts name them."""
    names = list(CONTROLLER_KINDS)
    return ", ".join(names[:-1]) + f" or {names[-1]}" if len(names) > 1 else names[0]


def controller_kind(name: str) -> ControllerKind:
    """The declaration of kind ``name``, or ``ValueError`` naming the kinds there are."""
    try:
        return CONTROLLER_KINDS[name]
    except KeyError:
        raise ValueError(f"unknown controller kind {name!r}; expected {known_kinds()}") from None


def make_controller(config: ControllerConfigBase, n_actuators: int) -> Controller:
    """The adapter ``config`` asks for, driving ``n_actuators`` control points."""
    return controller_kind(config.kind).build(config, n_actuators)


def controller_kinds_markdown() -> str:
    """docs/configuration.md's table cell for ``[sites.controller] kind``."""
    parts = []
    for kind in CONTROLLER_KINDS.values():
        keys = ", ".join(f"`{k}`" for k in kind.config.model_fields if k != "kind")
        actuators = {None: "any number of actuators", 1: "one actuator"}.get(
            kind.max_actuators, f"up to {kind.max_actuators} actuators")
        parts.append(f"`{kind.name}`: {kind.summary}; {actuators}; keys {keys}")
    return "<br>".join(parts)
