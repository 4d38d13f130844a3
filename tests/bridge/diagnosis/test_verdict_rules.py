"""The verdict's rules on records made to test one each: undershoot's form, family changes,
flags that say when a number is not measured, and a quiet tail.

Records come from ``sim_actuator``'s rig (``diagnosis.synth``), diagnosed blind.
"""

from __future__ import annotations

from typing import Any

import numpy as np
import pytest

from benchmarks.diagnosis.synth import command_history, rig_record, run_rig, synthetic_record
from fresco_bridge.diagnosis.model import reference
from fresco_bridge.diagnosis.options import Policy
from fresco_bridge.diagnosis.outputs import summary
from fresco_bridge.diagnosis.verdict import Options, diagnose, stop_of

DT = 0.01
SPECIMEN = {"k0": 10.0, "fy": 25.0, "alpha": 0.05, "n": 2.0, "beta": 0.6, "gamma": 0.4}


def _rig(actuator: dict[str, Any], cmd: np.ndarray, *, kind: str = "bouc-wen",
         specimen: dict[str, float] | None = None, noise: bool = True) -> Any:
    sensors = {"lvdt": {"noise_std": 0.003 if noise else 0.0},
               "load_cell": {"noise_std": 0.05 if noise else 0.0}}
    return run_rig({"name": "rules", "seed": 3, "specimen": {
        "kind": kind, "params": specimen or SPECIMEN},
        "actuator": {"stroke": 200.0, "force_capacity": 1e6, **actuator},
        "effects": {}, "sensors": sensors}, cmd, DT, "rules")


def test_the_undershoot_candidate_has_the_rigs_form_exactly() -> None:
    cmd = command_history(np.random.default_rng(4), 400, DT, 10.0)
    cmd[200:205] = cmd[200]  # a hold: the direction of the last move is kept
    record = _rig({"undershoot": 0.4, "amplitude": 1.05}, cmd, noise=False)
    piston = reference(cmd, {"undershoot": 0.4, "amplitude_error": 0.05})
    assert record.meas_disp is not None
    np.testing.assert_allclose(record.meas_disp[1:], piston[1:], atol=1e-9)


def test_undershoot_is_named_and_sized_on_a_synthetic_record() -> None:
    synthetic = synthetic_record("actuator_undershoot", 20261127, steps=1200)
    result = diagnose(synthetic.record).to_json()
    assert result["verdict"]["effect"] == "actuator_undershoot", result["verdict"]
    found = next(e for e in result["effects"] if e["name"] == "actuator_undershoot")
    assert found["params"]["undershoot"]["value"] == pytest.approx(
        synthetic.truth["undershoot"], rel=0.05)


def test_a_family_change_is_a_baseline_misfit_naming_the_family_not_an_effect() -> None:
    steel = {"k0": 20.0, "fy": 30.0, "alpha": 0.04, "R0": 8.0}
    cmd = command_history(np.random.default_rng(8), 1200, DT, 6.0 * steel["fy"] / steel["k0"])
    synthetic = rig_record("rules", "none", 8, "menegotto-pinto", steel,
                           {"stroke": 200.0, "force_capacity": 1e6}, {},
                           {"lvdt": {"noise_std": 0.002}, "load_cell": {"noise_std": 0.06}},
                           {}, cmd, DT)
    diagnosis = diagnose(synthetic.record, Options(baseline="bilinear"))
    result = diagnosis.to_json()
    verdict = result["verdict"]
    assert verdict["effect"] == "baseline_misfit", verdict
    assert verdict["better_family"] == "menegotto-pinto", verdict
    # the candidates that drive another law are measured from that family's best baseline and
    # never list its shape parameters as their own
    pinching = next(e for e in result["effects"] if e["name"] == "pinching")
    assert pinching["compared_with"] == "bouc-wen baseline"
    assert not {"n", "bg_sum", "beta_share"} & set(pinching["params"])
    assert "try --baseline menegotto-pinto" in summary(diagnosis)


def test_a_parameter_at_its_bound_is_flagged_and_lowers_the_confidence() -> None:
    cmd = command_history(np.random.default_rng(5), 900, DT, 8.0)
    record = _rig({"amplitude": 1.8}, cmd)  # 80 % gain error: beyond the candidate's 50 %
    # a systematic rival: the white noise is no rival of an effect (it is removed from the gap)
    diagnosis = diagnose(record, Options(effects=("actuator_amplitude", "actuator_delay",
                                                  "sensor_noise"), pairs=False))
    result = diagnosis.to_json()
    verdict = result["verdict"]
    assert verdict["effect"] == "actuator_amplitude", verdict
    assert "upper bound" in verdict["flags"]["amplitude_error"]
    amplitude = next(e for e in result["effects"] if e["name"] == "actuator_amplitude")
    assert "upper bound" in amplitude["params"]["amplitude_error"]["flag"]
    assert verdict["confidence"] <= Policy().flag_factor
    text = summary(diagnosis)
    assert "UNSURE: at its upper bound" in text and "does not measure amplitude_error" in text


def rms(x: np.ndarray) -> float:
    return float(np.sqrt(np.mean(x * x)))


def test_a_quiet_tail_neither_fills_the_withheld_part_nor_inflates_the_gap() -> None:
    n = 2500
    steps = np.arange(n)
    envelope = np.where(steps < 1200, 1.0, np.maximum(np.exp(-(steps - 1200) / 150.0), 0.02))
    cmd = command_history(np.random.default_rng(7), n, DT, 10.0) * envelope  # a coda
    record = _rig({}, cmd)  # no effect: instrument noise only
    old_stop = round(0.6 * n)
    assert rms(record.force[old_stop:]) < 0.15 * rms(record.force)  # the tail is quiet
    stop = stop_of(record, Options())
    assert stop < 1200  # the withheld part starts in the loud part, with its share of signal
    diagnosis = diagnose(record)
    result = diagnosis.to_json()
    assert result["record"]["withheld"]["samples"] == [stop, n]
    gap = result["baseline"]["gap_withheld"]["total_pct"]
    assert gap < 1.5 * result["noise_floor"]["noise_only_gap_pct"], gap
    assert result["verdict"]["effect"] == "none", result["verdict"]
    # what the tail would have made of the same residual: over its own RMS force, the noise
    # alone reads as a gap several times the floor
    assert diagnosis.series is not None
    residual = (record.force - diagnosis.series.sim)[old_stop:]
    assert 100.0 * rms(residual) / rms(record.force[old_stop:]) > 2.0
