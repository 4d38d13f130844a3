"""A platform several actuators load together: equilibrium, coupling, material semantics."""

from __future__ import annotations

import numpy as np
import pytest

from sim_actuator.models import make_model
from sim_actuator.platform import Platform, PlatformError

L1, L2 = 400.0, 600.0
COLUMN = [[1.0, 0.0, 0.0], [0.0, 1.0, -L1], [0.0, 1.0, L2]]  # ThreeActuators2d, linear
K_BASIC = (10.0, 200.0, 5.0e6)  # shear kN/mm, axial kN/mm, rotation kN·mm/rad


def elastic_column() -> Platform:
    return Platform(COLUMN, [make_model("elastic", k=k) for k in K_BASIC])


def test_one_actuator_moved_loads_the_others_in_equilibrium() -> None:
    platform = elastic_column()
    force, tangent = platform.set_trial(1, 1.0)  # actuator 2 (vertical, left) alone
    platform.commit()
    t, k = np.array(COLUMN), np.diag(K_BASIC)
    k_act = np.linalg.inv(t).T @ k @ np.linalg.inv(t)
    x = np.array([0.0, 1.0, 0.0])
    f = np.array([platform.force(i) for i in range(3)])
    np.testing.assert_allclose(f, k_act @ x, rtol=1e-12)
    assert force == pytest.approx(f[1], rel=1e-12) and tangent == pytest.approx(k_act[1, 1])
    assert abs(f[2]) > 1.0  # the other vertical actuator holds the platform's rotation
    q = np.array(platform.basic(platform.strokes))
    np.testing.assert_allclose(t.T @ f, np.array(K_BASIC) * q, rtol=1e-12, atol=1e-9)


def test_a_trial_is_from_the_committed_state_and_a_commit_moves_the_platform() -> None:
    platform = Platform(COLUMN, [make_model("bilinear", k0=10.0, fy=5.0, alpha=0.02),
                                 make_model("elastic", k=200.0), make_model("elastic", k=5e6)])
    first, _ = platform.set_trial(0, 2.0)  # beyond yield: 5 + 0.02*10*1.5
    again, _ = platform.set_trial(0, 2.0)  # not committed: the same answer
    assert first == again == pytest.approx(5.0 + 0.2 * 1.5)
    platform.commit()
    back, _ = platform.set_trial(0, 1.5)  # elastic unloading from the yielded state
    assert back == pytest.approx(5.3 - 10.0 * 0.5)
    assert platform.strokes == (2.0, 0.0, 0.0)


def test_a_singular_or_misshapen_geometry_is_refused() -> None:
    laws = [make_model("elastic", k=1.0) for _ in range(3)]
    with pytest.raises(PlatformError, match="singular"):
        Platform([[1, 0, 0], [0, 1, 0], [0, 2, 0]], laws)
    with pytest.raises(PlatformError, match=r"must be 3×3"):
        Platform([[1, 0], [0, 1]], laws)
