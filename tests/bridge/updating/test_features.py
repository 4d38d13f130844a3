"""Feature map and min-max normalisation against values worked out by hand."""

from __future__ import annotations

import numpy as np
import pytest

from fresco_bridge.updating import UpdaterError
from fresco_bridge.updating.features import (
    PAPER_FEATURES,
    FeatureSpec,
    MinMaxScaler,
    feature_row,
    feature_rows,
    next_energy,
)

D = [1.0, 2.0, -1.0]
F = [10.0, 15.0, -5.0]
# [d_i, d_i-1, F_i-1, F_i-1*d_i-1, F_i-1*(d_i - d_i-1), E_i-1], E_i-1 = E_i-2 + |F_i-1*d_i-1|
HAND_ROWS = [
    [1.0, 0.0, 0.0, 0.0, 0.0, 0.0],             # from the virgin state
    [2.0, 1.0, 10.0, 10.0, 10.0, 10.0],         # E_0 = |10*1|
    [-1.0, 2.0, 15.0, 30.0, -45.0, 40.0],       # F*dd = 15*(-3), E_1 = 10 + |15*2|
]  # fmt: skip


def test_feature_rows_match_hand_values() -> None:
    x, y = feature_rows(D, F)
    np.testing.assert_array_equal(x, HAND_ROWS)
    np.testing.assert_array_equal(y, F)


def test_feature_row_is_the_recurrence_step() -> None:
    np.testing.assert_array_equal(feature_row(-1.0, 2.0, 15.0, 40.0), HAND_ROWS[2])
    assert next_energy(10.0, 2.0, 15.0) == 40.0
    assert next_energy(0.0, -2.0, 3.0) == 6.0  # |F*d|, never negative


def test_minmax_normalisation_hand_values() -> None:
    x, y = feature_rows(D, F)
    scaler = MinMaxScaler.fit(x, y)
    np.testing.assert_array_equal(scaler.x_min, [-1.0, 0.0, 0.0, 0.0, -45.0, 0.0])
    np.testing.assert_array_equal(scaler.x_max, [2.0, 2.0, 15.0, 30.0, 10.0, 40.0])
    xn = scaler.x(x)
    np.testing.assert_allclose(xn[0], [2 / 3, 0.0, 0.0, 0.0, 45 / 55, 0.0])
    np.testing.assert_allclose(xn[2], [0.0, 1.0, 1.0, 1.0, 0.0, 1.0])
    np.testing.assert_allclose(scaler.y(y), [0.75, 1.0, 0.0])  # (F + 5)/20
    assert scaler.y_inverse(0.75) == 10.0
    # Online data beyond the offline range are not clipped.
    assert scaler.y(np.array([25.0]))[0] == 1.5


def test_constant_column_gets_unit_range() -> None:
    x = np.array([[1.0, 3.0, 0, 0, 0, 0], [2.0, 3.0, 0, 0, 0, 0]])
    scaler = MinMaxScaler.fit(x, np.array([4.0, 4.0]))
    np.testing.assert_array_equal(scaler.x(x)[:, 1], [0.0, 0.0])
    assert scaler.y_range == 1.0


def test_scaler_round_trip_through_bounds() -> None:
    x, y = feature_rows(D, F)
    a = MinMaxScaler.fit(x, y)
    b = MinMaxScaler.from_bounds(a.x_min, a.x_max, a.y_min, a.y_max)
    np.testing.assert_array_equal(a.x(x), b.x(x))
    with pytest.raises(UpdaterError, match="6 entries"):
        MinMaxScaler.from_bounds([0.0], [1.0], 0.0, 1.0)


def test_bad_histories_are_refused() -> None:
    with pytest.raises(UpdaterError, match="finite"):
        feature_rows([0.0, np.nan], [1.0, 2.0])
    with pytest.raises(UpdaterError, match="equal length"):
        feature_rows([0.0, 1.0], [1.0])


def test_other_feature_spec_is_refused() -> None:
    assert FeatureSpec.from_dict(PAPER_FEATURES.as_dict(), where="f") == PAPER_FEATURES
    other = {**PAPER_FEATURES.as_dict(), "version": 2}
    with pytest.raises(UpdaterError, match=r"f: feature spec 'paper6' v2 .* retrain"):
        FeatureSpec.from_dict(other, where="f")
