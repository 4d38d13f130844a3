"""The one home of the integrator coupling loop: the built-in explicit Newmark driving story
elements of a shear frame (the demo, ``lab integrate``, the paper study, the benchmarks).

A *story element* is anything with OpenSees material semantics for one story drift:
``set_trial(drift) -> (force, tangent)`` from its last commit, and ``commit()``. A hysteresis
model of ``sim_actuator.models`` is one, so is a bridge site over the genericClient protocol
(:class:`~fresco_bridge.integrator.link.SiteElement`), a specimen read through a load cell
(:class:`MeasuredElement`) and an updater's twin (:class:`UpdatingTwin`). Several elements may
share a story: their forces add up (the paper layout's tested damper and its twin side by side).

Per step, explicit Newmark knows the trial drifts before any force: each element gets its
``set_trial`` once, in the order the elements were given, the integrator commits with the summed
story forces, then every element is committed in the same order.

**Causality of a twin that learns** (``Placement(..., learns_from="tested")``): right after the
source element's trial, the coupling hands its (drift, force) to the learner's ``measured``.
What the twin's force at step ``i`` may depend on is the twin's ``causality``, stated once here
because a study copied to a served twin stands or falls with it:

* ``same-step``: the updater observes the tested element's step ``i`` *before* the twin answers
  step ``i`` (the source paper's order, and the study's default). Only possible when the tested
  element is measured first in the same step, as in this in-process loop; the source must come
  before the twin in the coupling's order, else the coupling refuses it.
* ``previous-step``: the twin's step ``i`` is answered only from what was committed through step
  ``i - 1``; the updater observes step ``i`` after the twin's commit. This is what a twin served
  live under OpenSees can always honour, whatever order OpenSees asks its elements in.

    coupling = StoryCoupling({"tested": Placement(0, MeasuredElement(model, load_cell)),
                              "twin": Placement(1, UpdatingTwin(updater, "previous-step"),
                                                learns_from="tested")})
    integrator = coupled_integrator(paper_two_story_frame(), coupling, motion, dt=dt, zeta=zeta)
    response = run_coupled(integrator, coupling, progress=ProgressBar("steps", integrator.n_steps))
    coupling.drift("twin"), coupling.force("twin")      # committed histories, step 0 first
"""

from __future__ import annotations

from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass
from typing import TYPE_CHECKING, Protocol, runtime_checkable

import numpy as np
import numpy.typing as npt

from fresco_bridge.integrator.ground_motion import GroundMotion
from fresco_bridge.integrator.newmark import ExperimentalForce, ExplicitNewmark, Response
from fresco_bridge.integrator.shear_building import ShearBuilding

from ..causality import CAUSALITIES, Causality

if TYPE_CHECKING:
    from fresco_bridge.updating.base import Updater
    from sim_actuator.effects import Sensor
    from sim_actuator.models.base import HysteresisModel

__all__ = [
    "CAUSALITIES",
    "Causality",
    "LearningElement",
    "MeasuredElement",
    "Placement",
    "StoryCoupling",
    "StoryElement",
    "UpdatingTwin",
    "coupled_integrator",
    "frame_integrator",
    "run_coupled",
]

FloatArray = npt.NDArray[np.float64]


@runtime_checkable
class StoryElement(Protocol):
    """A restoring force of one story drift with material semantics (trial from the last
    commit; ``commit`` makes it the committed state)."""

    def set_trial(self, d: float) -> tuple[float, float]: ...

    def commit(self) -> None: ...


@runtime_checkable
class TimedElement(Protocol):
    """An element that wants the step's time before its trial (a bridge site records it)."""

    def begin_step(self, step: int, time: float) -> None: ...


@runtime_checkable
class LearningElement(Protocol):
    """A story element that learns from another element's measurements (an updater's twin):
    ``measured(d, force)`` gets each trial of its source, ``causality`` says when it may use
    it."""

    @property
    def causality(self) -> Causality: ...

    def measured(self, d: float, force: float) -> None: ...

    def set_trial(self, d: float) -> tuple[float, float]: ...

    def commit(self) -> None: ...


@dataclass(frozen=True)
class Placement:
    """Where an element acts: ``story`` (0-based: story 0 joins the ground and floor 1) and the
    initial stiffness estimate the integrator uses for Rayleigh damping and its stability check
    (default: the element's ``initial_tangent`` when it has one, else 0). ``learns_from`` names
    the element whose measurements this one (a :class:`LearningElement`) learns from."""

    story: int
    element: StoryElement
    stiffness: float | None = None
    learns_from: str | None = None

    def initial_stiffness(self) -> float:
        if self.stiffness is not None:
            return float(self.stiffness)
        return float(getattr(self.element, "initial_tangent", 0.0))


class StoryCoupling:
    """The experimental force of :class:`ExplicitNewmark` for named elements placed in stories;
    commits them after each integrator commit and keeps their committed histories."""

    def __init__(self, elements: Mapping[str, Placement]) -> None:
        if not elements:
            raise ValueError("a coupling needs at least one element")
        for name, placement in elements.items():
            if placement.story < 0:
                raise ValueError(f"element {name!r}: story must be >= 0, got {placement.story}")
            if not isinstance(placement.element, StoryElement):
                raise TypeError(f"element {name!r} has no set_trial(d)/commit()")
        self.placements = dict(elements)
        self.stories: tuple[int, ...] = tuple(sorted({p.story for p in elements.values()}))
        """The coupled stories, ascending: the integrator's ``experimental_stories``."""
        column = {story: i for i, story in enumerate(self.stories)}
        self._plan = [(name, p.element, column[p.story]) for name, p in elements.items()]
        self._timed = [p.element for p in elements.values() if isinstance(p.element, TimedElement)]
        self._learners = _learners(self.placements)
        self._trial: dict[str, tuple[float, float]] = {}
        self._drift: dict[str, list[float]] = {name: [] for name in elements}
        self._force: dict[str, list[float]] = {name: [] for name in elements}

    def story_stiffness(self, n_stories: int) -> FloatArray:
        """Initial stiffness added to each of ``n_stories`` stories by the elements (kN/mm)."""
        extra = np.zeros(n_stories)
        for name, placement in self.placements.items():
            if placement.story >= n_stories:
                raise ValueError(f"element {name!r} is in story {placement.story + 1} of a "
                                 f"{n_stories}-story frame")
            extra[placement.story] += placement.initial_stiffness()
        return extra

    def __call__(self, step: int, time: float, drift: FloatArray) -> FloatArray:
        """Each element's trial at its story's drift, in order (a source's learners get its
        measurement right after its trial); the summed force per story."""
        for timed in self._timed:
            timed.begin_step(step, time)
        forces = np.zeros(len(self.stories))
        for name, element, column in self._plan:
            d = float(drift[column])
            force, _ = element.set_trial(d)
            self._trial[name] = (d, force)
            forces[column] += force
            for learner in self._learners.get(name, ()):
                learner.measured(d, force)
        return forces

    def commit(self) -> None:
        """Commit every element (after the integrator committed the step); record the step."""
        for name, element, _ in self._plan:
            element.commit()
            d, force = self._trial[name]
            self._drift[name].append(d)
            self._force[name].append(force)

    def drift(self, name: str) -> FloatArray:
        """The element's committed drifts, one per committed step (step 0 first)."""
        return np.array(self._drift[name], dtype=np.float64)

    def force(self, name: str) -> FloatArray:
        """The element's committed forces (what its ``set_trial`` answered)."""
        return np.array(self._force[name], dtype=np.float64)


def _learners(placements: Mapping[str, Placement]) -> dict[str, list[LearningElement]]:
    """The learners of each source element, checked: the source exists, the learner can learn,
    and a same-step learner comes after its source (it is answered after the source's trial)."""
    order = list(placements)
    out: dict[str, list[LearningElement]] = {}
    for name, placement in placements.items():
        source = placement.learns_from
        if source is None:
            continue
        element = placement.element
        if source == name or source not in placements:
            raise ValueError(f"element {name!r} learns from {source!r}, which is not another "
                             f"element of the coupling ({', '.join(order)})")
        if not isinstance(element, LearningElement):
            raise TypeError(f"element {name!r} learns from {source!r} but has no "
                            "measured(d, force)/causality")
        if element.causality == "same-step" and order.index(source) > order.index(name):
            raise ValueError(f"element {name!r} learns same-step from {source!r}, which must "
                             "come before it (elements are tried in the order given)")
        out.setdefault(source, []).append(element)
    return out


class MeasuredElement:
    """A specimen read through a load cell: the force the structure gets, and the one a learner
    is handed, is the reading (true force, bias and the cell's seeded noise), one reading per
    trial. The true force stays the model's."""

    def __init__(self, model: HysteresisModel, load_cell: Sensor) -> None:
        self.model = model
        self.load_cell = load_cell

    @property
    def initial_tangent(self) -> float:
        return self.model.initial_tangent

    def set_trial(self, d: float) -> tuple[float, float]:
        force, tangent = self.model.set_trial(d)
        return self.load_cell.read(force), tangent

    def commit(self) -> None:
        self.model.commit()


class UpdatingTwin:
    """An updater's twin as a learning story element, with its causality explicit.

    ``same-step``: at the first trial after its source's measurement of step ``i``, the twin is
    probed (its one-step-ahead force), the updater observes step ``i``, then the twin answers.
    ``previous-step``: the twin answers from its state committed through step ``i - 1`` (that
    answer *is* its one-step-ahead force); at ``commit`` the twin commits, then the updater
    observes step ``i``. Either way each measurement is observed once. ``same-step`` assumes one
    trial per step (explicit Newmark): under Newton iterations it would learn from a trial.
    Keeps per committed step the one-step-ahead force and the updater's time.
    """

    def __init__(self, updater: Updater, causality: Causality = "same-step") -> None:
        if causality not in CAUSALITIES:
            raise ValueError(f"unknown causality {causality!r}; known: {', '.join(CAUSALITIES)}")
        self.updater = updater
        self._causality: Causality = causality
        self._pending: tuple[float, float] | None = None
        self._ahead: float | None = None
        self._ahead_history: list[float] = []
        self._seconds_history: list[float] = []

    @property
    def causality(self) -> Causality:
        return self._causality

    @property
    def initial_tangent(self) -> float:
        return self.updater.twin.initial_tangent

    def measured(self, d: float, force: float) -> None:
        """The source's measurement of this step (observed now or at commit: the causality)."""
        self._pending = (d, force)

    def set_trial(self, d: float) -> tuple[float, float]:
        twin = self.updater.twin
        if self._pending is not None and self._causality == "same-step":
            ahead, _ = twin.set_trial(d)
            self._learn()
            if self._ahead is None:
                self._ahead = ahead
        force, tangent = twin.set_trial(d)
        if self._ahead is None:
            self._ahead = force
        return force, tangent

    def commit(self) -> None:
        self.updater.twin.commit()
        self._learn()  # previous-step: step i now (same-step learned it at the trial)
        self._ahead_history.append(float("nan") if self._ahead is None else self._ahead)
        self._seconds_history.append(self.updater.last_update_seconds)
        self._ahead = None

    def _learn(self) -> None:
        """The updater observes the pending measurement, if any, once."""
        if self._pending is not None:
            d, force = self._pending
            self._pending = None
            self.updater.observe(d, force)

    def ahead_force(self) -> FloatArray:
        """The twin's force at each committed step before the updater saw that step."""
        return np.array(self._ahead_history, dtype=np.float64)

    def update_seconds(self) -> FloatArray:
        """The updater's time of each committed step's observation (0 for a fixed model)."""
        return np.array(self._seconds_history, dtype=np.float64)


def frame_integrator(
    frame: ShearBuilding,
    experimental_force: ExperimentalForce,
    stories: Sequence[int],
    story_stiffness: npt.ArrayLike,
    motion: GroundMotion,
    *,
    dt: float,
    zeta: float,
    rayleigh_modes: tuple[int, int] = (1, 2),
) -> ExplicitNewmark:
    """Explicit Newmark for ``frame`` with experimental elements in ``stories``.

    ``story_stiffness`` (one value per story of the frame, kN/mm) is the elements' initial
    stiffness: Rayleigh damping (``zeta`` on ``rayleigh_modes``) uses the frame with it, the
    linear stiffness is the frame alone (the elements' forces come from ``experimental_force``),
    and the stability check sees it too. ``motion`` is resampled to ``dt`` when needed.
    """
    extra = np.asarray(story_stiffness, dtype=np.float64)
    _, _, damping = frame.rayleigh(zeta, rayleigh_modes, extra_story_stiffness=extra)
    if motion.dt != dt:
        motion = motion.resampled(dt)
    return ExplicitNewmark(
        frame.mass_matrix(),
        damping,
        frame.stiffness_matrix(),
        dt,
        motion,
        experimental_force,
        tuple(stories),
        experimental_stiffness=[float(extra[s]) for s in stories],
    )


def coupled_integrator(
    frame: ShearBuilding,
    coupling: StoryCoupling,
    motion: GroundMotion,
    *,
    dt: float,
    zeta: float,
    rayleigh_modes: tuple[int, int] = (1, 2),
) -> ExplicitNewmark:
    """:func:`frame_integrator` with the coupling as the experimental force."""
    extra = coupling.story_stiffness(frame.n_stories)
    return frame_integrator(frame, coupling, coupling.stories, extra, motion, dt=dt, zeta=zeta,
                            rayleigh_modes=rayleigh_modes)


def run_coupled(
    integrator: ExplicitNewmark,
    coupling: StoryCoupling,
    *,
    steps: int | None = None,
    progress: Callable[[int, int], None] | None = None,
) -> Response:
    """Step 0 (the initial state) if not done yet, then ``steps`` more (default: to the end of
    the record), committing the elements after each integrator step. ``progress(done, total)``
    after each step. Returns the integrator's response."""
    if integrator.current_step < 0:
        integrator.step()
        coupling.commit()
    remaining = integrator.n_steps - integrator.current_step
    count = remaining if steps is None else steps
    if not 0 <= count <= remaining:
        raise ValueError(f"steps={steps} is outside 0..{remaining} (steps left in the record)")
    for done in range(1, count + 1):
        integrator.step()
        coupling.commit()
        if progress is not None:
            progress(done, count)
    return integrator.response()
