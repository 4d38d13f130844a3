"""The controller adapter interface: what a site needs from an actuator controller.

OpenFresco calls this an *experimental control*: it receives *ctrl* signals (actuator
commands) and returns *daq* signals (measurements). Every method is a coroutine; the caller
(the site) applies the deadline, so implementations must not wrap themselves in
``asyncio.timeout`` (the in-process controller completes without suspending and is driven
eagerly on the hot path).
"""

from __future__ import annotations

import abc
from typing import NamedTuple


class ControllerError(Exception):
    """A controller failed: lost connection, fault word, bad reply. The site goes to HOLD."""


class ControllerLinkError(ControllerError):
    """The controller could not be reached or did not answer (connection refused, closed or
    silent, stale heartbeat): its own state is unknown, not faulted. The site may wait for it
    to answer again (``bridge.controller_recovery``); every other ``ControllerError`` (a latched
    fault, an interlock, a refused command, a malformed reply) needs a human."""


def wrong_count(where: str, n_actuators: int, disp: tuple[float, ...]) -> ControllerError:
    """The error for a ctrl vector whose length is not the controller's actuator count."""
    plural = "" if n_actuators == 1 else "s"
    return ControllerError(f"{where}: drives {n_actuators} actuator{plural}, got {len(disp)} "
                           f"ctrl values {list(disp)}")


class Daq(NamedTuple):
    """Measured signals at the control points, one entry per actuator (mm, kN).

    A named tuple (immutable, compared by value, like the frozen dataclass it was): one is
    made for every measurement, 3 a step, at about half a frozen dataclass's cost."""

    disp: tuple[float, ...]
    force: tuple[float, ...]
    external: tuple[float, ...] | None = None
    """A second displacement per actuator (mm) from a separate transducer, e.g. on the
    specimen behind the frame's compliance and the pin's play, where the controller provides
    one and its config names it (``Controller.external_channel``); None otherwise (the default
    costs nothing: no field is read, no value made)."""


class Controller(abc.ABC):
    """One actuator controller serving ``n_actuators`` control points.

    Setpoints are absolute and idempotent: re-sending the same ctrl displacement is harmless,
    and a motion command is never retried blindly by the adapter.
    """

    n_actuators: int = 1
    inline: bool = False
    """True when every call completes without suspending (in-process); then no deadline task."""
    external_channel: str | None = None
    """What ``Daq.external`` measures when this controller fills it (its config named an
    external channel), e.g. ``"specimen displacement"``; None: ``Daq.external`` is always None.
    The outer-loop correction (``sites/correction_loop.py``) reads it when a site asks for
    ``measured = "external"``."""

    def in_process(self) -> InlineController | None:
        """This controller as an in-process one whose specimen the bridge holds (resume
        replays the record's commands into it), or None: a specimen outside the bridge."""
        return None

    async def connect(self) -> None:  # noqa: B027 - optional hook
        """Open the link to the controller (no-op for in-process controllers)."""

    @abc.abstractmethod
    async def set_ctrl(self, disp: tuple[float, ...]) -> None:
        """Command absolute actuator displacements and wait until they are reached."""

    @abc.abstractmethod
    async def get_daq(self) -> Daq:
        """Acquire the measured displacements and forces for the current command."""

    @abc.abstractmethod
    async def commit(self) -> None:
        """The integrator accepted the step: the current state becomes the committed one."""

    @abc.abstractmethod
    async def tangent_stiffness(self) -> tuple[float, ...]:
        """Current tangent stiffness in actuator space, n×n column-major (kN/mm)."""

    @abc.abstractmethod
    async def initial_stiffness(self) -> tuple[float, ...]:
        """Initial stiffness in actuator space, n×n column-major (kN/mm)."""

    async def hold(self) -> None:  # noqa: B027 - optional hook
        """Stop motion and keep the last command (called when the site enters HOLD)."""

    async def close(self) -> None:  # noqa: B027 - optional hook
        """Release the link; the actuator keeps holding its last command."""

    def status_fields(self) -> dict[str, object]:
        """What the controller adds to its site's ``ctl status`` (a twin: source, learner)."""
        return {}


class InlineController(Controller):
    """An in-process controller: every call completes at once, so its synchronous ``*_now``
    methods are the implementation and the coroutines only wrap them.

    The site calls the ``*_now`` methods directly on its hot path: no coroutine, no eager step
    and no deadline per call (``sites/experimental.py``, the ``*_eager`` methods). Nothing here
    can lose a link: a failure is a ``ControllerError`` that HOLDs the site at once, never a
    ``ControllerLinkError`` to wait out (``bridge.controller_recovery`` does not apply).
    """

    inline = True

    def in_process(self) -> InlineController:
        return self

    @abc.abstractmethod
    def set_ctrl_now(self, disp: tuple[float, ...]) -> None:
        """Command absolute actuator displacements; returns when they are reached."""

    @abc.abstractmethod
    def get_daq_now(self) -> Daq:
        """The measured displacements and forces for the current command."""

    @abc.abstractmethod
    def commit_now(self) -> None:
        """The integrator accepted the step."""

    @abc.abstractmethod
    def reset(self) -> None:
        """Back to the virgin specimen: a new session that starts from zero, and the start of
        a resume's replay of the record (``sites/experimental_kind.SpecimenRestore``)."""

    @abc.abstractmethod
    def tangent_stiffness_now(self) -> tuple[float, ...]:
        """Current tangent stiffness in actuator space, n×n column-major (kN/mm)."""

    @abc.abstractmethod
    def initial_stiffness_now(self) -> tuple[float, ...]:
        """Initial stiffness in actuator space, n×n column-major (kN/mm)."""

    async def set_ctrl(self, disp: tuple[float, ...]) -> None:
        self.set_ctrl_now(disp)

    async def get_daq(self) -> Daq:
        return self.get_daq_now()

    async def commit(self) -> None:
        self.commit_now()

    async def tangent_stiffness(self) -> tuple[float, ...]:
        return self.tangent_stiffness_now()

    async def initial_stiffness(self) -> tuple[float, ...]:
        return self.initial_stiffness_now()


class PhysicalController(Controller):
    """A controller of a physical (or physically simulated) rig: every move really happens, so
    there is no trial state to commit, and the rig cannot report its stiffness: tangent and
    initial stiffness are the configured estimate ``stiffness`` (kN/mm) of every actuator,
    uncoupled."""

    stiffness: float

    async def commit(self) -> None:
        """A physical rig has no trial state to commit."""

    async def tangent_stiffness(self) -> tuple[float, ...]:
        return diagonal((self.stiffness,) * self.n_actuators)

    async def initial_stiffness(self) -> tuple[float, ...]:
        return diagonal((self.stiffness,) * self.n_actuators)


def diagonal(values: tuple[float, ...]) -> tuple[float, ...]:
    """diag(values), n×n column-major (slice assignment: no Python loop over n² entries)."""
    n = len(values)
    out = [0.0] * (n * n)
    out[:: n + 1] = values
    return tuple(out)
