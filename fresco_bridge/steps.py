"""A committed step: the one value a site hands its listeners (record, telemetry, monitors, an
updater) and the base of the telemetry step message."""

from __future__ import annotations

from dataclasses import dataclass

__all__ = ["CommittedStep"]


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
