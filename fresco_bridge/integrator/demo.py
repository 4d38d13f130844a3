"""The demo structure: the source paper's two-story frame with a bending damper in story 1.

Source paper, section 3.2: a two-story, two-span steel frame (H = 2000 mm per story, columns and
beams HN 200x100) modelled as a shear building, 20222.8 kg per floor, classical Rayleigh damping
of 5 % in modes 1 and 2, explicit Newmark at dt = 0.01 s, ground motion scaled to a PGA of
300 cm/s^2. The left bending damper of story 1 is the experimental element. (The paper also has
an identical right damper, simulated as the updatable numerical substructure; a caller that
wants it adds its force to story 1 inside the experimental-force callable.)

The paper gives neither the frame stiffness nor usable damper values, so they are chosen here:

* Frame: 10 kN/mm per story. Three HN 200x100 columns (I = 1.84e7 mm^4, E = 206 kN/mm^2) give
  3 * 12 E I / H^3 = 17 kN/mm with rigid beams; flexible beams bring this to roughly 10.
  Frame alone: T1 = 0.457 s; with the damper's initial stiffness in story 1: T1 = 0.379 s,
  T2 = 0.157 s.
* Damper (bilinear, kinematic hardening): k0 = 8 kN/mm, fy = 12 kN, alpha = 0.05, so the yield
  displacement is fy / k0 = 1.5 mm. The paper's Table 1 (k0 = 68000 N/mm, Fy = 35000 N,
  alpha = 0.008) is the deliberately crude initial guess of its numerical model and does not
  fit its own measurements: the measured peak damper forces are 13.8-19.2 kN (Table 3), below
  that Fy, although the hysteresis loops show clear yielding. fy = 12 kN with 5 % hardening
  reaches 18-19 kN at the demo's peak drift, matching the measured peaks.
* Under ``kanai_tajimi(3.0, seed=0)`` (20 s, dt = 0.01 s) with the bilinear damper the peak
  story-1 drift is about 17.8 mm (about 12 yield displacements, 0.9 % of the story height), and
  explicit Newmark has dt * omega_max = 0.40 (critical dt 0.050 s, five times dt).
"""

from __future__ import annotations

from typing import Final

import numpy as np
import numpy.typing as npt

from fresco_bridge.integrator.coupling import (
    Placement,
    StoryCoupling,
    coupled_integrator,
    frame_integrator,
)
from fresco_bridge.integrator.ground_motion import GroundMotion, kanai_tajimi
from fresco_bridge.integrator.link import GenericClientLink, SiteElement
from fresco_bridge.integrator.newmark import ExperimentalForce, ExplicitNewmark
from fresco_bridge.integrator.shear_building import ShearBuilding

__all__ = [
    "DEMO_DAMPER",
    "DEMO_DT",
    "DEMO_EXPERIMENTAL_STORIES",
    "DEMO_FLOOR_MASS",
    "DEMO_FRAME_STORY_STIFFNESS",
    "DEMO_PGA_M_S2",
    "DEMO_ZETA",
    "demo_damper_story_stiffness",
    "demo_frame_integrator",
    "demo_ground_motion",
    "demo_integrator",
    "demo_site_coupling",
    "paper_two_story_frame",
]

DEMO_FLOOR_MASS: Final = 0.0202228
"""kN*s^2/mm per floor (20222.8 kg, source paper section 3.2.1)."""
DEMO_FRAME_STORY_STIFFNESS: Final = 10.0
"""kN/mm per story, frame only (chosen; see the module docstring)."""
_DAMPER_K0: Final = 8.0
_DAMPER_FY: Final = 12.0
_DAMPER_ALPHA: Final = 0.05
DEMO_DAMPER: Final[dict[str, str | float]] = {
    "model": "bilinear",
    "k0": _DAMPER_K0,
    "fy": _DAMPER_FY,
    "alpha": _DAMPER_ALPHA,
}
"""Experimental bending damper of story 1: k0 in kN/mm, fy in kN, alpha = post-yield/k0 ratio.
Chosen to match the paper's measured damper forces, not its Table 1 (see the module docstring)."""
DEMO_EXPERIMENTAL_STORIES: Final = (0,)
"""0-based story indices of the experimental elements: the damper in story 1."""
DEMO_DT: Final = 0.01
DEMO_PGA_M_S2: Final = 3.0
DEMO_ZETA: Final = 0.05


def paper_two_story_frame() -> ShearBuilding:
    """The bare frame (no damper) of the source paper's demo, in mm, kN, s."""
    return ShearBuilding(
        masses=np.array([DEMO_FLOOR_MASS, DEMO_FLOOR_MASS]),
        story_stiffness=np.array([DEMO_FRAME_STORY_STIFFNESS, DEMO_FRAME_STORY_STIFFNESS]),
    )


def demo_damper_story_stiffness() -> npt.NDArray[np.float64]:
    """The damper's initial stiffness per story (kN/mm), as ``extra_story_stiffness``."""
    extra = np.zeros(2)
    extra[list(DEMO_EXPERIMENTAL_STORIES)] = _DAMPER_K0
    return extra


def demo_ground_motion(seed: int = 0) -> GroundMotion:
    """Stand-in for the paper's (unavailable) Simi Valley record: Kanai-Tajimi at PGA 3 m/s^2."""
    return kanai_tajimi(DEMO_PGA_M_S2, duration=20.0, dt=DEMO_DT, seed=seed)


def demo_integrator(
    experimental_force: ExperimentalForce, ground_motion: GroundMotion | None = None
) -> ExplicitNewmark:
    """Explicit Newmark for the demo frame with the damper of story 1 as experimental element.

    Rayleigh damping uses the initial stiffness including the damper's k0; the linear part
    ``K_lin`` is the frame alone, as the damper's force comes from ``experimental_force``.
    """
    record = ground_motion if ground_motion is not None else demo_ground_motion()
    return frame_integrator(paper_two_story_frame(), experimental_force,
                            DEMO_EXPERIMENTAL_STORIES, demo_damper_story_stiffness(), record,
                            dt=DEMO_DT, zeta=DEMO_ZETA)


def demo_frame_integrator(
    coupling: StoryCoupling, ground_motion: GroundMotion | None = None
) -> ExplicitNewmark:
    """Explicit Newmark for the demo frame with the coupling's elements in their stories
    (Rayleigh damping with their initial stiffness); drive it with ``run_coupled``."""
    record = ground_motion if ground_motion is not None else demo_ground_motion()
    return coupled_integrator(paper_two_story_frame(), coupling, record, dt=DEMO_DT,
                              zeta=DEMO_ZETA)


def demo_site_coupling(link: GenericClientLink) -> StoryCoupling:
    """The demo's coupling: the bridge's ``damper`` site (2 DOFs, ``OneActuator``) in story 1,
    reached over ``link``; the committed histories are ``coupling.drift/force("damper")``."""
    return StoryCoupling({"damper": Placement(0, SiteElement(link, stiffness=_DAMPER_K0))})
