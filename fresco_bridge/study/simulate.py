"""One case of the study: the two-story frame, the tested damper, its updatable twin.

The case runs through the one coupling loop (``fresco_bridge.integrator.coupling``): the built-in
explicit Newmark (no iteration: each step's trial drift is imposed once, so the material
semantics of the twin are exercised by the one-step-ahead probe, not by Newton) with two story
elements, in this order:

* ``tested`` (story 1): the specimen's true law read through a load cell, the true force plus
  seeded noise (one stream per run: every case of a run sees the same noise, common random
  numbers); the structure gets the reading and the updater observes it;
* ``twin`` (story 1 in the paper layout, story 2 in the generalisation layout): the updater's
  twin, learning from ``tested`` with the run's ``causality``. ``same-step`` (the default, the
  paper's order: the twin's step ``i`` uses what was learned from step ``i``) or
  ``previous-step`` (the twin's step ``i`` knows the tested damper only through step ``i - 1``,
  what a twin served live under OpenSees can always honour). A study copied onto a served twin
  must say which it reproduces.

The one-step-ahead force is the twin's answer before the updater saw step ``i`` (under
``previous-step``, the twin's answer itself). Afterwards a noise-free copy of the true law is
driven along the twin's drifts: the twin's true force. Actuator dynamics are left out on
purpose, as the paper assumes ("a very small control error"): the study isolates model error.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numpy as np
import numpy.typing as npt

from fresco_bridge.integrator import (
    DEMO_DT,
    DEMO_ZETA,
    Causality,
    GroundMotion,
    MeasuredElement,
    Placement,
    StoryCoupling,
    UpdatingTwin,
    coupled_integrator,
    paper_two_story_frame,
    run_coupled,
)
from fresco_bridge.lawfit import law_forces
from fresco_bridge.study.constants import (
    IN_FAMILY_SPECIMENS,
    MENEGOTTO_PINTO_DAMPER,
    SPECIMEN_PRESET,
    SPECIMENS,
)
from fresco_bridge.updating.base import Updater
from sim_actuator.effects import Sensor
from sim_actuator.models import HysteresisModel, make_model

__all__ = ["CaseHistory", "simulate_case", "specimen_model", "specimen_params"]

FloatArray = npt.NDArray[np.float64]


def specimen_params(specimen: str) -> tuple[str, dict[str, float]]:
    """(model kind, parameters) of a study specimen: ``bwbn`` (the rig preset), GMP, or an
    in-family law (``constants.IN_FAMILY_SPECIMENS``)."""
    if specimen == "bwbn":
        from sim_actuator.config import preset

        config = preset(SPECIMEN_PRESET).specimen
        return config.kind, dict(config.params)
    if specimen == "menegotto-pinto":
        return "menegotto-pinto", dict(MENEGOTTO_PINTO_DAMPER)
    if specimen in IN_FAMILY_SPECIMENS:
        kind, params = IN_FAMILY_SPECIMENS[specimen]
        return kind, dict(params)
    raise ValueError(f"unknown specimen {specimen!r}; known: {', '.join(SPECIMENS)}")


def specimen_model(specimen: str) -> HysteresisModel:
    """A virgin instance of the specimen's true law."""
    kind, params = specimen_params(specimen)
    return make_model(kind, **params)


@dataclass(frozen=True, eq=False)
class CaseHistory:
    """Histories of one case, one row per committed step (step 0 included)."""

    tested_drift: FloatArray
    tested_force: FloatArray
    """Measured (noisy) force of the tested damper, the updater's input."""
    twin_drift: FloatArray
    twin_force: FloatArray
    """The twin's committed prediction (what the structure got)."""
    twin_true_force: FloatArray
    """The true law under the twin's drift (known in simulation only)."""
    twin_ahead_force: FloatArray
    """The twin's prediction before the updater saw the step (one-step-ahead)."""
    update_seconds: FloatArray
    floor_displacement: FloatArray
    """(steps, 2): floor displacements relative to the ground."""
    extra: dict[str, Any] = field(default_factory=dict)


def simulate_case(
    layout: str,
    specimen: str,
    updater: Updater,
    motion: GroundMotion,
    *,
    noise_std: float = 0.0,
    noise_seed: int = 0,
    steps: int | None = None,
    causality: Causality = "same-step",
) -> CaseHistory:
    """Run one case to the end of the record (or ``steps`` steps after step 0)."""
    if layout not in ("paper", "generalisation"):
        raise ValueError(f"unknown layout {layout!r}; known: paper, generalisation")
    model = specimen_model(specimen)
    k0 = model.initial_tangent
    load_cell = Sensor(noise_std=noise_std, rng=np.random.default_rng(noise_seed))
    twin = UpdatingTwin(updater, causality)
    coupling = StoryCoupling({
        "tested": Placement(0, MeasuredElement(model, load_cell)),
        "twin": Placement(0 if layout == "paper" else 1, twin, stiffness=k0,
                          learns_from="tested"),
    })  # fmt: skip
    integrator = coupled_integrator(paper_two_story_frame(), coupling, motion, dt=DEMO_DT,
                                    zeta=DEMO_ZETA)  # fmt: skip
    response = run_coupled(integrator, coupling, steps=steps)
    twin_drift = coupling.drift("twin")
    return CaseHistory(
        tested_drift=coupling.drift("tested"),
        tested_force=coupling.force("tested"),
        twin_drift=twin_drift,
        twin_force=coupling.force("twin"),
        twin_true_force=law_forces(specimen_model(specimen), twin_drift),
        twin_ahead_force=twin.ahead_force(),
        update_seconds=twin.update_seconds(),
        floor_displacement=response.displacement,
    )
