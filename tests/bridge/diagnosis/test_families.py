"""Each baseline family is recovered from its own synthetic record, and auto chooses it.

A record of the family's own law (no effect, 0.5 % load-cell noise) must come back with its
parameters within the stated tolerance, the baseline's withheld gap at the noise-only gap, and
the verdict ``none``.
"""

from __future__ import annotations

import numpy as np
import pytest

from benchmarks.diagnosis.synth import command_history
from fresco_bridge.diagnosis.load import Record, record_from_arrays
from fresco_bridge.diagnosis.model import Context, law_parameters, law_vector
from fresco_bridge.diagnosis.names import AUTO_FAMILIES, BASELINES
from fresco_bridge.diagnosis.verdict import Options, diagnose
from sim_actuator.models import MODEL_KINDS
from sim_actuator.models.paths import drive

TOLERANCE = 0.05
"""Relative tolerance on every law parameter (R0, whose effect on the curve is weak once it is
sharp, and the excursion scales get :data:`LOOSE`)."""
LOOSE = {"R0": 0.15, "cR2": 0.15, "p_sat": 0.15}
FAMILIES = {
    "isotropic-bilinear": {"k0": 10.0, "fy": 20.0, "alpha": 0.01, "q_iso": 0.8, "p_sat": 15.0},
    "steel02": {"k0": 10.0, "fy": 20.0, "alpha": 0.02, "R0": 18.0, "cR1": 0.9, "cR2": 0.15,
                "a1": 0.05, "a3": 0.05},
    "menegotto-pinto": {"k0": 10.0, "fy": 20.0, "alpha": 0.02, "R0": 12.0, "cR1": 0.85,
                        "cR2": 0.1},
}


def _record(kind: str, law: dict[str, float], seed: int = 5) -> Record:
    rng = np.random.default_rng(seed)
    cmd = command_history(rng, 1500, 0.01, 5.0 * law.get("fy", 20.0) / law.get("k0", 10.0))
    force = drive(*law_vector(kind, law), cmd, 0.0, 0.2)
    force = force + rng.normal(0.0, 0.005 * float(np.max(np.abs(force))), force.size)
    time = np.arange(cmd.size, dtype=np.float64) * 0.01
    return record_from_arrays(time, cmd, force, source=kind)


@pytest.mark.parametrize("kind", list(FAMILIES))
def test_each_family_is_recovered_from_its_own_record(kind: str) -> None:
    law = FAMILIES[kind]
    result = diagnose(_record(kind, law), Options(pairs=False,
                                                  effects=("backlash", "friction"))).to_json()
    assert result["baseline"]["kind"] == kind, result["baseline"]["selection"]["reason"]
    fitted = result["baseline"]["params"]
    for name, truth in law.items():
        assert fitted[name] == pytest.approx(truth, rel=LOOSE.get(name, TOLERANCE)), name
    gap = result["baseline"]["gap_withheld"]["total_pct"]
    assert gap == pytest.approx(result["noise_floor"]["noise_only_gap_pct"], rel=0.1)
    assert result["verdict"]["effect"] == "none"


def test_every_registry_kind_and_every_auto_family_is_a_baseline() -> None:
    assert set(MODEL_KINDS) <= set(BASELINES)
    assert set(AUTO_FAMILIES) <= set(BASELINES)
    ctx = Context.of(_record("bilinear", {"k0": 10.0, "fy": 20.0, "alpha": 0.02}))
    assert set(law_parameters(ctx)) == set(BASELINES)


def test_an_elastic_spring_under_the_elastic_baseline() -> None:
    result = diagnose(_record("elastic", {"k": 4.0}), Options(
        baseline="elastic", pairs=False, effects=("friction",))).to_json()
    assert result["baseline"]["params"]["k"] == pytest.approx(4.0, rel=1e-3)
    gap = result["baseline"]["gap_withheld"]["total_pct"]
    assert gap == pytest.approx(result["noise_floor"]["noise_only_gap_pct"], rel=0.1)
