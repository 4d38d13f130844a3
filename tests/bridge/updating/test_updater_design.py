"""The design records of ``benchmarks.updater_design``: the synthetic families are seeded records
at the study's 3 m/s², distinct from each other, the impulsive ones strong early; the run list
honours ``--only``/``--noise``/``--family`` and refuses what it cannot run."""

from __future__ import annotations

import numpy as np
import pytest

from benchmarks.updater_design import DESIGN_FAMILIES, design_motion, design_runs
from fresco_bridge.integrator.ground_motion import G_M_S2


def _early_share(accel: np.ndarray, dt: float, seconds: float = 5.0) -> float:
    energy = np.cumsum(accel**2)
    return float(energy[round(seconds / dt)] / energy[-1])


def test_families_are_seeded_distinct_records_at_the_study_pga() -> None:
    records = {name: design_motion(name, 11) for name in DESIGN_FAMILIES}
    for name, motion in records.items():
        again = design_motion(name, 11)
        assert np.array_equal(motion.accel, again.accel), name
        assert np.max(np.abs(motion.accel)) * G_M_S2 == pytest.approx(3.0), name
        assert motion.accel.size == 2001, name
    names = list(records)
    for i, a in enumerate(names):
        for b in names[i + 1:]:
            assert not np.allclose(records[a].accel, records[b].accel), (a, b)
    assert not np.array_equal(design_motion("kt", 11).accel, design_motion("kt", 12).accel)
    # the default family is the harness's historical record (kanai_tajimi defaults)
    from fresco_bridge.integrator import kanai_tajimi

    assert np.array_equal(design_motion("kt", 3).accel, kanai_tajimi(3.0, 20.0, seed=3).accel)
    # impulsive envelopes put the strong shaking early
    for name in ("pulse", "softpulse"):
        base = "kt" if name == "pulse" else "soft"
        assert (_early_share(records[name].accel, records[name].dt)
                > 1.5 * _early_share(records[base].accel, records[base].dt))


def test_the_run_list() -> None:
    default = design_runs()
    assert len(default) == 10 and sum(it[0] == "replay" for it, _ in default) == 2
    assert {fam for _, fam in default} == {"kt"}
    runs = design_runs("bwbn", (11, 12), ("kt", "pulse"), 0.0)
    assert [(it, fam) for it, fam in runs] == [
        ((11, "bwbn", 0.0), "kt"), ((12, "bwbn", 0.0), "kt"),
        ((11, "bwbn", 0.0), "pulse"), ((12, "bwbn", 0.0), "pulse")]
    assert len(design_runs(seeds=(3,), noise=1.0)) == 2


@pytest.mark.parametrize(("seeds", "families"), [
    (None, ("pulse",)),      # another family needs seeds: the replay pairs are kt's
    ((11,), ("rock",)),      # unknown
    ((11,), ()),             # none
])
def test_bad_runs_are_refused(seeds: tuple[int, ...] | None, families: tuple[str, ...]) -> None:
    with pytest.raises(ValueError, match="families must be of kt, soft, pulse, softpulse"):
        design_runs(seeds=seeds, families=families)

