"""Explicit Newmark: closed-form SDOF checks, an exact MDOF reference, energy, stability, errors.

The hysteretic experimental forces here are tiny closures written for these tests; the real
models live in sim_actuator/models.
"""

from __future__ import annotations

import math
from collections.abc import Callable

import numpy as np
import pytest

from fresco_bridge.integrator import (
    ExplicitNewmark,
    GroundMotion,
    IntegrationError,
    ShearBuilding,
    UnstableTimeStepError,
    kanai_tajimi,
)

Closure = Callable[[int, float, np.ndarray], list[float]]


def elastic_perfectly_plastic(k: float, fy: float) -> tuple[Closure, dict[str, float]]:
    """EPP spring for one story; also counts the plastic work fy * sum |d(plastic drift)|."""
    state = {"x": 0.0, "f": 0.0, "plastic_work": 0.0}

    def force(step: int, time: float, drift: np.ndarray) -> list[float]:
        x = float(drift[0])
        trial = state["f"] + k * (x - state["x"])
        f = min(max(trial, -fy), fy)
        state["plastic_work"] += abs(trial - f) / k * fy
        state["x"], state["f"] = x, f
        return [f]

    return force, state


def elastic(k: float) -> Closure:
    return lambda step, time, drift: list(k * np.asarray(drift))


def free_vibration(omega: float, dt: float, steps: int, zeta: float = 0.0) -> ExplicitNewmark:
    m = 2.0
    return ExplicitNewmark(
        [[m]], [[2 * zeta * omega * m]], [[omega**2 * m]], dt, np.zeros(steps + 1),
        initial_displacement=[1.0],
    )  # fmt: skip


def test_undamped_sdof_follows_the_discrete_closed_form_exactly() -> None:
    omega, dt = 2 * np.pi, 0.02
    response = free_vibration(omega, dt, 500).run()
    big_omega = omega * dt
    omega_bar = 2 * math.asin(big_omega / 2)  # central-difference frequency per step
    expected = np.cos(np.arange(501) * omega_bar)
    np.testing.assert_allclose(response.displacement[:, 0], expected, atol=1e-11)
    # the velocity is the average-acceleration velocity of the same motion
    assert response.velocity[0, 0] == 0.0


def _measured_period(time: np.ndarray, x: np.ndarray) -> float:
    up = np.flatnonzero((x[:-1] < 0.0) & (x[1:] >= 0.0))
    crossings = time[up] - x[up] * (time[up + 1] - time[up]) / (x[up + 1] - x[up])
    return float((crossings[-1] - crossings[0]) / (len(crossings) - 1))


def test_period_error_is_second_order_in_dt() -> None:
    omega = 2 * np.pi  # T = 1 s
    errors = []
    for dt in (0.04, 0.02, 0.01):
        steps = round(60.0 / dt)
        r = free_vibration(omega, dt, steps).run()
        errors.append(abs(_measured_period(r.time, r.displacement[:, 0]) - 1.0))
        assert errors[-1] < 1.1 * (omega * dt) ** 2 / 24  # known leading term Omega^2/24
    assert errors[0] / errors[1] == pytest.approx(4.0, rel=0.1)
    assert errors[1] / errors[2] == pytest.approx(4.0, rel=0.1)


def test_damped_sdof_converges_to_the_analytic_free_vibration() -> None:
    omega, zeta = 2 * np.pi, 0.05
    omega_d = omega * math.sqrt(1 - zeta**2)
    max_errors = []
    for dt in (0.02, 0.01):
        r = free_vibration(omega, dt, round(5.0 / dt), zeta=zeta).run()
        t = r.time
        exact = np.exp(-zeta * omega * t) * (
            np.cos(omega_d * t) + zeta * omega / omega_d * np.sin(omega_d * t)
        )
        max_errors.append(float(np.max(np.abs(r.displacement[:, 0] - exact))))
    assert max_errors[1] < 0.01
    assert max_errors[0] / max_errors[1] == pytest.approx(4.0, rel=0.15)


def _expm(matrix: np.ndarray) -> np.ndarray:
    """Matrix exponential by scaling and squaring a Taylor series (independent of the code)."""
    norm = np.linalg.norm(matrix, 1)
    squarings = max(0, math.ceil(math.log2(norm)) + 4) if norm > 0 else 0
    scaled = matrix / 2**squarings
    result, term = np.eye(len(matrix)), np.eye(len(matrix))
    for k in range(1, 25):
        term = term @ scaled / k
        result = result + term
    for _ in range(squarings):
        result = result @ result
    return result


def exact_linear_response(
    mass: np.ndarray, damping: np.ndarray, stiffness: np.ndarray, ag: np.ndarray, dt: float
) -> np.ndarray:
    """Exact displacements for a ground acceleration linear between samples.

    State [d, v, ag, dag/dt] obeys a linear ODE over each step; its propagator is expm(A dt).
    """
    n = len(mass)
    m_inv = np.linalg.inv(mass)
    a = np.zeros((2 * n + 2, 2 * n + 2))
    a[:n, n : 2 * n] = np.eye(n)
    a[n : 2 * n, :n] = -m_inv @ stiffness
    a[n : 2 * n, n : 2 * n] = -m_inv @ damping
    a[n : 2 * n, 2 * n] = -np.ones(n)
    a[2 * n, 2 * n + 1] = 1.0
    propagator = _expm(a * dt)
    out = np.zeros((ag.size, n))
    state = np.zeros(2 * n + 2)
    for i in range(ag.size - 1):
        state[2 * n] = ag[i]
        state[2 * n + 1] = (ag[i + 1] - ag[i]) / dt
        state = propagator @ state
        out[i + 1] = state[:n]
    return out


def test_linear_mdof_with_elastic_experimental_story_matches_exact_solution() -> None:
    frame = ShearBuilding(masses=[0.0202228] * 2, story_stiffness=[10.0, 10.0])
    k_damper = 8.0
    extra = [k_damper, 0.0]
    _, _, damping = frame.rayleigh(0.05, (1, 2), extra_story_stiffness=extra)
    record = kanai_tajimi(3.0, duration=10.0, dt=0.01, seed=2)
    reference = exact_linear_response(
        frame.mass_matrix(), damping, frame.stiffness_matrix(extra), record.accel_mm_s2, 0.01
    )
    peak = np.max(np.abs(reference))
    errors = []
    for dt in (0.01, 0.005):
        integ = ExplicitNewmark(
            frame.mass_matrix(), damping, frame.stiffness_matrix(), dt, record.resampled(dt),
            elastic(k_damper), [0],
        )  # fmt: skip
        d = integ.run().displacement[:: round(0.01 / dt)]
        errors.append(float(np.max(np.abs(d - reference))) / peak)
    assert errors[0] < 0.02
    assert errors[0] / errors[1] == pytest.approx(4.0, rel=0.2)


def test_energy_balance_with_elastic_perfectly_plastic_story() -> None:
    frame = ShearBuilding(masses=[0.0202228] * 2, story_stiffness=[10.0, 10.0])
    k0, fy = 8.0, 12.0
    _, _, damping = frame.rayleigh(0.05, (1, 2), extra_story_stiffness=[k0, 0.0])
    force, state = elastic_perfectly_plastic(k0, fy)
    integ = ExplicitNewmark(
        frame.mass_matrix(), damping, frame.stiffness_matrix(), 0.01, kanai_tajimi(3.0), force,
        [0], experimental_stiffness=[k0],
    )  # fmt: skip
    response = integ.run()
    energy = integ.energy_balance()
    assert np.max(np.abs(response.drift[:, 0])) > 3 * fy / k0  # it really yielded
    assert energy.relative_error() < 0.01
    # work on the specimen = plastic dissipation + what it still stores elastically
    stored = response.experimental_force[-1, 0] ** 2 / (2 * k0)
    assert energy.experimental[-1] == pytest.approx(state["plastic_work"] + stored, rel=0.02)
    assert energy.experimental[-1] > 0.2 * energy.input[-1]  # the damper matters
    assert np.all(np.diff(energy.damping) >= -1e-12)  # viscous work never decreases


def test_stability_limit_is_checked_and_real() -> None:
    m, k = 0.5, 200.0
    omega = math.sqrt(k / m)
    dt_cr = 2 / omega
    ok = ExplicitNewmark([[m]], [[0.0]], [[k]], 0.99 * dt_cr, np.zeros(3))
    assert ok.critical_dt() == pytest.approx(dt_cr, rel=1e-12)
    with pytest.raises(UnstableTimeStepError, match=r"dt=0\.101 s >= critical dt .*0\.1 s") as info:
        ExplicitNewmark([[m]], [[0.0]], [[k]], 0.101, np.zeros(3))
    assert info.value.critical_dt == pytest.approx(0.1)
    # the experimental element's initial stiffness is part of the check
    with pytest.raises(UnstableTimeStepError, match="omega_max="):
        ExplicitNewmark([[m]], [[0.0]], [[k]], 0.08, np.zeros(3), elastic(150.0), [0],
                        experimental_stiffness=[150.0])  # fmt: skip
    # undeclared, the same stiffness makes the run blow up: the limit is the real one
    hidden = ExplicitNewmark([[m]], [[0.0]], [[k]], 0.08, np.zeros(3001), elastic(150.0), [0],
                             initial_displacement=[1.0])  # fmt: skip
    with pytest.raises(IntegrationError, match="non-finite"):
        hidden.run()
    assert hidden.current_step > 100
    assert np.max(np.abs(hidden.response().displacement)) > 1e100


def test_callable_exception_is_wrapped_with_the_step_and_state_is_kept() -> None:
    boom = OSError("actuator interlock")
    calls: list[int] = []

    def flaky(step: int, time: float, drift: np.ndarray) -> list[float]:
        calls.append(step)
        if step == 3 and calls.count(3) == 1:
            raise boom
        return [5.0 * float(drift[0])]

    frame = ShearBuilding(masses=[1.0, 1.0], story_stiffness=[100.0, 100.0])
    integ = ExplicitNewmark(frame.mass_matrix(), np.zeros((2, 2)), frame.stiffness_matrix(),
                            0.01, np.ones(11), flaky, [1])  # fmt: skip
    integ.run(2)
    with pytest.raises(IntegrationError, match=r"step 3: .*OSError.*actuator interlock") as info:
        integ.step()
    assert info.value.__cause__ is boom and info.value.step == 3
    assert integ.current_step == 2
    assert integ.step().step == 3  # retrying the same trial works
    assert calls == [0, 1, 2, 3, 3]


def test_bad_forces_from_the_callable_are_rejected() -> None:
    integ = ExplicitNewmark([[1.0]], [[0.0]], [[1.0]], 0.01, np.ones(5),
                            lambda s, t, d: [1.0, 2.0], [0])  # fmt: skip
    with pytest.raises(IntegrationError, match=r"step 0: expected 1 experimental force"):
        integ.step()
    integ = ExplicitNewmark([[1.0]], [[0.0]], [[1.0]], 0.01, np.ones(5),
                            lambda s, t, d: [math.inf], [0])  # fmt: skip
    with pytest.raises(IntegrationError, match="not finite"):
        integ.step()


def test_trial_commit_matches_step_and_run_reports_progress() -> None:
    frame = ShearBuilding(masses=[0.02, 0.02], story_stiffness=[10.0, 10.0])
    _, _, damping = frame.rayleigh(0.05)
    record = kanai_tajimi(3.0, duration=2.0)
    args = (frame.mass_matrix(), damping, frame.stiffness_matrix(), 0.01, record)
    force_a, _ = elastic_perfectly_plastic(8.0, 1.0)
    force_b, _ = elastic_perfectly_plastic(8.0, 1.0)
    by_run = ExplicitNewmark(*args, force_a, [0])
    seen: list[tuple[int, int]] = []
    by_run.run(50, progress=lambda done, total: seen.append((done, total)))
    assert seen[0] == (1, 50) and seen[-1] == (50, 50) and len(seen) == 50
    by_run.run()
    assert by_run.done and by_run.current_step == record.npts - 1

    manual = ExplicitNewmark(*args, force_b, [0])
    while not manual.done:
        trial = manual.trial()
        assert manual.trial() is trial  # idempotent until committed
        manual.commit(force_b(trial.step, trial.time, np.asarray(trial.drift)))
    a, b = by_run.response(), manual.response()
    np.testing.assert_array_equal(a.displacement, b.displacement)
    np.testing.assert_array_equal(a.experimental_force, b.experimental_force)
    np.testing.assert_allclose(a.drift, frame.floor_to_drifts(a.displacement))
    np.testing.assert_allclose(a.experimental_drift[:, 0], a.drift[:, 0])
    np.testing.assert_allclose(a.time[-1], record.duration)
    with pytest.raises(IntegrationError, match="record ends at step 200"):
        manual.trial()
    with pytest.raises(ValueError, match=r"outside 0\.\.0"):
        manual.run(1)


def test_equation_of_motion_holds_at_every_step() -> None:
    frame = ShearBuilding(masses=[0.02, 0.03], story_stiffness=[10.0, 6.0])
    _, _, damping = frame.rayleigh(0.05)
    force, _ = elastic_perfectly_plastic(8.0, 2.0)
    integ = ExplicitNewmark(frame.mass_matrix(), damping, frame.stiffness_matrix(), 0.01,
                            kanai_tajimi(3.0, duration=3.0), force, [0])  # fmt: skip
    r = integ.run()
    resisting = r.displacement @ frame.stiffness_matrix().T
    resisting[:, 0] += r.experimental_force[:, 0]
    # the story-1 element acts on floor 1 and the ground only: M a + C v + r = -M 1 ag
    residual = (
        r.acceleration @ frame.mass_matrix().T + r.velocity @ damping.T + resisting
        + np.outer(r.ground_accel, frame.masses)
    )  # fmt: skip
    assert np.max(np.abs(residual)) < 1e-9 * np.max(np.abs(np.outer(r.ground_accel, frame.masses)))
    # the update formulas of the scheme
    dt = 0.01
    np.testing.assert_allclose(
        r.displacement[1:],
        r.displacement[:-1] + dt * r.velocity[:-1] + dt**2 / 2 * r.acceleration[:-1],
    )
    np.testing.assert_allclose(
        r.velocity[1:], r.velocity[:-1] + dt / 2 * (r.acceleration[:-1] + r.acceleration[1:])
    )


def test_input_validation() -> None:
    with pytest.raises(ValueError, match=r"damping must be 2x2 like the mass matrix"):
        ExplicitNewmark(np.eye(2), np.eye(3), np.eye(2), 0.01, np.zeros(3))
    with pytest.raises(ValueError, match="dt must be a finite number > 0"):
        ExplicitNewmark(np.eye(1), np.eye(1), np.eye(1), 0.0, np.zeros(3))
    with pytest.raises(ValueError, match="need an experimental_force"):
        ExplicitNewmark(np.eye(1), np.eye(1), np.eye(1), 0.01, np.zeros(3), None, [0])
    with pytest.raises(ValueError, match=r"story index 2 is not in 0\.\.1"):
        ExplicitNewmark(np.eye(2), np.eye(2), np.eye(2), 0.01, np.zeros(3), elastic(1.0), [2])
    with pytest.raises(ValueError, match="mass matrix is not symmetric positive definite"):
        ExplicitNewmark(-np.eye(1), np.eye(1), np.eye(1), 0.01, np.zeros(3))
    record = GroundMotion(dt=0.02, accel=np.zeros(5), name="coarse", source="test")
    with pytest.raises(ValueError, match=r"dt=0\.02 s but the integrator dt is 0\.01 s"):
        ExplicitNewmark(np.eye(1), np.eye(1), np.eye(1), 0.01, record)
    with pytest.raises(ValueError, match="non-finite value at index 1"):
        ExplicitNewmark(np.eye(1), np.eye(1), np.eye(1), 0.01, np.array([0.0, np.nan]))
