"""One case of the study: the two-story frame, the tested damper, its updatable twin.

In process, the built-in explicit Newmark integrator (no iteration: each step's trial drift is
imposed once, so the material semantics of the twin are exercised by the one-step-ahead probe
below, not by Newton). Per step ``i``, in this order:

1. the tested damper (story 1) is moved to its drift and committed; its measured force is the
   true force plus load-cell noise (one seeded stream per run: every case of a run sees the
   same noise, common random numbers);
2. the twin is *probed* at its drift before the updater sees step ``i`` (``set_trial`` only:
   the one-step-ahead prediction, never committed);
3. ``updater.observe(d_i, F_i)``; the twin's force at its drift is then computed and committed:
   that is what the structure gets, as in the paper, where the twin's step ``i`` uses what was
   learned from step ``i``;
4. a noise-free copy of the true law follows the twin's drift: the twin's true force.

The integrator gets the *measured* tested force (noise included) and the twin's prediction.
Actuator dynamics are left out on purpose, as the paper assumes ("a very small control error"):
the study isolates model error.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numpy as np
import numpy.typing as npt

from fresco_bridge.integrator import (
    DEMO_DT,
    DEMO_ZETA,
    ExplicitNewmark,
    GroundMotion,
    paper_two_story_frame,
)
from fresco_bridge.study.constants import MENEGOTTO_PINTO_DAMPER, SPECIMEN_PRESET
from fresco_bridge.updating.base import Updater
from sim_actuator.models import HysteresisModel, make_model

__all__ = ["CaseHistory", "simulate_case", "specimen_model", "specimen_params"]

FloatArray = npt.NDArray[np.float64]


def specimen_params(specimen: str) -> tuple[str, dict[str, float]]:
    """(model kind, parameters) of a study specimen: ``bwbn`` (the rig preset) or GMP."""
    if specimen == "bwbn":
        from sim_actuator.config import preset

        config = preset(SPECIMEN_PRESET).specimen
        return config.kind, dict(config.params)
    if specimen == "menegotto-pinto":
        return "menegotto-pinto", dict(MENEGOTTO_PINTO_DAMPER)
    raise ValueError(f"unknown specimen {specimen!r}; known: bwbn, menegotto-pinto")


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
) -> CaseHistory:
    """Run one case to the end of the record (or ``steps`` steps after step 0)."""
    if layout not in ("paper", "generalisation"):
        raise ValueError(f"unknown layout {layout!r}; known: paper, generalisation")
    tested = specimen_model(specimen)
    truth = specimen_model(specimen)
    k0 = tested.initial_tangent
    frame = paper_two_story_frame()
    paper = layout == "paper"
    extra = np.array([2.0 * k0, 0.0]) if paper else np.array([k0, k0])
    _, _, damping = frame.rayleigh(DEMO_ZETA, (1, 2), extra_story_stiffness=extra)
    rng = np.random.default_rng(noise_seed)
    twin = updater.twin
    rows: list[tuple[float, ...]] = []

    def forces(step: int, t: float, drift: FloatArray) -> list[float]:
        d_tested = float(drift[0])
        d_twin = d_tested if paper else float(drift[1])
        f_true, _ = tested.set_trial(d_tested)
        tested.commit()
        f_meas = f_true + noise_std * float(rng.standard_normal()) if noise_std else f_true
        f_ahead, _ = twin.set_trial(d_twin)
        updater.observe(d_tested, f_meas)
        f_twin, _ = twin.set_trial(d_twin)
        twin.commit()
        f_twin_true, _ = truth.set_trial(d_twin)
        truth.commit()
        rows.append((d_tested, f_meas, d_twin, f_twin, f_twin_true, f_ahead,
                     updater.last_update_seconds))  # fmt: skip
        return [f_meas + f_twin] if paper else [f_meas, f_twin]

    if motion.dt != DEMO_DT:
        motion = motion.resampled(DEMO_DT)
    integrator = ExplicitNewmark(
        frame.mass_matrix(),
        damping,
        frame.stiffness_matrix(),
        DEMO_DT,
        motion,
        forces,
        (0,) if paper else (0, 1),
        experimental_stiffness=[2.0 * k0] if paper else [k0, k0],
    )
    response = integrator.run(steps)
    table = np.array(rows, dtype=np.float64)
    return CaseHistory(
        tested_drift=table[:, 0],
        tested_force=table[:, 1],
        twin_drift=table[:, 2],
        twin_force=table[:, 3],
        twin_true_force=table[:, 4],
        twin_ahead_force=table[:, 5],
        update_seconds=table[:, 6],
        floor_displacement=response.displacement,
    )
