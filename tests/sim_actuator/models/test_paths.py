"""The JIT whole-history drives are the scalar models, sample for sample (one law, two forms)."""

from __future__ import annotations

import numpy as np
import pytest

from sim_actuator.effects import LoadPath
from sim_actuator.models import ModelInputError, make_model
from sim_actuator.models.bouc_wen import BoucWen
from sim_actuator.models.paths import LAW_BOUC_WEN, bouc_wen_vector, drive, drive_many, law_vector

CASES = [
    ("bilinear", {"k0": 10.0, "fy": 5.0, "alpha": 0.05}),
    ("bouc-wen", {"k0": 10.0, "fy": 5.0, "alpha": 0.05, "n": 2.0, "beta": 0.6, "gamma": 0.4}),
    ("bouc-wen", {"k0": 3.0, "fy": 9.0, "alpha": 0.1, "n": 1.0, "beta": 0.2, "gamma": 0.9,
                  "A": 1.3}),
    ("bwbn", {"k0": 8.0, "fy": 12.0, "alpha": 0.05, "n": 1.5, "beta": 0.5, "gamma": 0.5,
              "delta_nu": 0.002, "delta_eta": 0.003, "delta_a": 0.0005, "zeta_s": 0.6,
              "p": 0.8, "q": 0.1, "psi0": 0.2, "delta_psi": 0.004, "lam": 0.5}),
    ("menegotto-pinto", {"k0": 20.0, "fy": 10.0, "alpha": 0.02, "R0": 18.0}),
    ("menegotto-pinto", {"k0": 5.0, "fy": 30.0, "alpha": 0.1, "R0": 8.0, "cR1": 0.8,
                         "cR2": 0.3, "a1": 0.05, "a2": 2.0, "a3": 0.04, "a4": 3.0}),
]


def _history(seed: int, n: int = 200, peak: float = 6.0) -> np.ndarray:
    rng = np.random.default_rng(seed)
    steps = rng.standard_normal(n) * 0.4
    steps[rng.random(n) < 0.1] = 0.0  # holds: repeated samples
    d = np.cumsum(steps)
    return np.asarray(d / np.max(np.abs(d)) * peak, dtype=np.float64)


@pytest.mark.parametrize(("kind", "params"), CASES)
@pytest.mark.parametrize("dz_max", [0.01, 0.2])
def test_drive_equals_the_scalar_model(kind: str, params: dict[str, float],
                                       dz_max: float) -> None:
    d = _history(3)
    extra = {} if kind in ("bilinear", "menegotto-pinto") else {"dz_max": dz_max}
    model = make_model(kind, **params)
    if extra:
        model = type(model)(**params, **extra)  # type: ignore[call-arg]
    expected = []
    for x in d:
        force, _ = model.set_trial(float(x))
        model.commit()
        expected.append(force)
    law, vec = law_vector(kind, params)
    got = drive(law, vec, d, 0.0, dz_max)
    np.testing.assert_allclose(got, expected, rtol=0.0, atol=1e-12 * params["fy"])


@pytest.mark.parametrize(("kind", "params"), [*CASES[:2], CASES[4]])
def test_drive_behind_a_gap_equals_the_rigs_load_path(kind: str,
                                                       params: dict[str, float]) -> None:
    d = _history(5, 300)
    path = LoadPath(make_model(kind, **params), dt=0.01, gap=0.3)
    expected = [path.step(float(x)).connection_force for x in d]
    law, vec = law_vector(kind, params)
    np.testing.assert_allclose(drive(law, vec, d, 0.3), expected, rtol=0.0, atol=1e-9)


def test_population_rows_are_independent_drives() -> None:
    law, vec = law_vector(*CASES[1])
    d = _history(7)
    rows = np.tile(vec, (3, 1))
    rows[:, 0] *= [0.8, 1.0, 1.3]
    many = drive_many(law, rows, d[None, :], np.array([0.0, 0.1, 0.0]), 0.05)
    for i in range(3):
        np.testing.assert_array_equal(many[i], drive(law, rows[i], d, [0.0, 0.1, 0.0][i], 0.05))


def test_a_refused_history_is_nan_from_where_the_scalar_model_refuses_it() -> None:
    params = dict(CASES[3][1], delta_a=0.3)  # A = A0 - delta_a*e is exhausted partway
    d = _history(9, 400, 20.0)
    model = make_model("bwbn", **params)
    refused = None
    for k, x in enumerate(d):
        try:
            model.set_trial(float(x))
        except ModelInputError:
            refused = k
            break
        model.commit()
    assert refused is not None and refused > 0
    law, vec = law_vector("bwbn", params)
    out = drive(law, vec, d)
    assert np.all(np.isfinite(out[:refused])) and np.all(np.isnan(out[refused:]))


def test_menegotto_pinto_from_rest_and_with_an_overflowing_curve() -> None:
    """Holds at the virgin state (Steel02's "at rest" branch) and an R so large that
    |x|**R overflows: the drive takes the scalar law's exact limit, not inf."""
    params = {"k0": 10.0, "fy": 5.0, "alpha": 0.01, "R0": 800.0, "cR1": 0.0}
    d = np.concatenate([np.zeros(3), _history(11, 150, 40.0)])
    model = make_model("menegotto-pinto", **params)
    expected = []
    for x in d:
        force, _ = model.set_trial(float(x))
        model.commit()
        expected.append(force)
    law, vec = law_vector("menegotto-pinto", params)
    np.testing.assert_allclose(drive(law, vec, d), expected, rtol=0.0, atol=1e-12 * 5.0)


@pytest.mark.parametrize("params", [CASES[1][1], CASES[2][1],
                                    {"k0": 10.0, "fy": 5.0, "alpha": 0.2, "n": 9.0, "beta": 2.0,
                                     "gamma": 0.1}])  # fmt: skip
@pytest.mark.parametrize("dz_max", [0.01, 0.2])
def test_the_classic_bouc_wen_drive_is_the_object_bit_for_bit(params: dict[str, float],
                                                              dz_max: float) -> None:
    d = _history(7, 400, 9.0)
    model = BoucWen(**params, dz_max=dz_max)
    expected = []
    for x in d:
        expected.append(model.set_trial(float(x))[0])
        model.commit()
    got = drive(LAW_BOUC_WEN, bouc_wen_vector(params), d, 0.0, dz_max)
    assert np.array_equal(got, np.array(expected))  # the same operations: not merely close


ISOTROPIC = {"k0": 10.0, "fy": 5.0, "alpha": 0.03, "q_iso": 0.7, "p_sat": 6.0}


def test_isotropic_bilinear_drive_equals_the_scalar_model() -> None:
    from sim_actuator.models import IsotropicBilinear

    d = _history(7, 400)
    model = IsotropicBilinear(**ISOTROPIC)
    expected = []
    for x in d:
        force, _ = model.set_trial(float(x))
        model.commit()
        expected.append(force)
    law, vec = law_vector("isotropic-bilinear", ISOTROPIC)
    np.testing.assert_allclose(drive(law, vec, d), expected, rtol=0.0, atol=1e-12 * 5.0)
    plain = law_vector("bilinear", {"k0": 10.0, "fy": 5.0, "alpha": 0.03})
    without = law_vector("isotropic-bilinear", {**ISOTROPIC, "q_iso": 0.0})
    np.testing.assert_allclose(drive(*without, d), drive(*plain, d), rtol=0.0, atol=1e-12)
