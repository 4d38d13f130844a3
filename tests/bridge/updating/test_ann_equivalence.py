"""The pre-registered non-inferiority analysis of ``benchmarks.ann_equivalence`` on hand-made
numbers: seeds are averaged in log space, the one-sided bound uses Student's t, the verdict
needs both endpoints and all pairs."""

from __future__ import annotations

import math
from typing import Any

import pytest

from benchmarks.ann_equivalence import CANDIDATE, FAITHFUL, analyse, markdown, non_inferiority

T_095_3 = 2.3533634348  # scipy.stats.t.ppf(0.95, 3)


def _rows(d_tf: list[float], d_ma: list[float], base: float = 1.0) -> list[dict[str, Any]]:
    """Four pairs (2 per specimen); faithful seeds 1, 2, 3 = base x (1, 4, 16) (geometric mean
    base x 4); the candidate = faithful x exp(d) on every seed."""
    rows = []
    labels = ["bwbn/record2", "bwbn/record3", "menegotto-pinto/record2",
              "menegotto-pinto/record3"]
    for p, dt, dm in zip(labels, d_tf, d_ma, strict=True):
        for seed, f in zip((1, 2, 3), (1.0, 4.0, 16.0), strict=True):
            for meth, k_t, k_m in ((FAITHFUL, 1.0, 1.0),
                                   (CANDIDATE, math.exp(dt), math.exp(dm))):
                rows.append({"layout": "generalisation", "pair": p, "method": meth,
                             "seed": seed, "teacher_forced_rmse": base * f * k_t,
                             "maeth": 10.0 * base * f * k_m, "iterations_mean": 8.0,
                             "cpu_ms_median": 1.0, "cpu_ms_p99": 2.0})
    return rows


def test_the_rule_by_hand() -> None:
    # d = 0.1, 0.2, 0.0, 0.3: mean 0.15, SD sqrt(0.05 / 3), U = 0.15 + t s / 2
    res = non_inferiority({"a/1": 0.1, "a/2": 0.2, "b/1": 0.0, "b/2": 0.3})
    s = math.sqrt(0.05 / 3)
    assert res["n"] == 4
    assert res["d_mean"] == pytest.approx(0.15)
    assert res["d_sd"] == pytest.approx(s)
    assert res["t_0.95"] == pytest.approx(T_095_3)
    assert res["upper"] == pytest.approx(0.15 + T_095_3 * s / 2)  # 0.3019 > ln 1.25 = 0.2231
    assert res["ratio"] == pytest.approx(math.exp(0.15))
    assert res["ratio_upper"] == pytest.approx(math.exp(0.15 + T_095_3 * s / 2))
    assert res["non_inferior"] is False
    assert res["pairs_worse"] == 3
    assert res["per_specimen_ratio"] == {"a": pytest.approx(math.exp(0.15)),
                                         "b": pytest.approx(math.exp(0.15))}
    assert [w["pair"] for w in res["worst3"]] == ["b/2", "a/2", "a/1"]
    # a candidate better on average with a small spread is non-inferior
    ok = non_inferiority({"a/1": -0.1, "a/2": 0.05, "b/1": 0.0, "b/2": -0.05})
    assert ok["upper"] < math.log(1.25) and ok["non_inferior"] is True
    # exactly at the margin counts as non-inferior (U <= ln 1.25)
    edge = non_inferiority({"a/1": 0.0, "a/2": 0.0}, margin=1.0)
    assert edge["upper"] == 0.0 and edge["non_inferior"] is True


def test_analyse_both_endpoints_needed_and_log_means() -> None:
    summary = analyse(_rows([0.1, 0.2, 0.0, 0.3], [-0.1, 0.05, 0.0, -0.05]),
                      expected_pairs=4)
    tf, ma = summary["endpoints"]["teacher_forced_rmse"], summary["endpoints"]["maeth"]
    assert summary["partial"] is False and summary["pairs_complete"] == 4
    assert tf["non_inferior"] is False and ma["non_inferior"] is True
    assert summary["equal_accuracy"] is False
    assert tf["d_mean"] == pytest.approx(0.15) and ma["d_mean"] == pytest.approx(-0.025)
    # seeds are averaged in log space: the faithful geometric mean is 4, not (1+4+16)/3
    assert tf["geomean"][FAITHFUL] == pytest.approx(4.0)
    assert ma["per_specimen_geomean"]["bwbn"][CANDIDATE] == pytest.approx(
        40.0 * math.exp(-0.025))
    # the own spread: SD of ln(1, 4, 16) = 2 ln 2; seed 2 / seed 1 = 4, seed 3 / seed 1 = 16
    sp = tf["spread"][FAITHFUL]
    assert sp["sd_ln_median"] == pytest.approx(2 * math.log(2))
    assert sp["seed_ratios"]["seed 2 / seed 1"]["ratio"] == pytest.approx(4.0)
    assert sp["seed_ratios"]["seed 3 / seed 1"]["ratio"] == pytest.approx(16.0)
    assert sp["seed_ratios"]["seed 3 / seed 1"]["pairs_up"] == 4
    # runaways: MAETH = 10 x (1, 4, 16) x k: the seed-2 and seed-3 runs exceed 20 kN
    assert summary["runaways"]["generalisation"][FAITHFUL] == {"runs_over": 8, "runs": 12}
    both = analyse(_rows([0.0, 0.01, -0.01, 0.0], [0.02, 0.0, -0.02, 0.0]), expected_pairs=4)
    assert both["equal_accuracy"] is True
    assert "equal accuracy declared" in markdown(both)


def test_partial_data_gives_no_verdict() -> None:
    rows = _rows([0.0, 0.01, -0.01, 0.0], [0.02, 0.0, -0.02, 0.0])
    # one seed of one pair missing: that pair is left out and the verdict withheld
    rows = [r for r in rows if not (r["pair"] == "bwbn/record3" and r["seed"] == 3
                                    and r["method"] == CANDIDATE)]
    summary = analyse(rows, expected_pairs=4)
    assert summary["pairs_complete"] == 3 and summary["partial"] is True
    assert summary["endpoints"]["maeth"]["n"] == 3
    assert summary["equal_accuracy"] is None
    assert "PARTIAL" in markdown(summary)


def test_paper_layout_secondary() -> None:
    rows = [{"layout": "paper", "pair": p, "method": m, "seed": 1,
             "teacher_forced_rmse": v, "maeth": 2 * v, "iterations_mean": 8.0,
             "cpu_ms_median": 1.0, "cpu_ms_p99": 2.0}
            for p, m, v in (("bwbn/record2", FAITHFUL, 1.0), ("bwbn/record2", CANDIDATE, 2.0),
                            ("bwbn/record3", FAITHFUL, 4.0), ("bwbn/record3", CANDIDATE, 2.0),
                            ("bwbn/record4", FAITHFUL, 3.0), ("bwbn/record4", CANDIDATE, 6.0))]
    summary = analyse(rows, expected_pairs=28)
    pa = summary["paper"]["teacher_forced_rmse"]
    assert summary["paper"]["pairs_complete"] == 3
    assert pa["median"] == {FAITHFUL: 3.0, CANDIDATE: 2.0}
    assert pa["ratio"] == pytest.approx((2.0 * 0.5 * 2.0) ** (1 / 3))
    assert pa["pairs_worse"] == 2
    assert summary["equal_accuracy"] is None  # no generalisation pair: no verdict


def test_non_positive_value_is_an_error() -> None:
    rows = _rows([0.0] * 4, [0.0] * 4)
    rows[0]["maeth"] = 0.0
    with pytest.raises(ValueError, match="not a positive finite"):
        analyse(rows, expected_pairs=4)
