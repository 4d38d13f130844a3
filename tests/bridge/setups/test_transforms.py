"""Setup transforms: identity costs nothing, any other T is one BLAS product.

``Tᵀ k T`` on every stiffness request as a pure-Python O(n³) loop would dominate a 64-DOF step
(BENCHMARKS.md, "Multi-DOF elements"): the identity passes values through untouched and a
general T goes through numpy. Both are checked against the explicit sum, and a 64-DOF element
is served end to end.
"""

from __future__ import annotations

import math
import random
import textwrap
from collections.abc import Callable

import pytest

from fresco_bridge.controls.base import diagonal
from fresco_bridge.daemon import BridgeThread
from fresco_bridge.integrator.link import GenericClientLink
from fresco_bridge.setups import LinearSetup, make_setup
from protocol import Action


def explicit_basic_matrix(setup: LinearSetup, k: tuple[float, ...]) -> list[float]:
    """(Tᵀ k T)[r][c] = Σ_a Σ_b T[a][r] k[a][b] T[b][c], k and result column-major."""
    na, nb, t = setup.n_actuators, setup.n_basic, setup.t
    return [sum(t[a][r] * k[b * na + a] * t[b][c] for a in range(na) for b in range(na))
            for c in range(nb) for r in range(nb)]


@pytest.mark.parametrize("n", [1, 2, 7, 64])
def test_no_transformation_passes_every_signal_through_untouched(n: int) -> None:
    setup = make_setup("NoTransformation", n)
    rng = random.Random(n)
    u = tuple(rng.uniform(-5, 5) for _ in range(n))
    k = tuple(rng.uniform(-5, 5) for _ in range(n * n))
    assert setup.identity
    assert setup.ctrl_disp(u) is u and setup.basic_force(u) is u
    assert setup.basic_matrix(k) is k
    assert setup.out_disp(u, u, u) is u


def test_one_actuator_two_nodes_matches_the_explicit_transform() -> None:
    setup = make_setup("OneActuator", 2)
    assert not setup.identity
    assert setup.ctrl_disp((1.5, 4.0)) == (2.5,)
    assert setup.basic_force((3.0,)) == (-3.0, 3.0)
    assert setup.basic_matrix((8.0,)) == (8.0, -8.0, -8.0, 8.0)
    # the stroke error goes back along the actuator: trial + T⁺ (daq − ctrl)
    assert setup.out_disp((1.0, 3.0), (2.0,), (2.5,)) == (0.75, 3.25)


def test_a_general_transform_equals_the_explicit_sum() -> None:
    rng = random.Random(3)
    t = tuple(tuple(rng.uniform(-2, 2) for _ in range(5)) for _ in range(3))
    setup = LinearSetup("OneActuator", 5, 3, t)  # any T: the kind only names the geometry
    k = tuple(rng.uniform(-10, 10) for _ in range(9))
    got = setup.basic_matrix(k)
    want = explicit_basic_matrix(setup, k)
    assert len(got) == 25
    assert all(math.isclose(g, w, rel_tol=1e-12, abs_tol=1e-12) for g, w in zip(got, want,
                                                                                strict=True))


def test_the_sim_controller_diagonal_is_column_major() -> None:
    assert diagonal((1.0, 2.0, 3.0)) == (1.0, 0, 0, 0, 2.0, 0, 0, 0, 3.0)


def test_a_64_dof_element_is_served_end_to_end(
        run_bridge: Callable[[str], BridgeThread]) -> None:
    n = 64
    config = textwrap.dedent(f"""
        [record]
        enabled = false
        [[sites]]
        name = "wall"
        port = 0
        dofs = {n}
        [sites.controller]
        kind = "sim"
        model = "elastic"
        params = {{ k = 50.0 }}
        """)
    bridge = run_bridge(config)
    with GenericClientLink("127.0.0.1", bridge.ports["wall"], n, timeout=20.0) as link:
        for step in range(3):
            d = tuple(0.01 * (i + 1) * (step + 1) for i in range(n))
            link.set_trial(d, time=0.01 * (step + 1))
            assert link.force() == pytest.approx(tuple(50.0 * x for x in d))
            k = link.matrix(Action.GET_TANGENT_STIFF)
            assert all(k[r][c] == (50.0 if r == c else 0.0) for r in range(n) for c in range(n))
            link.commit()
