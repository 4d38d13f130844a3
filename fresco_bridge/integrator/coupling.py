"""The one home of the integrator coupling loop: the built-in explicit Newmark driving story
elements of a shear frame (the demo, ``lab integrate``, the paper study, the benchmarks).

A *story element* is anything with OpenSees material semantics for one story drift:
``set_trial(drift) -> (force, tangent)`` from its last commit, and ``commit()``. A hysteresis
model of ``sim_actuator.models`` is one, so is an updater's twin, and so is a bridge site over
the genericClient protocol (:class:`~fresco_bridge.integrator.link.SiteElement`). Several
elements may share a story: their forces add up (the paper layout's tested damper and its twin
side by side).

Per step, explicit Newmark knows the trial drifts before any force: each element gets its
``set_trial`` once, in the order the elements were given (so a caller can make the twin's trial
see what the tested element just measured, through ``after_trial``), the integrator commits with
the summed story forces, then every element is committed in the same order.

    coupling = StoryCoupling({"tested": Placement(0, tested), "twin": Placement(1, twin)})
    integrator = coupled_integrator(paper_two_story_frame(), coupling, motion)
    response = run_coupled(integrator, coupling, progress=ProgressBar("steps", integrator.n_steps))
    coupling.drift("twin"), coupling.force("twin")      # committed histories, step 0 first
"""

from __future__ import annotations

from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass
from typing import Protocol, runtime_checkable

import numpy as np
import numpy.typing as npt

from fresco_bridge.integrator.ground_motion import GroundMotion
from fresco_bridge.integrator.newmark import ExperimentalForce, ExplicitNewmark, Response
from fresco_bridge.integrator.shear_building import ShearBuilding

__all__ = [
    "Placement",
    "StoryCoupling",
    "StoryElement",
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


@dataclass(frozen=True)
class Placement:
    """Where an element acts: ``story`` (0-based: story 0 joins the ground and floor 1) and the
    initial stiffness estimate the integrator uses for Rayleigh damping and its stability check
    (default: the element's ``initial_tangent`` when it has one, else 0)."""

    story: int
    element: StoryElement
    stiffness: float | None = None

    def initial_stiffness(self) -> float:
        if self.stiffness is not None:
            return float(self.stiffness)
        return float(getattr(self.element, "initial_tangent", 0.0))


class StoryCoupling:
    """The experimental force of :class:`ExplicitNewmark` for named elements placed in stories;
    commits them after each integrator commit and keeps their committed histories."""

    def __init__(
        self,
        elements: Mapping[str, Placement],
        *,
        after_trial: Callable[[str, float, float], None] | None = None,
    ) -> None:
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
        self._after_trial = after_trial
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
        """Each element's trial at its story's drift, in order; the summed force per story."""
        for timed in self._timed:
            timed.begin_step(step, time)
        forces = np.zeros(len(self.stories))
        for name, element, column in self._plan:
            d = float(drift[column])
            force, _ = element.set_trial(d)
            self._trial[name] = (d, force)
            forces[column] += force
            if self._after_trial is not None:
                self._after_trial(name, d, force)
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
