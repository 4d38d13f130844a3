"""The twin controller: what makes an ordinary site an updatable one.

An updatable site is an ``ExperimentalSite`` whose controller answers from a twin instead of
an actuator, so sessions, the state table, limits, the operator, the NaN stop, the record,
telemetry and status apply unchanged (``docs/architecture.md``, "Updatable sites"). A learner
that cannot answer is a ``ControllerError``: the site HOLDs, the integrator stops, and the
experimental source is never touched.

With ``causality = "same-step"`` the twin's trial of step k waits (up to the learner's
deadline) for the source's trial of the same step and time to reach its controller, takes the
source's measurement of it (the one read of that trial, shared with the source's own force
request) and has the learner learn it before answering: the paper's order. OpenSees sends every
element's trial before any force request, so the source's trial arrives whatever the element
order; a client that asks the twin's force before sending the source's trial would wait
forever: past the deadline the twin answers ``previous-step`` for the rest of the session,
said in a ``same-step-fallback`` event.

The controller is also a step listener of its own site, after the site's record writer: each
committed twin step gets an update line (the source step its answer was learned through, the
step's update time, the source's one-step error) from the one writer of the site's lines
(``record/site.py``).
"""

from __future__ import annotations

import asyncio
import math
from typing import TYPE_CHECKING, Protocol, runtime_checkable

from protocol import Signals

from ..controls.base import Controller, ControllerError, Daq
from ..safety import SiteState
from ..site_output import CommittedStep
from .learner import Learner, LearnerError

if TYPE_CHECKING:
    from ..record.site import SiteRecorder

__all__ = ["TwinController"]

POLL = 0.0002
"""Seconds between two looks at the source's trial while a same-step trial waits for it."""


class TwinHost(Protocol):
    """What the twin controller reads of its own site (its step, trial, events, record)."""

    session: int
    step: int
    time: float
    trial: Signals
    in_session: bool
    recorder: SiteRecorder | None

    def event(self, kind: str, reason: str, **extra: object) -> None: ...


@runtime_checkable
class MeasuredSource(Protocol):
    """What a same-step twin reads of its source site: its trial and that trial's one
    measurement."""

    step: int
    time: float
    state: SiteState
    pending: tuple[float, ...] | None

    @property
    def trial_forwarded(self) -> bool: ...

    async def acquire(self) -> Daq: ...


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
        self.update_seconds = 0.0
        """The worker's update time of the twin's current step (the last answer's)."""
        self.one_step_error: float | None = None
        """The source's one-step error of the twin's current step (the last answer's)."""
        self._answered = False
        """Whether the last trial was answered by the learner (else no update line)."""
        self._site: TwinHost | None = None
        self._source: MeasuredSource | None = None
        self._fallback_session = -1
        """The session in which same-step fell back to previous-step."""
        self.same_step_steps = 0
        """Trials answered same-step."""

    def bind(self, site: TwinHost, source: MeasuredSource) -> None:
        """The twin's own site and its source's (same-step matches their trials)."""
        self._site, self._source = site, source

    async def set_ctrl(self, disp: tuple[float, ...]) -> None:
        same = self.causality == "same-step" and await self._source_measured()
        self._answered = False
        try:
            force, tangent, through, seconds, error = await self.learner.trial(
                self.twin, disp[0], same_step=same)
        except LearnerError as exc:
            raise ControllerError(f"twin {self.twin}: {exc}") from None
        self._d, self._force, self._tangent = disp[0], force, tangent
        self.trained_through, self.update_seconds, self.one_step_error = through, seconds, error
        self._answered = True
        self.same_step_steps += same

    async def _source_measured(self) -> bool:
        """Wait for the source's trial of this step; the learner gets its measurement. False:
        previous-step for this trial (fallen back, no trial time, source not running)."""
        site, source = self._site, self._source
        if site is None or source is None or self._fallback_session == site.session:
            return False
        step, t = site.step + 1, site.time
        if not site.trial.time:
            self._fall_back(site, "the client sends no trial time (the source's step cannot "
                            "be matched)")
            return False
        loop = asyncio.get_running_loop()
        end = loop.time() + self.learner.deadline
        while not (source.step + 1 == step and source.time == t and source.pending is None
                   and source.trial_forwarded):
            if source.state in (SiteState.HOLD, SiteState.FAULT):
                return False  # the integrator is being stopped: nothing to learn
            if loop.time() > end:
                self._fall_back(site, f"the source's trial of step {step} (t = {t:g} s) did "
                                f"not arrive within {self.learner.deadline:g} s of the twin's: "
                                "the client asks the twin's force before sending the source's "
                                "trial")
                return False
            await asyncio.sleep(POLL)
        daq = await source.acquire()
        d, f = daq.disp[0], daq.force[0]
        if source.state is not SiteState.RUNNING or not (math.isfinite(d) and math.isfinite(f)):
            return False
        self.learner.observe_same_step(step, d, f)
        return True

    def _fall_back(self, site: TwinHost, why: str) -> None:
        self._fallback_session = site.session
        site.event("same-step-fallback", f"twin {self.twin}: {why}; previous-step from step "
                   f"{site.step + 1} to the end of session {site.session}", step=site.step + 1)

    async def get_daq(self) -> Daq:
        return Daq((self._d,), (self._force,))

    async def commit(self) -> None:
        try:
            self.learner.commit(self.twin)
        except LearnerError as exc:
            raise ControllerError(f"twin {self.twin}: {exc}") from None

    def step_committed(self, step: CommittedStep) -> None:
        """The site's listener: the committed step's update line in the record (none for a
        step whose last trial the learner did not answer: the site HOLDs then)."""
        self.step_values(step.session, step.step, step.time, step.ctrl, step.daq_disp)

    def step_values(self, session: int, step: int, time: float, ctrl: tuple[float, ...],
                    daq_disp: tuple[float, ...]) -> None:
        site = self._site
        if self._answered and site is not None and site.recorder is not None:
            site.recorder.update(session, step, self.trained_through, self.update_seconds,
                                 self.one_step_error)

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
        site = self._site
        fallen = site is not None and self._fallback_session == site.session
        return {"kind": "updatable", "source": self.learner.source, "updater": self.updater,
                "causality": self.causality + (" (fell back to previous-step)" if fallen
                                               else ""),
                **self.learner.status(self.twin, active=site is not None and site.in_session)}
