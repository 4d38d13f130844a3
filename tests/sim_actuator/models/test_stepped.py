"""The JIT-stepped Bouc-Wen objects are the objects, bit for bit (trials, commits, reverts,
clones, refusals)."""

from __future__ import annotations

from collections.abc import Callable

import numpy as np
import pytest

from sim_actuator.models import ModelInputError
from sim_actuator.models.bouc_wen import BoucWen, BoucWenFamily
from sim_actuator.models.bwbn import BoucWenBaberNoori
from sim_actuator.models.stepped import SteppedBaberNoori, SteppedBoucWen

BW = {"k0": 10.0, "fy": 5.0, "alpha": 0.05, "n": 2.0, "beta": 0.6, "gamma": 0.4}
BWBN = {"k0": 8.0, "fy": 12.0, "alpha": 0.05, "n": 1.5, "beta": 0.5, "gamma": 0.5,
        "delta_nu": 0.002, "delta_eta": 0.003, "delta_a": 0.0005, "zeta_s": 0.6, "p": 0.8,
        "q": 0.1, "psi0": 0.2, "delta_psi": 0.004, "lam": 0.5}  # fmt: skip


def _history(seed: int, n: int = 300, peak: float = 6.0) -> list[float]:
    rng = np.random.default_rng(seed)
    steps = rng.standard_normal(n) * 0.4
    steps[rng.random(n) < 0.1] = 0.0
    d = np.cumsum(steps)
    return [float(x) for x in d / np.max(np.abs(d)) * peak]


@pytest.mark.parametrize(("plain", "stepped", "params"),
                         [(BoucWen, SteppedBoucWen, BW),
                          (BoucWenBaberNoori, SteppedBaberNoori, BWBN)])  # fmt: skip
@pytest.mark.parametrize("dz_max", [0.01, 0.2])
def test_stepped_is_the_object_bit_for_bit(plain: Callable[..., BoucWenFamily],
                                           stepped: Callable[..., BoucWenFamily],
                                           params: dict[str, float], dz_max: float) -> None:
    a, b = plain(**params, dz_max=dz_max), stepped(**params, dz_max=dz_max)
    for i, d in enumerate(_history(4)):
        assert a.set_trial(d) == b.set_trial(d)
        if i % 7 == 3:  # a trial that is discarded
            assert a.set_trial(d + 0.5) == b.set_trial(d + 0.5)
            a.revert_to_last_commit()
            b.revert_to_last_commit()
            assert a.set_trial(d) == b.set_trial(d)
        a.commit()
        b.commit()
        assert a.state() == b.state()
    c = b.clone()
    assert type(c) is stepped and c.set_trial(1.0) == a.set_trial(1.0)


def test_a_refused_trial_raises_the_objects_error() -> None:
    model = SteppedBaberNoori(**{**BWBN, "delta_a": 0.5})
    with pytest.raises(ModelInputError, match="degradation exhausted"):
        for d in _history(2, 400, 40.0):
            model.set_trial(d)
            model.commit()


def test_a_step_past_the_substep_limit_raises_the_objects_error() -> None:
    model = SteppedBoucWen(**BW)
    with pytest.raises(ModelInputError, match="substeps"):
        model.set_trial(1e9)
    assert model.set_trial(0.5) == BoucWen(**BW).set_trial(0.5)  # nothing was committed
