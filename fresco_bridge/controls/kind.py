"""What a controller kind declares, in one place: its config model, its factory, how many
actuators it can drive, and the line docs/configuration.md's table shows for it.

Each kind's module ends with its ``KIND``; ``controls/registry.py`` lists them (one line each),
and the config's discriminated union, its error texts and docs/configuration.md's table derive
from it.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

from sim_actuator.platform import Geometry

from ..config_model import StrictConfig
from .base import Controller

__all__ = ["ControllerConfigBase", "ControllerKind"]


class ControllerConfigBase(StrictConfig):
    """The ``[sites.controller]`` table of one kind; subclasses set ``kind: Literal[...]``."""

    kind: str

    def external_channel(self) -> str | None:
        """What the external channel this table names measures (``Controller.external_channel``
        of the adapter built from it), or None: the kind has none, or the table names none."""
        return None


@dataclass(frozen=True)
class ControllerKind:
    """One controller kind: ``kind = "<name>"`` in ``[sites.controller]``."""

    name: str
    config: type[ControllerConfigBase]
    factory: Callable[[Any, int, Geometry | None], Controller]
    """``factory(config, n_actuators, geometry)``: the adapter for a site whose setup drives
    ``n_actuators`` control points (``setups/`` owns that count) through ``geometry`` (the
    setup's platform, for a simulated specimen several actuators load; None without one)."""
    summary: str
    """The kind's description in docs/configuration.md's table (markdown, one cell)."""
    max_actuators: int | None = 1
    """How many actuators one controller of this kind drives (None: any number)."""
    fits: Callable[[Any, int, Geometry | None], str | None] | None = None
    """``fits(config, n_actuators, geometry)``: why this kind's table cannot drive
    ``n_actuators`` through ``geometry`` (e.g. a table per channel, and not that many), or
    None."""

    def actuators_problem(self, config: ControllerConfigBase, n_actuators: int,
                          geometry: Geometry | None = None) -> str | None:
        """Why ``config`` cannot drive a site of ``n_actuators`` control points, or None."""
        most = self.max_actuators
        if most is not None and n_actuators > most:
            return (f"controller {self.name} drives {most} actuator(s); this site needs "
                    f"{n_actuators}")
        return None if self.fits is None else self.fits(config, n_actuators, geometry)

    def build(self, config: ControllerConfigBase, n_actuators: int,
              geometry: Geometry | None = None) -> Controller:
        return self.factory(config, n_actuators, geometry)
