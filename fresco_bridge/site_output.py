"""What leaves a site for its listeners (the run record, telemetry, the monitors, an updater):
each committed step (``CommittedStep``, also the base of the telemetry step message) and each
event (``SiteNotice``).

Below the sites and below their listeners, so the listeners need nothing of a site to take what
it hands them, and any kind of site hands them the same values. Which listeners a site has, and
the methods they implement, are the site's own (``sites/listeners.py``).
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass

__all__ = ["CommittedStep", "SiteNotice"]


@dataclass(frozen=True, slots=True, init=False)
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

    def __init__(self, site: str, session: int, step: int, time: float,
                 trial: tuple[float, ...], ctrl: tuple[float, ...],
                 daq_disp: tuple[float, ...], daq_force: tuple[float, ...], state: str) -> None:
        """The generated ``__init__`` of a frozen dataclass, at about half the cost (one is made
        every committed step when a listener is attached): it sets the slots through their
        descriptors instead of ``object.__setattr__`` by name. Still frozen, compared and hashed
        by value; a named tuple (as ``Signals``) is not possible: ``StepSample`` extends it."""
        _SET[0](self, site)
        _SET[1](self, session)
        _SET[2](self, step)
        _SET[3](self, time)
        _SET[4](self, trial)
        _SET[5](self, ctrl)
        _SET[6](self, daq_disp)
        _SET[7](self, daq_force)
        _SET[8](self, state)


_SET = tuple(CommittedStep.__dict__[name].__set__ for name in (
    "site", "session", "step", "time", "trial", "ctrl", "daq_disp", "daq_force", "state"))
"""The slots' setters, in field order (``CommittedStep.__init__``)."""


@dataclass(frozen=True, slots=True)
class SiteNotice:
    """An event of a site (``hold``, ``limit``, ``session-open``, …) with its reason; ``extra``
    is what the record keeps with it (telemetry publishes its scalar entries)."""

    site: str
    session: int
    step: int
    time: float
    kind: str
    reason: str
    extra: Mapping[str, object]
