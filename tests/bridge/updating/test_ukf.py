"""online_ukf: paper start values in kN/mm, convergence on synthetic Bilinear data."""

from __future__ import annotations

import numpy as np
import pytest

from fresco_bridge.updating import make_updater
from fresco_bridge.updating.ukf import PAPER_UKF, OnlineUkfUpdater, bilinear_step
from sim_actuator.models import Bilinear
from tests.support.histories import disp_history, force_history

TRUE = {"k0": 8.0, "fy": 12.0, "alpha": 0.05}


def test_paper_start_converted_from_n_and_mm() -> None:
    assert PAPER_UKF["k0"] == 68.0 and PAPER_UKF["fy"] == 35.0 and PAPER_UKF["alpha"] == 0.008
    np.testing.assert_allclose(PAPER_UKF["p0"], (1e-3, 0.2, 1e-6))  # (1e3 (N/mm)^2, 0.2, 1 N^2)
    np.testing.assert_allclose(PAPER_UKF["q"], (1e-12, 1e-6, 1e-12))
    assert PAPER_UKF["r"] == pytest.approx(1e-4)  # 1e2 N^2
    u = make_updater("online_ukf")
    assert isinstance(u, OnlineUkfUpdater)
    assert u.parameters == (68.0, 0.008, 35.0)
    np.testing.assert_allclose(np.diag(u.covariance), PAPER_UKF["p0"])


def test_measurement_function_is_the_sim_actuator_law() -> None:
    law = Bilinear(**TRUE)
    for d in (0.5, 2.0, 1.0, -3.0):
        d_c, f_c = law.committed
        f = law.set_trial(d)[0]
        law.commit()
        assert bilinear_step(np.array([8.0, 0.05, 12.0]), d_c, f_c, d) == f


def test_ukf_converges_on_synthetic_bilinear_data() -> None:
    d = disp_history(1200, seed=3, amp=6.0)  # yields repeatedly (dy = 1.5 mm)
    f = force_history(d, "bilinear", TRUE)
    u = make_updater("online_ukf", k0=10.0, alpha=0.1, fy=8.0, p0=(4.0, 0.01, 16.0))
    for di, fi in zip(d, f, strict=True):
        u.observe(float(di), float(fi))
    k0, alpha, fy = u.parameters  # type: ignore[attr-defined]
    assert k0 == pytest.approx(8.0, rel=0.01)
    assert alpha == pytest.approx(0.05, rel=0.05)
    assert fy == pytest.approx(12.0, rel=0.01)
    # The twin, driven on its own, now follows the true law.
    twin_f = []
    for di in d[:300]:
        twin_f.append(u.twin.set_trial(float(di))[0])
        u.twin.commit()
    assert np.max(np.abs(np.array(twin_f) - f[:300])) < 0.1


def test_twin_keeps_its_state_when_parameters_change() -> None:
    u = make_updater("online_ukf", k0=10.0, alpha=0.1, fy=8.0, p0=(4.0, 0.01, 16.0))
    twin = u.twin
    twin.set_trial(0.5)
    twin.commit()
    before = twin.committed
    u.observe(0.3, 2.4)
    assert u.twin is twin and twin.committed == before
