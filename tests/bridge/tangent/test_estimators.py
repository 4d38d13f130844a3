"""Tangent estimators on a bilinear specimen: each follows the specimen past yield where a
constant initial stiffness does not, refuses updates an integrator cannot use, and the site
answers action 13 with the estimate (an event when it refuses)."""

from __future__ import annotations

import math
import textwrap
from collections.abc import Callable

import numpy as np
import pytest

from fresco_bridge.daemon import BridgeThread
from fresco_bridge.integrator.link import GenericClientLink
from fresco_bridge.tangent import TangentEstimate, TangentMethod, broyden, unusable
from protocol import Action
from sim_actuator.models import Bilinear

K0, FY, ALPHA = 10.0, 5.0, 0.05


def loading(n: int = 40, peak: float = 2.0) -> list[float]:
    """Monotonic to ``peak`` (four times yield), then back."""
    up = [peak * (i + 1) / n for i in range(n)]
    return up + up[-2::-1]


def run(method: TangentMethod, path: list[float]) -> tuple[list[float], int]:
    """Committed (disp, force) along ``path``: the estimate after each, and the refusals."""
    spec, est = Bilinear(k0=K0, fy=FY, alpha=ALPHA), TangentEstimate(method, 1)
    est.answer((K0,))
    got, refused = [], 0
    for d in path:
        f, _ = spec.set_trial(d)
        spec.commit()
        refused += est.committed((d,), (f,)) is not None
        got.append(est.answer((K0,))[0])
    return got, refused


@pytest.mark.parametrize("method", ["broyden", "bfgs", "transpose"])
def test_each_estimator_follows_a_yielding_specimen(method: TangentMethod) -> None:
    got, refused = run(method, loading())
    assert refused == 0
    # past yield (steps 11..39 of the loading branch) the estimate is the post-yield secant
    for i in range(12, 39):
        assert got[i] == pytest.approx(ALPHA * K0, rel=1e-9)
    # after the reversal the specimen is elastic again, and the estimate with it
    assert got[45] == pytest.approx(K0, rel=1e-9)
    initial, _ = run("initial", loading())
    assert set(initial) == {K0}


def test_broyden_satisfies_the_secant_condition_in_several_dofs() -> None:
    rng = np.random.default_rng(1)
    k = np.diag([10.0, 20.0, 5.0])
    for _ in range(10):
        dd, df = rng.normal(size=3), rng.normal(size=3)
        k = broyden(k, dd, df)
        assert k @ dd == pytest.approx(df, rel=1e-12, abs=1e-12)


def test_an_update_that_opposes_the_motion_is_refused_and_the_estimate_kept() -> None:
    est = TangentEstimate("broyden", 1)
    est.answer((K0,))
    assert est.committed((0.0,), (0.0,)) is None
    assert est.committed((1.0,), (8.0,)) is None  # secant 8
    why = est.committed((2.0,), (7.0,))  # force falls as displacement grows: secant −1
    assert why is not None and "not positive definite" in why
    assert est.answer((K0,)) == (8.0,) and est.refusals == 1
    assert est.committed((2.0,), (math.nan,)) is not None  # a NaN force
    assert est.committed((2.0,), (7.0,)) is None  # no motion: nothing to learn
    assert unusable(np.array([[1.0, 0.0], [0.0, 1e-13]])) is not None  # singular


def test_transpose_needs_n_independent_increments() -> None:
    est = TangentEstimate("transpose", 2)
    est.answer((4.0, 0.0, 0.0, 4.0))
    assert est.committed((0.0, 0.0), (0.0, 0.0)) is None
    assert est.committed((1.0, 0.0), (3.0, 1.0)) is None
    assert est.answer((4.0, 0.0, 0.0, 4.0)) == (4.0, 0.0, 0.0, 4.0)  # one increment: initial
    assert est.committed((1.0, 1.0), (4.0, 3.0)) is None
    k = np.array(est.answer((4.0, 0.0, 0.0, 4.0))).reshape(2, 2, order="F")
    assert k @ [1.0, 0.0] == pytest.approx([3.0, 1.0]) and k @ [0.0, 1.0] == pytest.approx(
        [1.0, 2.0])


def test_the_site_answers_action_13_with_the_estimate(
        run_bridge: Callable[[str], BridgeThread]) -> None:
    config = textwrap.dedent(f"""
        [record]
        enabled = false
        [[sites]]
        name = "bilinear"
        port = 0
        tangent = "broyden"
        [sites.controller]
        kind = "sim"
        model = "bilinear"
        params = {{ k0 = {K0}, fy = {FY}, alpha = {ALPHA} }}
        """)
    bridge = run_bridge(config)
    spec = Bilinear(k0=K0, fy=FY, alpha=ALPHA)
    with GenericClientLink("127.0.0.1", bridge.ports["bilinear"], 1, timeout=20.0) as link:
        last, secant = (0.0, 0.0), K0
        for step, d in enumerate(loading(20), start=1):
            link.set_trial((d,), time=0.01 * step)
            f = link.force()[0]
            assert f == pytest.approx(spec.set_trial(d)[0])
            spec.commit()
            k = link.matrix(Action.GET_TANGENT_STIFF)[0][0]
            # the estimate answered during a step is built from the committed steps before it
            assert k == pytest.approx(K0 if step <= 2 else secant, rel=1e-9)
            link.commit()
            secant = (f - last[1]) / (d - last[0])
            last = (d, f)


def test_a_step_whose_newton_stops_contracting_is_answered_with_the_initial_stiffness() -> None:
    est = TangentEstimate("broyden", 1)
    est.answer((K0,))
    est.committed((0.0,), (0.0,))
    est.committed((1.0,), (1.0,))  # a soft secant: 1.0
    assert est.answer((K0,)) == (1.0,)
    assert est.trial((2.0,)) is None and est.trial((1.5,)) is None  # a predictor, a correction
    why = est.trial((2.0,))  # the correction did not shrink: a cycle
    assert why is not None and "stopped contracting" in why
    assert est.answer((K0,)) == (K0,) and est.trial((1.5,)) is None  # once per step
    est.committed((1.6,), (1.6,))  # the next step starts from the estimate again
    assert est.answer((K0,)) == (1.0,) and est.fallbacks == 1
    assert est.trial((1.7,)) is None and est.trial((1.65,)) is None \
        and est.trial((1.64,)) is None  # contracting: no fallback


def test_a_three_actuator_site_answers_a_secant_of_its_last_committed_step(
        run_bridge: Callable[[str], BridgeThread]) -> None:
    """Broyden in actuator space, mapped through the setup: the answered basic tangent maps
    the last committed trial increment onto the last out-force increment — or, when that
    update was refused (a rank-one update need not stay positive definite), it is the
    previous answer."""
    config = textwrap.dedent(f"""
        [record]
        enabled = false
        [[sites]]
        name = "column"
        port = 0
        dofs = 3
        tangent = "broyden"
        [sites.setup]
        kind = "ThreeActuators2d"
        La1 = 1000.0
        La2 = 900.0
        La3 = 800.0
        L1 = 500.0
        L2 = 400.0
        [sites.controller]
        kind = "sim"
        model = "bilinear"
        params = {{ k0 = {K0}, fy = {FY}, alpha = {ALPHA} }}
        """)
    bridge = run_bridge(config)
    rng = np.random.default_rng(4)
    with GenericClientLink("127.0.0.1", bridge.ports["column"], 3, timeout=20.0) as link:
        u = np.zeros(3)
        history: list[tuple[np.ndarray, np.ndarray]] = []
        previous, updated, refused = np.zeros((3, 3)), 0, 0
        for step in range(1, 16):
            u = u + rng.uniform(-0.3, 0.6, 3) * np.array([1.0, 1.0, 0.002])
            link.set_trial(tuple(u.tolist()), time=0.01 * step)
            q = np.array(link.force())
            k = np.array(link.matrix(Action.GET_TANGENT_STIFF))
            if len(history) >= 2:  # the estimate during this step: from the last two commits
                (u1, q1), (u2, q2) = history[-2:]
                if np.allclose(k @ (u2 - u1), q2 - q1, rtol=1e-9, atol=1e-9):
                    updated += 1
                else:
                    assert np.array_equal(k, previous)
                    refused += 1
            previous = k
            link.commit()
            history.append((u.copy(), q))
    assert updated >= 8, (updated, refused)  # most updates keep a positive definite matrix
