"""Forgetting window (Eqs. 1-3), Levenberg-Marquardt and the MLP's analytic Jacobian."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from fresco_bridge.updating import UpdaterError
from fresco_bridge.updating.lm import LmOptions, levenberg_marquardt
from fresco_bridge.updating.mlp import PAPER_LAYERS, Mlp
from fresco_bridge.updating.window import SampleWindow, forgetting_weights


@pytest.mark.parametrize(("length", "mu"), [(1, 0.1), (3, 0.5), (200, 0.1), (50, 0.98)])
def test_forgetting_weights_closed_form_and_sum(length: int, mu: float) -> None:
    lam = forgetting_weights(length, mu)
    expected = [(1 - mu) / (1 - mu**length) * mu ** (length - i) for i in range(1, length + 1)]
    np.testing.assert_allclose(lam, expected, rtol=1e-15, atol=0)
    assert lam.sum() == pytest.approx(1.0, abs=1e-14)
    assert np.all(np.diff(lam) >= 0)  # the newest sample weighs most


def test_paper_window_weights() -> None:
    lam = forgetting_weights(200, 0.1)
    assert lam[-1] == pytest.approx(0.9) and lam[-2] == pytest.approx(0.09)


def test_window_slides_oldest_out() -> None:
    w = SampleWindow(3, 2, 0.5)
    for k in range(5):
        w.push(np.array([k, -k], dtype=float), float(k))
    x, y, lam = w.samples()
    np.testing.assert_array_equal(y, [2.0, 3.0, 4.0])
    np.testing.assert_array_equal(x[:, 1], [-2.0, -3.0, -4.0])
    np.testing.assert_allclose(lam, forgetting_weights(3, 0.5))
    part = SampleWindow(10, 1, 0.1)
    part.push(np.array([1.0]), 1.0)
    part.push(np.array([2.0]), 2.0)
    assert part.samples()[2].sum() == pytest.approx(1.0)  # a partly filled window: L = held


def test_bad_forgetting_parameters() -> None:
    with pytest.raises(UpdaterError, match="0 < mu < 1"):
        forgetting_weights(10, 1.0)
    with pytest.raises(UpdaterError, match="length"):
        forgetting_weights(0, 0.1)


def test_paper_network_has_301_parameters() -> None:
    assert Mlp(PAPER_LAYERS).n_params == 301


def test_jacobian_matches_central_differences() -> None:
    net = Mlp(PAPER_LAYERS)
    rng = np.random.default_rng(5)
    theta = net.init_params(rng)
    x = rng.random((9, 6))
    y, jac = net.jacobian(theta, x)
    np.testing.assert_allclose(y, net.forward(theta, x), rtol=1e-14)
    h = 1e-6
    fd = np.empty_like(jac)
    for k in range(net.n_params):
        e = np.zeros(net.n_params)
        e[k] = h
        fd[:, k] = (net.forward(theta + e, x) - net.forward(theta - e, x)) / (2 * h)
    np.testing.assert_allclose(jac, fd, rtol=1e-6, atol=1e-9)


def test_input_gradient_matches_central_differences() -> None:
    net = Mlp(PAPER_LAYERS)
    rng = np.random.default_rng(6)
    theta = net.init_params(rng)
    x = rng.random(6)
    y, grad = net.input_gradient(theta, x)
    assert y == pytest.approx(float(net.forward(theta, x[None, :])[0]), rel=1e-14)
    h = 1e-6
    for k in range(6):
        e = np.zeros(6)
        e[k] = h
        fd = (net.forward(theta, (x + e)[None, :])[0] - net.forward(theta, (x - e)[None, :])[0])
        assert grad[k] == pytest.approx(fd / (2 * h), rel=1e-6, abs=1e-9)


def _realisable_problem() -> tuple[Mlp, np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Data produced by a known network: the minimum (cost 0) is at theta_true."""
    net = Mlp((2, 4, 1))
    rng = np.random.default_rng(7)
    theta_true = net.init_params(rng)
    x = rng.random((80, 2))
    y = net.forward(theta_true, x)
    start = theta_true + 0.2 * rng.standard_normal(net.n_params)
    return net, theta_true, x, y, start


def test_lm_finds_a_known_minimum() -> None:
    net, theta_true, x, y, start = _realisable_problem()
    res = levenberg_marquardt(net, start, x, y, options=LmOptions(max_iterations=200))
    assert res.initial_cost > 1e-3
    assert res.cost < 1e-14 and res.stop in ("gradient", "mu_max", "cost_zero")
    np.testing.assert_allclose(net.forward(res.theta, x), y, atol=1e-8)
    np.testing.assert_allclose(res.theta, theta_true, atol=1e-5)  # the start's basin
    assert all(b <= a for a, b in zip(res.costs, res.costs[1:], strict=False))  # monotone


def test_lm_weights_zero_out_a_corrupted_sample() -> None:
    net, _, x, y, start = _realisable_problem()
    y_bad = y.copy()
    y_bad[3] += 10.0
    w = np.ones(len(y))
    w[3] = 0.0
    res = levenberg_marquardt(net, start, x, y_bad, w, LmOptions(max_iterations=200))
    np.testing.assert_allclose(np.delete(net.forward(res.theta, x) - y, 3), 0.0, atol=1e-7)


def test_lm_stopping_rules_and_progress() -> None:
    net, _, x, y, start = _realisable_problem()
    seen: list[int] = []
    capped = levenberg_marquardt(net, start, x, y, options=LmOptions(max_iterations=3),
                                 progress=lambda i, n: seen.append(i))
    assert capped.iterations == 3 and capped.stop == "max_iterations" and seen == [1, 2, 3]
    early = levenberg_marquardt(net, start, x, y, options=LmOptions(max_iterations=200, rtol=0.5))
    assert early.stop == "rtol" and early.iterations < 200
    untouched = start.copy()
    levenberg_marquardt(net, start, x, y)
    np.testing.assert_array_equal(start, untouched)  # theta0 is not modified


def test_lm_options_are_checked() -> None:
    with pytest.raises(UpdaterError, match="momentum"):
        LmOptions(momentum=1.5)
    with pytest.raises(UpdaterError, match="weights"):
        net, _, x, y, start = _realisable_problem()
        levenberg_marquardt(net, start, x, y, -np.ones(len(y)))
    assert dataclasses.replace(LmOptions(), rtol=0.1).rtol == 0.1


def test_jacobian_row_scale_is_the_scaled_jacobian() -> None:
    net = Mlp(PAPER_LAYERS)
    rng = np.random.default_rng(8)
    theta = net.init_params(rng)
    x = rng.random((7, 6))
    scale = rng.random(7) + 0.1
    _, jac = net.jacobian(theta, x)
    _, scaled = net.jacobian(theta, x, row_scale=scale)
    np.testing.assert_allclose(scaled, jac * scale[:, None], rtol=1e-12, atol=1e-15)
    with pytest.raises(UpdaterError, match="row_scale"):
        net.jacobian(theta, x, row_scale=scale[:3])


def test_lm_counts_its_factorisations() -> None:
    net, _, x, y, start = _realisable_problem()
    res = levenberg_marquardt(net, start, x, y, options=LmOptions(max_iterations=10))
    assert res.factorisations >= res.iterations == res.jacobians
