"""``online_improved`` over an arbitrarily long run: an expert whose law diverges (a free-run
copy whose force grows without bound, as a reversal basis extrapolated past its data can) loses
the comparison instead of raising, and the served answer and every accumulated error stay
finite (a 100,000-step twin session HOLDed on an ``OverflowError`` at step 44,366)."""

from __future__ import annotations

import math

import numpy as np

from fresco_bridge.updating.improved import OnlineImproved
from sim_actuator.models import make_model
from sim_actuator.models.base import HysteresisModel

DAMPER = {"k0": 20.0, "fy": 15.0, "alpha": 0.05}


class Diverging:
    """A law that multiplies its force by 1e30 every step: past 1e154 its error squared
    overflows a float, then it is inf, then NaN (inf - inf)."""

    name = "diverging"
    initial_tangent = 1.0

    def __init__(self) -> None:
        self.force = 1.0
        self.committed = (0.0, 0.0)

    def set_trial(self, d: float) -> tuple[float, float]:
        self.force = self.force * 1e30 - (math.inf if self.force == math.inf else 0.0)
        return self.force, self.force

    def commit(self) -> None:
        self.committed = (0.0, self.force)

    def revert_to_last_commit(self) -> None:
        pass

    def revert_to_start(self) -> None:
        self.force = 1.0

    def clone(self) -> HysteresisModel:
        return Diverging()


def _source(steps: int) -> list[tuple[float, float]]:
    law = make_model("bilinear", **DAMPER)
    out = []
    for i in range(1, steps + 1):
        d = 3.0 * math.sin(2 * math.pi * i / 50)
        out.append((d, law.set_trial(d)[0]))
        law.commit()
    return out


def _updater() -> OnlineImproved:
    d = 3.0 * np.linspace(0.0, 1.0, 400) * np.sin(2 * np.pi * np.arange(400) / 50)
    law = make_model("bilinear", **DAMPER)
    f = []
    for x in d.tolist():
        f.append(law.set_trial(x)[0])
        law.commit()
    return OnlineImproved(offline=(d, np.array(f)), experts=("reversal", "reversal+memory"))


def test_a_diverging_free_run_copy_loses_and_never_raises() -> None:
    updater = _updater()
    updater._free[0] = Diverging()  # the reversal expert's copy on the tested element diverges
    for d, f in _source(300):  # its force passes 1e154 (overflow), inf and NaN, restarts
        updater.observe(d, f)
    assert np.all(np.isfinite(updater.scores)) and np.all(np.isfinite(updater.harm))
    weights = updater.mixture_weights()
    assert math.isclose(float(weights.sum()), 1.0)
    assert weights[0] < 1e-6 < weights[1]  # the diverging expert lost the comparison
    assert updater.scores[0] > 1e6 * updater.scores[1]


def test_the_served_answer_stays_finite_when_a_weighted_part_diverges() -> None:
    updater = _updater()
    for d, f in _source(100):
        updater.observe(d, f)
    updater.harm[:] = (0.0, 1.0)  # serve the mixture, not the offline start
    assert not updater.serving_start and updater.mixture_weights()[0] > 0.0
    twin = updater.twin
    twin._parts[0] = Diverging()  # type: ignore[attr-defined]
    for i in range(1, 40):  # the part passes inf, then NaN
        force, tangent = twin.set_trial(0.5 * math.sin(i / 5))
        assert math.isfinite(force) and math.isfinite(tangent)
        twin.commit()


def test_the_do_no_harm_errors_stay_finite_when_every_copy_diverges() -> None:
    """The prequential errors are running means (the same choice as the sums) of errors that
    cannot overflow: the mixture with no finite copy loses to the offline start."""
    updater = _updater()
    updater._free = [Diverging(), Diverging()]
    for d, f in _source(300):
        updater.observe(d, f)
    assert np.all(np.isfinite(updater.harm)) and np.all(np.isfinite(updater.scores))
    assert updater.serving_start and updater.harm[0] > 1e300 > updater.harm[1]
    assert math.isfinite(updater.twin.set_trial(1.0)[0])
