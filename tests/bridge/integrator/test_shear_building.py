"""Shear building: matrices, modes against closed forms, Rayleigh damping, drift conventions."""

from __future__ import annotations

import math

import numpy as np
import pytest

from fresco_bridge.integrator.shear_building import ShearBuilding, drift_matrix


def test_two_equal_stories_match_closed_form_modes() -> None:
    m, k = 0.0202228, 10.0
    building = ShearBuilding(masses=[m, m], story_stiffness=[k, k])
    modes = building.modes()
    expected = np.sqrt(np.array([(3 - math.sqrt(5)) / 2, (3 + math.sqrt(5)) / 2]) * k / m)
    np.testing.assert_allclose(modes.omega, expected, rtol=1e-12)
    np.testing.assert_allclose(modes.period, 2 * np.pi / expected, rtol=1e-12)
    # shape ratios roof/first floor: golden ratio and its conjugate
    ratios = modes.shapes[1] / modes.shapes[0]
    np.testing.assert_allclose(ratios, [(1 + math.sqrt(5)) / 2, (1 - math.sqrt(5)) / 2])
    mass = building.mass_matrix()
    np.testing.assert_allclose(modes.shapes.T @ mass @ modes.shapes, np.eye(2), atol=1e-12)
    stiffness = building.stiffness_matrix()
    np.testing.assert_allclose(
        modes.shapes.T @ stiffness @ modes.shapes, np.diag(expected**2), rtol=1e-10, atol=1e-9
    )
    # participating masses add up to the total mass
    assert np.sum(modes.participation**2) == pytest.approx(2 * m, rel=1e-12)


def test_stiffness_matrix_by_hand_with_extra_story_stiffness() -> None:
    building = ShearBuilding(masses=[1.0, 2.0, 3.0], story_stiffness=[5.0, 4.0, 3.0])
    k1, k2, k3 = 5.0 + 8.0, 4.0, 3.0
    expected = np.array([[k1 + k2, -k2, 0.0], [-k2, k2 + k3, -k3], [0.0, -k3, k3]])
    np.testing.assert_array_equal(building.stiffness_matrix([8.0, 0.0, 0.0]), expected)
    np.testing.assert_array_equal(building.mass_matrix(), np.diag([1.0, 2.0, 3.0]))
    with pytest.raises(ValueError, match="extra_story_stiffness needs 3 values"):
        building.stiffness_matrix([1.0])


def _modal_damping_ratios(building: ShearBuilding, damping: np.ndarray, extra=None) -> np.ndarray:
    modes = building.modes(extra)
    generalized = modes.shapes.T @ damping @ modes.shapes
    return np.diag(generalized) / (2 * modes.omega)


def test_rayleigh_gives_exactly_the_target_ratio_in_the_two_modes() -> None:
    building = ShearBuilding(masses=[0.0202228] * 2, story_stiffness=[10.0, 10.0])
    extra = [8.0, 0.0]
    alpha, beta, damping = building.rayleigh(0.05, (1, 2), extra_story_stiffness=extra)
    np.testing.assert_allclose(_modal_damping_ratios(building, damping, extra), [0.05, 0.05])
    np.testing.assert_allclose(
        damping, alpha * building.mass_matrix() + beta * building.stiffness_matrix(extra)
    )
    # the modes stay uncoupled by classical damping
    modes = building.modes(extra)
    off = modes.shapes.T @ damping @ modes.shapes
    assert abs(off[0, 1]) < 1e-12 * abs(off[0, 0])


def test_rayleigh_on_modes_1_and_3_under_damps_mode_2() -> None:
    building = ShearBuilding(masses=[1.0, 1.0, 1.0], story_stiffness=[300.0, 200.0, 100.0])
    _, _, damping = building.rayleigh(0.03, (1, 3))
    ratios = _modal_damping_ratios(building, damping)
    np.testing.assert_allclose(ratios[[0, 2]], [0.03, 0.03], rtol=1e-12)
    assert ratios[1] < 0.03


def test_rayleigh_rejects_bad_modes() -> None:
    building = ShearBuilding(masses=[1.0, 1.0], story_stiffness=[1.0, 1.0])
    with pytest.raises(ValueError, match=r"two distinct modes in 1\.\.2"):
        building.rayleigh(0.05, (1, 3))
    with pytest.raises(ValueError, match="two distinct modes"):
        building.rayleigh(0.05, (2, 2))


def test_drift_and_force_conventions_are_adjoint() -> None:
    building = ShearBuilding(masses=[1.0, 1.0, 1.0], story_stiffness=[1.0, 1.0, 1.0])
    u = np.array([1.0, 3.0, 2.5])
    np.testing.assert_array_equal(building.floor_to_drifts(u), [1.0, 2.0, -0.5])
    f = np.array([10.0, 4.0, 1.0])
    # story i pushes floor i-1 by +f_i and floor i by -f_i; resisting force is the opposite
    np.testing.assert_array_equal(building.story_forces_to_floor(f), [6.0, 3.0, 1.0])
    rng = np.random.default_rng(1)
    for _ in range(5):
        uu, ff = rng.normal(size=3), rng.normal(size=3)
        # virtual work: story forces on drifts equal floor forces on displacements
        assert ff @ building.floor_to_drifts(uu) == pytest.approx(
            building.story_forces_to_floor(ff) @ uu
        )
    history = rng.normal(size=(7, 3))
    np.testing.assert_allclose(
        building.floor_to_drifts(history)[4], history[4] - [0, *history[4, :2]]
    )
    # elastic story springs: T^T (k * drift) is the stiffness matrix times u
    np.testing.assert_allclose(
        building.story_forces_to_floor(building.story_stiffness * building.floor_to_drifts(u)),
        building.stiffness_matrix() @ u,
    )


def test_drift_matrix_rows_and_errors() -> None:
    np.testing.assert_array_equal(drift_matrix(3, [2, 0]), [[0, -1, 1], [1, 0, 0]])
    with pytest.raises(ValueError, match=r"story index 3 is not in 0\.\.2"):
        drift_matrix(3, [3])
    with pytest.raises(ValueError, match="distinct"):
        drift_matrix(3, [1, 1])


@pytest.mark.parametrize(
    ("masses", "stiffness", "pattern"),
    [
        ([1.0, 1.0], [1.0], "1 values but there are 2 floor masses"),
        ([1.0, -1.0], [1.0, 1.0], "mass of floor 1 must be finite and > 0"),
        ([1.0, 1.0], [1.0, math.nan], "stiffness of story 1"),
        ([], [], "non-empty"),
    ],
)
def test_invalid_buildings(masses: list[float], stiffness: list[float], pattern: str) -> None:
    with pytest.raises(ValueError, match=pattern):
        ShearBuilding(masses=masses, story_stiffness=stiffness)
