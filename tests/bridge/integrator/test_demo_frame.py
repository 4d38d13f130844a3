"""The paper's two-story demo frame: realistic periods, a yielding damper, a stable time step.

The bilinear damper force is a tiny closure written for this test; the real hysteresis models
live in sim_actuator/models.
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np
import pytest

from fresco_bridge.integrator import (
    DEMO_DAMPER,
    DEMO_DT,
    DEMO_EXPERIMENTAL_STORIES,
    DEMO_ZETA,
    demo_damper_story_stiffness,
    demo_ground_motion,
    demo_integrator,
    paper_two_story_frame,
)


def bilinear_kinematic(
    k0: float, fy: float, alpha: float
) -> Callable[[int, float, np.ndarray], list[float]]:
    """Bilinear spring with kinematic hardening between the lines +-fy + alpha k0 (x -+ fy/k0)."""
    state = {"x": 0.0, "f": 0.0}
    kh = alpha * k0

    def force(step: int, time: float, drift: np.ndarray) -> list[float]:
        x = float(drift[0])
        trial = state["f"] + k0 * (x - state["x"])
        upper = fy + kh * (x - fy / k0)
        lower = -fy + kh * (x + fy / k0)
        state["x"], state["f"] = x, min(max(trial, lower), upper)
        return [state["f"]]

    return force


def test_demo_frame_matches_the_paper_and_has_realistic_periods() -> None:
    frame = paper_two_story_frame()
    assert frame.n_stories == 2
    np.testing.assert_allclose(frame.masses, [0.0202228, 0.0202228])  # 20222.8 kg in kN s^2/mm
    bare = frame.modes()
    with_damper = frame.modes(demo_damper_story_stiffness())
    assert 0.3 <= with_damper.period[0] <= 0.5
    assert 0.3 <= bare.period[0] <= 0.5
    assert with_damper.period[0] < bare.period[0]  # the damper stiffens story 1
    assert DEMO_DAMPER["model"] == "bilinear"
    assert DEMO_EXPERIMENTAL_STORIES == (0,)


def test_demo_run_yields_the_damper_and_is_stable_with_margin() -> None:
    k0, fy, alpha = (float(DEMO_DAMPER[key]) for key in ("k0", "fy", "alpha"))
    integ = demo_integrator(bilinear_kinematic(k0, fy, alpha))
    assert integ.dt == DEMO_DT
    assert integ.dt <= 0.5 * integ.critical_dt()
    response = integ.run()
    assert response.time[-1] == pytest.approx(20.0)
    peak_drift = float(np.max(np.abs(response.experimental_drift[:, 0])))
    assert peak_drift >= 3 * fy / k0
    assert peak_drift < 0.02 * 2000.0  # under 2 % of the 2 m story height
    peak_force = float(np.max(np.abs(response.experimental_force)))
    assert 12.0 < peak_force < 25.0  # the paper measured 13.8-19.2 kN
    assert integ.energy_balance().relative_error() < 0.01
    assert np.max(np.abs(response.ground_accel)) == pytest.approx(3000.0)  # mm/s^2


def test_demo_damping_is_five_percent_in_both_modes() -> None:
    integ = demo_integrator(lambda step, time, drift: [0.0])
    frame = paper_two_story_frame()
    modes = frame.modes(demo_damper_story_stiffness())
    ratios = np.diag(modes.shapes.T @ integ.damping @ modes.shapes) / (2 * modes.omega)
    np.testing.assert_allclose(ratios, [DEMO_ZETA, DEMO_ZETA])


def test_demo_ground_motion_is_resampled_when_needed() -> None:
    record = demo_ground_motion(seed=1).resampled(0.005)
    integ = demo_integrator(lambda step, time, drift: [0.0], record)
    assert integ.n_steps == 2000
