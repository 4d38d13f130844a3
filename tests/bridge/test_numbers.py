"""The one number formatter: significant digits, no float dust, ``–`` for undefined."""

from __future__ import annotations

import math

import numpy as np

from fresco_bridge.numbers import UNDEFINED, fmt, pct, rounded


def test_fmt_prints_significant_digits_and_zero_for_dust() -> None:
    assert fmt(12.3456) == "12.35" and fmt(0.000123456) == "0.0001235"
    assert fmt(1234567.0, "kN") == "1.235e+06 kN" and fmt(3, "mm", 2) == "3 mm"
    assert fmt(-2.434e-19) == "0" and fmt(-2.434e-16, "ms") == "0 ms"  # the float dust
    assert fmt(-1e-9) == "-1e-09"  # small but not dust: kept
    assert fmt(-0.00001, digits=1) == "-1e-05" and fmt(-0.0) == "0"
    assert fmt(np.float64(-4e-20)) == "0"


def test_undefined_values_print_a_dash() -> None:
    for value in (None, math.nan, math.inf, -math.inf):
        assert fmt(value) == UNDEFINED == "–" and pct(value) == UNDEFINED


def test_pct_never_prints_minus_zero() -> None:
    assert pct(-0.001) == "0.00 %" and pct(-3.4e-13) == "0.00 %"
    assert pct(12.345) == "12.35 %" and pct(-1.5, 1) == "-1.5 %"


def test_rounded_keeps_significant_digits_for_json() -> None:
    assert rounded(5.887515649000079) == 5.888 and rounded(16.357297897338867) == 16.36
    assert rounded(-3e-17) == 0.0 and math.isnan(rounded(math.nan))


def test_ctl_status_prints_live_values_without_dust() -> None:
    from fresco_bridge.ctl import format_answer

    site = {"site": "damper", "state": "RUNNING", "reason": "", "session": 1, "peer": None,
            "step": 3, "time": 0.03, "ctrl": [0.0, -2.434e-19], "target": [0.0, 1.23456],
            "daq_disp": [-0.0], "daq_force": [math.nan], "holds": 0, "limit_events": {},
            "limits": [], "pending": None}
    text = format_answer({"sites": [site]})
    assert "ctrl [0, 0] mm (target [0, 1.235])  daq disp [0] mm force [–] kN" in text, text
