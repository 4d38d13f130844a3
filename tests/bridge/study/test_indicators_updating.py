"""Model-updating indicators (paper Table 3, Fig. 14) against hand values."""

from __future__ import annotations

import math

import numpy as np
import pytest

from fresco_bridge.indicators import (
    IndicatorError,
    maesd,
    maeth,
    one_step_rmse,
    peak_values,
    rmseth,
)


def test_peak_values_and_their_errors_are_magnitudes_per_sign() -> None:
    pv = peak_values([1.0, 5.0, -3.0, 2.0], [0.5, 4.0, -4.5, 1.0])
    assert (pv.pv_es_pos, pv.pv_es_neg, pv.pv_ums_pos, pv.pv_ums_neg) == (5.0, 3.0, 4.0, 4.5)
    assert (pv.aepv_pos, pv.aepv_neg) == (1.0, 1.5)


def test_maeth_and_one_step_rmse_by_hand() -> None:
    true, pred = [0.0, 1.0, -2.0, 3.0], [0.5, 1.0, -1.0, 3.0]
    assert maeth(true, pred) == 1.0
    assert one_step_rmse(true, pred) == pytest.approx(math.sqrt((0.25 + 1.0) / 4))
    assert rmseth(true, pred) == one_step_rmse(true, pred)  # the same RMS, of the served force


def test_maesd_is_per_story() -> None:
    u = np.array([[0.0, 0.0], [1.0, 2.0], [2.0, 5.0]])
    ref = np.array([[0.0, 0.0], [1.5, 2.0], [2.0, 3.0]])
    assert maesd(u, ref) == [0.5, 2.0]


@pytest.mark.parametrize(
    "call",
    [
        lambda: maeth([1.0, 2.0], [1.0]),
        lambda: maeth([1.0, math.nan], [1.0, 2.0]),
        lambda: one_step_rmse([], []),
        lambda: rmseth([1.0, math.inf], [1.0, 2.0]),
        lambda: maesd(np.zeros((3, 2)), np.zeros((3, 1))),
        lambda: maesd(np.full((2, 2), np.inf), np.zeros((2, 2))),
    ],
)
def test_bad_signals_are_refused_with_a_clear_error(call: object) -> None:
    with pytest.raises(IndicatorError):
        call()  # type: ignore[operator]
