"""The speed paths of the diagnosis keep its answers: a record fitted on a thinned calibration
part (every k-th sample and every reversal, candidates fitted in two stages) names the same
effect with the same magnitude as the record fitted on every sample, and the gap stays scored
on every withheld sample. No timing is asserted (the machine is shared)."""

from __future__ import annotations

import pytest

from benchmarks.diagnosis.synth import synthetic_record
from fresco_bridge.diagnosis.verdict import Options, diagnose, stop_of

SEED = 20261127


@pytest.mark.parametrize(("effect", "param"), [("friction", "coulomb"), ("backlash", "gap")])
def test_thinned_fits_keep_the_verdict_and_the_magnitude(effect: str, param: str) -> None:
    synthetic = synthetic_record(effect, SEED, steps=2400)
    record = synthetic.record
    effects = ("friction", "backlash", "pinching", "sensor_bias", "sensor_noise")
    whole = diagnose(record, Options(effects=effects, pairs=False)).to_json()
    budget = 500
    assert stop_of(record, Options()) > budget  # the thinned, staged path is really taken
    thin = diagnose(record, Options(effects=effects, pairs=False, max_fit_samples=budget)).to_json()
    assert any("fits used" in note for note in thin["record"]["notes"])
    assert thin["verdict"]["effect"] == whole["verdict"]["effect"] == effect
    got = [next(e for e in r["effects"] if e["name"] == effect)["params"][param]["value"]
           for r in (whole, thin)]
    assert got[1] == pytest.approx(got[0], rel=0.1)
    assert got[1] == pytest.approx(synthetic.truth[param], rel=0.2)
    # scored on every withheld sample, whatever the fits saw
    assert thin["record"]["withheld"]["samples"] == whole["record"]["withheld"]["samples"]
    assert thin["baseline"]["gap_withheld"]["total_pct"] == pytest.approx(
        whole["baseline"]["gap_withheld"]["total_pct"], rel=0.25)
