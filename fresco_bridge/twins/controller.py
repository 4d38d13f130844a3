"""The twin controller: how an updatable site answers (``twins/kind.py``).

An updatable site is served through the shared site core with this controller
(``sites.controlled_site``), so sessions, the state table, limits, the operator, the NaN stop,
the record, telemetry and status apply unchanged (``docs/architecture.md``, "Updatable
sites"). A learner that cannot answer is a ``ControllerError``: the site HOLDs, the integrator
stops, and the experimental source is never touched.

With ``causality = "same-step"`` the twin's n-th moving trial of step k awaits (up to the
learner's deadline) its source's n-th published trial of the same step and time
(``twins/source.py``: no polling, no reference to the source site), takes that trial's
measurement (the one read of that trial, shared with the source's own force request; or the
committed one when the source already committed the step) and has the learner learn it before
answering: the paper's order. A trial's measurement is learned tentatively (``worker.py``):
trained on only if it is the one the source commits. Where the order of messages makes
same-step impossible (the client asks the twin's force before sending the source's trial; an
implicit scheme's several trials per step) the twin answers ``previous-step`` for the rest of
the session, said once in a ``same-step-fallback`` event with the true reason, and the
tentative step is unlearned before the answer.

The controller is also a step listener of its own site, after the site's record writer: each
committed twin step gets an update line (the source step its answer was learned through, the
step's update time, the source's one-step error) from the one writer of the site's lines
(``record/site.py``).
"""

from __future__ import annotations

import math
from typing import TYPE_CHECKING, Protocol

from protocol import Signals

from ..causality import Causality
from ..controls.base import Controller, ControllerError, Daq
from ..site_output import CommittedStep
from .learner import Learner, LearnerError, Measured
from .source import SameStepImpossible, SourceFeed

if TYPE_CHECKING:
    from ..record.site import SiteRecorder

__all__ = ["TwinController"]

class TwinHost(Protocol):
    """What the twin controller reads of its own site (its step, trial, events, record)."""

    step: int
    time: float
    trial: Signals

    @property
    def session(self) -> int: ...

    @property
    def in_session(self) -> bool: ...

    recorder: SiteRecorder | None

    def event(self, kind: str, reason: str, **extra: object) -> None: ...


class TwinController(Controller):
    """One twin of a learner, as a one-actuator controller (mm, kN, kN/mm)."""

    n_actuators = 1
    inline = False

    def __init__(self, learner: Learner, twin: str, *, updater: str, causality: Causality,
                 feed: SourceFeed | None = None) -> None:
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
        self.upto: tuple[int, int] | None = None
        """The source (session, step) the last answer was learned through, when that is
        short of what it asked for (its learner catching up: ``twins/catchup.py``)."""
        self._answered = False
        """Whether the last trial was answered by the learner (else no update line)."""
        self._committed: tuple[int, float] | None = None
        """The session and displacement of the twin's last commit: a trial of it again moves
        nothing and asks nothing of the source (``twins/source.py``)."""
        self._site: TwinHost | None = None
        self._feed = feed
        """The source's published trials and commits (same-step)."""
        self._fallback_session = -1
        """The session in which same-step fell back to previous-step."""
        self.same_step_steps = 0
        """Trials answered same-step."""
        self._nth: tuple[int, int, int] = (0, 0, 0)
        """(session, step, n): the twin's moving trials of its current step asked so far."""

    def bind(self, site: TwinHost) -> None:
        """The twin's own site (its step and trial time, its events and record)."""
        self._site = site

    async def set_ctrl(self, disp: tuple[float, ...]) -> None:
        site = self._site
        moves = site is None or (site.session, disp[0]) != self._committed
        same, measured = (await self._source_measured() if self.causality == "same-step"
                          and moves else (False, None))
        self._answered = False
        try:
            force, tangent, through, seconds, error, upto = await self.learner.trial(
                self.twin, disp[0], step=site.step + 1 if site is not None else 1,
                same_step=same, measured=measured)
        except LearnerError as exc:
            raise ControllerError(f"twin {self.twin}: {exc}") from None
        self._d, self._force, self._tangent = disp[0], force, tangent
        self.trained_through, self.update_seconds, self.one_step_error = through, seconds, error
        self.upto = upto
        self._answered = True
        self.same_step_steps += same

    async def _source_measured(self) -> tuple[bool, Measured]:
        """Whether this trial is answered same-step, and the source's trial measurement it
        learns tentatively (None: the source's commit of the step came first, the learner has
        it). ``(False, None)``: previous-step for this trial (fallen back, no trial time, the
        source stopped)."""
        site, feed = self._site, self._feed
        if site is None or feed is None or self._fallback_session == site.session:
            return False, None
        step, t = site.step + 1, site.time
        if not site.trial.time:
            self._fall_back(site, "the client sends no trial time (the source's step cannot "
                            "be matched)")
            return False, None
        nth = self._nth[2] + 1 if self._nth[:2] == (site.session, step) else 1
        self._nth = (site.session, step, nth)
        try:
            got = await feed.measurement(step, t, self.learner.deadline, nth)
        except SameStepImpossible as exc:
            self._fall_back(site, str(exc))
            return False, None
        if got is None:
            return False, None  # the integrator is being stopped: nothing to learn
        d, f, committed = got
        if not (math.isfinite(d) and math.isfinite(f)):
            return False, None
        return True, None if committed else (d, f)

    def _fall_back(self, site: TwinHost, why: str) -> None:
        self._fallback_session = site.session
        site.event("same-step-fallback", f"twin {self.twin}: {why}; previous-step from step "
                   f"{site.step + 1} to the end of session {site.session}", step=site.step + 1)

    async def get_daq(self) -> Daq:
        return Daq((self._d,), (self._force,))

    async def commit(self) -> None:
        if self._site is not None:
            self._committed = (self._site.session, self._d)
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
                                 self.one_step_error, self.upto)

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
