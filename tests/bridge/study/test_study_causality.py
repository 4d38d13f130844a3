"""The study's causality: ``same-step`` is the paper's loop to the last bit, ``previous-step`` the
lagged one; both reach study.json, the tables and the run directories."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from fresco_bridge.cli import main
from fresco_bridge.integrator import (
    DEMO_DT,
    DEMO_ZETA,
    Causality,
    ExplicitNewmark,
    kanai_tajimi,
    paper_two_story_frame,
)
from fresco_bridge.study.simulate import CaseHistory, simulate_case, specimen_model
from fresco_bridge.updating import make_updater

MOTION = kanai_tajimi(3.0, duration=2.0, dt=DEMO_DT, seed=2)
NOISE_STD, NOISE_SEED, STEPS = 0.1, 2, 150
FIELDS = ("tested_drift", "tested_force", "twin_drift", "twin_force", "twin_true_force",
          "twin_ahead_force", "floor_displacement")  # fmt: skip


def documented_loop(layout: str, causality: Causality) -> dict[str, np.ndarray]:
    """The study's order written out in one Newmark callback (the tested damper measured and
    committed first, then the twin), as the study ran before it went through the coupling."""
    tested, truth = specimen_model("bwbn"), specimen_model("bwbn")
    updater = make_updater("online_ukf")
    twin, k0, paper = updater.twin, tested.initial_tangent, layout == "paper"
    rng = np.random.default_rng(NOISE_SEED)
    rows: list[tuple[float, ...]] = []

    def forces(step: int, t: float, drift: np.ndarray) -> list[float]:
        d_tested = float(drift[0])
        d_twin = d_tested if paper else float(drift[1])
        f_true, _ = tested.set_trial(d_tested)
        tested.commit()
        f_meas = f_true + NOISE_STD * float(rng.standard_normal())
        if causality == "same-step":  # learn step i, then answer step i
            f_ahead, _ = twin.set_trial(d_twin)
            updater.observe(d_tested, f_meas)
            f_twin, _ = twin.set_trial(d_twin)
            twin.commit()
        else:  # answer step i from what was learned through i - 1, then learn step i
            f_twin, _ = twin.set_trial(d_twin)
            f_ahead = f_twin
            twin.commit()
            updater.observe(d_tested, f_meas)
        f_twin_true, _ = truth.set_trial(d_twin)
        truth.commit()
        rows.append((d_tested, f_meas, d_twin, f_twin, f_twin_true, f_ahead))
        return [f_meas + f_twin] if paper else [f_meas, f_twin]

    frame = paper_two_story_frame()
    extra = np.array([2.0 * k0, 0.0]) if paper else np.array([k0, k0])
    _, _, damping = frame.rayleigh(DEMO_ZETA, (1, 2), extra_story_stiffness=extra)
    integrator = ExplicitNewmark(frame.mass_matrix(), damping, frame.stiffness_matrix(), DEMO_DT,
                                 MOTION, forces, (0,) if paper else (0, 1),
                                 experimental_stiffness=[2.0 * k0] if paper else [k0, k0])
    response = integrator.run(STEPS)
    table = np.array(rows)
    return {**dict(zip(FIELDS[:-1], table.T, strict=True)),
            "floor_displacement": response.displacement}


def _simulated(layout: str, causality: Causality) -> CaseHistory:
    return simulate_case(layout, "bwbn", make_updater("online_ukf"), MOTION, noise_std=NOISE_STD,
                         noise_seed=NOISE_SEED, steps=STEPS, causality=causality)


@pytest.mark.parametrize("layout", ["paper", "generalisation"])
@pytest.mark.parametrize("causality", ["same-step", "previous-step"])
def test_the_study_through_the_coupling_is_the_documented_loop_bit_for_bit(
    layout: str, causality: Causality
) -> None:
    expected = documented_loop(layout, causality)
    got = _simulated(layout, causality)
    for name in FIELDS:
        assert np.array_equal(getattr(got, name), expected[name]), name


def test_under_previous_step_the_twins_answer_is_its_one_step_ahead_force() -> None:
    same = _simulated("generalisation", "same-step")
    lagged = _simulated("generalisation", "previous-step")
    assert np.array_equal(lagged.twin_ahead_force, lagged.twin_force)
    assert not np.array_equal(same.twin_ahead_force, same.twin_force)
    assert not np.array_equal(same.twin_force, lagged.twin_force)


def test_study_paper_runs_each_causality_asked_and_records_it(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    code = main(["study", "paper", "--causality", "previous-step", "--causality", "same-step",
                 "--steps", "40", "--cases", "conventional_calibrated,online_ukf", "--no-plots",
                 "--workers", "1", "-o", str(tmp_path)])  # fmt: skip
    assert code == 0
    runs = {p.name: json.loads((p / "study.json").read_text())
            for p in tmp_path.iterdir() if p.is_dir()}  # fmt: skip
    label = "synthetic-seed1_bwbn_noise0_seed1"
    assert set(runs) == {label, f"{label}_previous-step"}
    assert runs[label]["causality"] == "same-step"
    lagged = runs[f"{label}_previous-step"]
    assert lagged["causality"] == "previous-step"
    summary = json.loads((tmp_path / "summary.json").read_text())
    assert [doc["causality"] for doc in summary["runs"]] == ["previous-step", "same-step"]
    for layout in ("paper", "generalisation"):
        same = runs[label]["layouts"][layout]["cases"]
        late = lagged["layouts"][layout]["cases"]
        assert same["conventional_calibrated"] == late["conventional_calibrated"]  # learns nothing
        assert same["online_ukf"]["maeth"] != late["online_ukf"]["maeth"]
    table = (tmp_path / f"{label}_previous-step" / "table.md").read_text()
    assert "causality previous-step (the twin's step i knew the tested damper through" in table
    rows = (tmp_path / "summary.md").read_text()
    assert "| seed | causality |" in rows
    assert "| 1 | previous-step |" in rows and "| 1 | same-step |" in rows


def test_an_unknown_causality_is_exit_2(capsys: pytest.CaptureFixture[str]) -> None:
    with pytest.raises(SystemExit) as exit_info:
        main(["study", "paper", "--causality", "late"])
    assert exit_info.value.code == 2
    assert "--causality" in capsys.readouterr().err
