"""The twin controller: what makes an ordinary site an updatable one.

An updatable site is an ``ExperimentalSite`` whose controller answers from a twin instead of
an actuator, so sessions, the state table, limits, the operator, the NaN stop, the record,
telemetry and status apply unchanged (``docs/architecture.md``, "Updatable sites"). A learner
that cannot answer is a ``ControllerError``: the site HOLDs, the integrator stops, and the
experimental source is never touched.
"""

from __future__ import annotations

from ..controls.base import Controller, ControllerError, Daq
from .learner import Learner, LearnerError

__all__ = ["TwinController"]


class TwinController(Controller):
    """One twin of a learner, as a one-actuator controller (mm, kN, kN/mm)."""

    n_actuators = 1
    inline = False

    def __init__(self, learner: Learner, twin: str, *, updater: str, causality: str) -> None:
        self.learner = learner
        self.twin = twin
        self.updater = updater
        self.causality = causality
        self._d = 0.0
        self._force = 0.0
        self._tangent: float | None = None
        self.trained_through = 0
        """The source step the last answer was learned through."""

    async def set_ctrl(self, disp: tuple[float, ...]) -> None:
        try:
            force, tangent, through = await self.learner.trial(self.twin, disp[0])
        except LearnerError as exc:
            raise ControllerError(f"twin {self.twin}: {exc}") from None
        self._d, self._force, self._tangent = disp[0], force, tangent
        self.trained_through = through

    async def get_daq(self) -> Daq:
        return Daq((self._d,), (self._force,))

    async def commit(self) -> None:
        try:
            self.learner.commit(self.twin)
        except LearnerError as exc:
            raise ControllerError(f"twin {self.twin}: {exc}") from None

    async def tangent_stiffness(self) -> tuple[float, ...]:
        if self._tangent is None:
            return await self.initial_stiffness()
        return (self._tangent,)

    async def initial_stiffness(self) -> tuple[float, ...]:
        try:
            return (await self.learner.initial(self.twin),)
        except LearnerError as exc:
            raise ControllerError(f"twin {self.twin}: {exc}") from None

    def status_fields(self) -> dict[str, object]:
        return {"kind": "updatable", "source": self.learner.source, "updater": self.updater,
                "causality": self.causality, **self.learner.status(self.twin)}
