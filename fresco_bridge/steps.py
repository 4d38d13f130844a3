"""A committed step: the one value a site hands its listeners (record, telemetry, monitors, an
updater) and the base of the telemetry step message."""

from __future__ import annotations

from dataclasses import dataclass

__all__ = ["CommittedStep"]


@dataclass(frozen=True, slots=True)
class CommittedStep:
    """One committed step of a site (mm, kN, s): what the integrator asked (``trial``, basic
    DOFs), what the controller was sent (``ctrl``) and what was measured (``daq_*``), both in
    actuator DOFs."""

    site: str
    session: int
    step: int
    time: float
    trial: tuple[float, ...]
    ctrl: tuple[float, ...]
    daq_disp: tuple[float, ...]
    daq_force: tuple[float, ...]
    state: str
