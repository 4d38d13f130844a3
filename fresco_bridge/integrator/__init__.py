"""Built-in pseudo-dynamic integrator: ground motions, shear building, explicit Newmark.

Pure numerics (no I/O besides reading record files and the genericClient ``link``): story
elements (hysteresis models, updater twins, bridge sites) are coupled to the frame in one place,
``coupling.py`` (``StoryCoupling``, ``coupled_integrator``, ``run_coupled``).
"""

from fresco_bridge.integrator.coupling import (
    Placement,
    StoryCoupling,
    StoryElement,
    coupled_integrator,
    frame_integrator,
    run_coupled,
)
from fresco_bridge.integrator.demo import (
    DEMO_DAMPER,
    DEMO_DT,
    DEMO_EXPERIMENTAL_STORIES,
    DEMO_FLOOR_MASS,
    DEMO_FRAME_STORY_STIFFNESS,
    DEMO_PGA_M_S2,
    DEMO_ZETA,
    demo_damper_story_stiffness,
    demo_frame_integrator,
    demo_ground_motion,
    demo_integrator,
    demo_site_coupling,
    paper_two_story_frame,
)
from fresco_bridge.integrator.ground_motion import (
    G_M_S2,
    G_MM_S2,
    GroundMotion,
    GroundMotionFormatError,
    JenningsEnvelope,
    kanai_tajimi,
    read_ground_motion,
    read_peer_at2,
)
from fresco_bridge.integrator.newmark import (
    EnergyBalance,
    ExperimentalForce,
    ExplicitNewmark,
    IntegrationError,
    Response,
    StepState,
    TrialStep,
    UnstableTimeStepError,
)
from fresco_bridge.integrator.shear_building import (
    Modes,
    ShearBuilding,
    drift_matrix,
    generalized_eigen,
)

__all__ = [
    "DEMO_DAMPER",
    "DEMO_DT",
    "DEMO_EXPERIMENTAL_STORIES",
    "DEMO_FLOOR_MASS",
    "DEMO_FRAME_STORY_STIFFNESS",
    "DEMO_PGA_M_S2",
    "DEMO_ZETA",
    "G_MM_S2",
    "G_M_S2",
    "EnergyBalance",
    "ExperimentalForce",
    "ExplicitNewmark",
    "GroundMotion",
    "GroundMotionFormatError",
    "IntegrationError",
    "JenningsEnvelope",
    "Modes",
    "Placement",
    "Response",
    "ShearBuilding",
    "StepState",
    "StoryCoupling",
    "StoryElement",
    "TrialStep",
    "UnstableTimeStepError",
    "coupled_integrator",
    "demo_damper_story_stiffness",
    "demo_frame_integrator",
    "demo_ground_motion",
    "demo_integrator",
    "demo_site_coupling",
    "drift_matrix",
    "frame_integrator",
    "generalized_eigen",
    "kanai_tajimi",
    "paper_two_story_frame",
    "read_ground_motion",
    "read_peer_at2",
    "run_coupled",
]
