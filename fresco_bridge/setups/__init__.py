"""Setups: the kinematic map between an element's basic DOFs and the actuators.

OpenFresco's experimental setups transform *trial* signals (basic DOFs of the element) into
*ctrl* signals (actuator commands) and *daq* signals back into *out* signals. A site's
``setup`` is a name (``"NoTransformation"``, ``"OneActuator"``) or a ``[sites.setup]`` table
with OpenFresco's setup name as ``kind`` and its parameters (``kinds.py``).
"""

from __future__ import annotations

from typing import Annotated, Any, Literal, Union

from pydantic import BeforeValidator

from .base import Setup, SetupError
from .kinds import NOT_COVERED, SETUP_TABLES, SetupTable, parse_setup_table
from .linear import LinearSetup, make_linear

__all__ = ["NOT_COVERED", "SETUP_TABLES", "LinearSetup", "Setup", "SetupError", "SetupSpec",
           "SetupTable", "make_setup"]


def _setup_value(value: Any) -> Any:
    """A name stays a name (its Literal checks it); a table becomes its kind's model."""
    if isinstance(value, str | SetupTable):
        return value
    return parse_setup_table(value)


SetupSpec = Annotated[Union[Literal["NoTransformation", "OneActuator"], SetupTable],  # noqa: UP007
                      BeforeValidator(_setup_value)]
"""``setup = "OneActuator"`` or ``[sites.setup]`` with ``kind = "ThreeActuators2d"`` …"""


def make_setup(spec: str | SetupTable, n_basic: int) -> Setup:
    """The setup ``spec`` names, for an element with ``n_basic`` basic DOFs."""
    if spec == "NoTransformation":
        return make_linear("NoTransformation", n_basic)
    if spec == "OneActuator":
        return make_linear("OneActuator", n_basic)
    if isinstance(spec, str):
        raise SetupError(f"setup {spec!r} needs its parameters: give a [sites.setup] table "
                         f"with kind = {spec!r}")
    return spec.build(n_basic)
