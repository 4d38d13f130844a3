"""``study paper --integrator opensees``: the study's cases run from real OpenSeesPy, both dampers
served by a bridge, agree with the in-process study (issue 28's agreement targets)."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from fresco_bridge import indicators
from fresco_bridge.cli import main
from fresco_bridge.integrator import DEMO_DT, Causality, kanai_tajimi
from fresco_bridge.lawfit import law_forces
from fresco_bridge.study.opensees import simulate_case_opensees
from fresco_bridge.study.paper import (
    Prepared,
    RunSpec,
    _prepare,
    make_case_twin_site,
    make_case_updater,
)
from fresco_bridge.study.simulate import CaseHistory, simulate_case, specimen_model

pytest.importorskip("openseespy")

MOTION = kanai_tajimi(3.0, duration=20.0, dt=DEMO_DT, seed=1)
STEPS = 300


@pytest.fixture(scope="module")
def prepared() -> Prepared:
    return _prepare((RunSpec("synthetic-seed1", MOTION, "bwbn", 0.0, 1, STEPS),
                     ("reference", "online_improved")))


def both(case: str, layout: str, prepared: Prepared,
         causality: Causality) -> tuple[CaseHistory, CaseHistory]:
    """(in-process, OpenSees-driven) histories of one case."""
    builtin = simulate_case(layout, "bwbn", make_case_updater(case, prepared), MOTION,
                            steps=STEPS, causality=causality)
    served = simulate_case_opensees(layout, "bwbn", make_case_twin_site(case, prepared), MOTION,
                                    steps=STEPS, causality=causality,
                                    ahead_updater=make_case_updater(case, prepared))
    return builtin, served


def rel(a: np.ndarray, b: np.ndarray) -> float:
    return float(np.max(np.abs(a - b)) / np.max(np.abs(b)))


def test_reference_twin_in_opensees_equals_the_in_process_frame(prepared: Prepared) -> None:
    """updater none with the true law, paper layout (both dampers in story 1): OpenSees'
    frame is the study's, to 1e-9."""
    builtin, served = both("reference", "paper", prepared, "same-step")
    assert served.floor_displacement.shape == builtin.floor_displacement.shape == (STEPS + 1, 2)
    assert np.max(np.abs(builtin.tested_drift)) > 1.5  # the damper yields (fy / k0 = 1.5 mm)
    assert rel(served.floor_displacement, builtin.floor_displacement) < 1e-9
    assert rel(served.twin_force, builtin.twin_force) < 1e-9
    assert rel(served.tested_force, builtin.tested_force) < 1e-9


@pytest.mark.parametrize("causality", ["same-step", "previous-step"])
def test_online_improved_served_agrees_with_the_in_process_study(
        prepared: Prepared, causality: Causality) -> None:
    """Generalisation layout (twin in story 2): MAETH within 5 %, the twin's force history
    within 2 % NRMS, the one-step-ahead force the same."""
    builtin, served = both("online_improved", "generalisation", prepared, causality)
    maeth_in = indicators.maeth(builtin.twin_true_force, builtin.twin_force)
    maeth_os = indicators.maeth(served.twin_true_force, served.twin_force)
    assert maeth_in > 0.0  # the twin has something to learn
    assert abs(maeth_os - maeth_in) / maeth_in < 0.05
    diff = served.twin_force - builtin.twin_force
    nrms = float(np.sqrt(np.mean(diff**2)) / np.sqrt(np.mean(builtin.twin_force**2)))
    assert nrms < 0.02
    assert rel(served.twin_ahead_force, builtin.twin_ahead_force) < 0.02


def test_noise_is_the_tested_sites_seeded_load_cell(prepared: Prepared) -> None:
    """``--noise``: the sim site reads the true law through a seeded load cell (std as asked,
    zero mean, the same readings for the same seed), the twin's fixed law unaffected."""
    def run(seed: int) -> CaseHistory:
        return simulate_case_opensees("generalisation", "bwbn",
                                      make_case_twin_site("reference", prepared), MOTION,
                                      steps=STEPS, causality="previous-step", noise_std=0.05,
                                      noise_seed=seed)

    served = run(3)
    true = law_forces(specimen_model("bwbn"), served.tested_drift)
    residual = served.tested_force[1:] - true[1:]
    assert 0.04 < float(np.std(residual)) < 0.06 and abs(float(np.mean(residual))) < 0.015
    assert np.array_equal(run(3).tested_force, served.tested_force)
    assert rel(served.twin_force, law_forces(specimen_model("bwbn"), served.twin_drift)) < 1e-9


def test_cli_records_the_integrator_and_the_noise(tmp_path: Path) -> None:
    assert main(["study", "paper", "--integrator", "opensees", "--cases", "reference",
                 "--steps", "40", "--workers", "1", "--noise", "1", "--no-plots",
                 "-o", str(tmp_path)]) == 0
    document = json.loads(next(tmp_path.glob("*_opensees/study.json")).read_text())
    assert document["integrator"] == "opensees" and document["steps"] == 41
    assert document["noise_pct"] == 1.0 and document["noise_std_kN"] > 0.0
