"""Explicit Newmark (beta = 0, gamma = 1/2) for pseudo-dynamic tests of a shear building.

The scheme of the source paper and the usual one for pseudo-dynamic testing: the displacement of
step n+1 is known before the restoring force is, so it can be imposed on the specimen and the
measured force fed back, with no iteration and no tangent stiffness of the specimen needed.

Per step (``T`` holds the drift rows of the experimental stories, ``i`` the influence vector)::

    d[n+1] = d[n] + dt v[n] + dt^2/2 a[n]                      (trial: sent to the specimen)
    r      = K_lin d[n+1] + T^T f_exp(T d[n+1])                (out: measured forces)
    (M + gamma dt C) a[n+1] = -M i ag[n+1] - r - C (v[n] + (1 - gamma) dt a[n])
    v[n+1] = v[n] + dt ((1 - gamma) a[n] + gamma a[n+1])

Step 0 asks the specimen for its force at the initial drift too, and solves M a[0] = -M i ag[0]
- C v[0] - r[0]. The scheme is conditionally stable: dt * omega_max < 2 (for gamma = 1/2 this
holds with any viscous damping).

Two ways to drive it: :meth:`ExplicitNewmark.step`/:meth:`~ExplicitNewmark.run` call the
``experimental_force`` callable; :meth:`~ExplicitNewmark.trial` then
:meth:`~ExplicitNewmark.commit` let an asyncio caller await the specimen between the two.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass

import numpy as np
import numpy.typing as npt

from fresco_bridge.integrator.ground_motion import GroundMotion
from fresco_bridge.integrator.shear_building import drift_matrix, generalized_eigen

__all__ = [
    "EnergyBalance",
    "ExperimentalForce",
    "ExplicitNewmark",
    "IntegrationError",
    "Response",
    "StepState",
    "TrialStep",
    "UnstableTimeStepError",
]

FloatArray = npt.NDArray[np.float64]
ExperimentalForce = Callable[[int, float, FloatArray], npt.ArrayLike]
"""``(step, time, trial drifts of the experimental stories) -> their restoring forces``."""


class IntegrationError(RuntimeError):
    """A step could not be completed; ``step`` is the index of the step being computed.

    When the experimental-force callable raised, its exception is the ``__cause__``, unchanged.
    """

    def __init__(self, step: int, message: str) -> None:
        super().__init__(f"step {step}: {message}")
        self.step = step


class UnstableTimeStepError(ValueError):
    """dt is at or above the explicit Newmark stability limit 2 / omega_max."""

    def __init__(self, dt: float, critical_dt: float, omega_max: float) -> None:
        super().__init__(
            f"explicit Newmark is unstable: dt={dt:g} s >= critical dt 2/omega_max="
            f"{critical_dt:.6g} s (omega_max={omega_max:.6g} rad/s, dt*omega_max="
            f"{dt * omega_max:.4g} > 2); reduce dt or check the stiffness"
        )
        self.dt = dt
        self.critical_dt = critical_dt
        self.omega_max = omega_max


@dataclass(frozen=True, eq=False)
class TrialStep:
    """The next displacement to impose: floor ``displacement`` and experimental ``drift``."""

    step: int
    time: float
    displacement: FloatArray
    drift: FloatArray


@dataclass(frozen=True, eq=False)
class StepState:
    """The committed state of one step (relative displacement, velocity, acceleration)."""

    step: int
    time: float
    displacement: FloatArray
    velocity: FloatArray
    acceleration: FloatArray
    experimental_force: FloatArray


@dataclass(frozen=True, eq=False)
class Response:
    """Histories from step 0 to the last committed step; rows are steps.

    ``drift`` holds every story's drift; ``experimental_drift``/``experimental_force`` only the
    experimental stories (in the order of ``experimental_stories``).
    """

    time: FloatArray
    displacement: FloatArray
    velocity: FloatArray
    acceleration: FloatArray
    drift: FloatArray
    experimental_drift: FloatArray
    experimental_force: FloatArray
    ground_accel: FloatArray
    experimental_stories: tuple[int, ...]
    influence: FloatArray



@dataclass(frozen=True, eq=False)
class EnergyBalance:
    """Cumulative energies (kN*mm with the default units) from step 0, relative-motion form.

    ``experimental`` is the work done on the experimental elements (their stored plus
    dissipated energy); ``damping`` the viscous work; ``error`` what the balance misses.
    """

    time: FloatArray
    input: FloatArray
    kinetic: FloatArray
    elastic: FloatArray
    damping: FloatArray
    experimental: FloatArray

    @property
    def error(self) -> FloatArray:
        stored = self.kinetic + self.elastic + self.damping + self.experimental
        return np.asarray(self.input - stored)

    def relative_error(self) -> float:
        """max |error| over max |input| (0 when there was no input)."""
        peak = float(np.max(np.abs(self.input)))
        return 0.0 if peak == 0.0 else float(np.max(np.abs(self.error)) / peak)


def _square(name: str, value: npt.ArrayLike, n: int | None) -> FloatArray:
    arr = np.array(value, dtype=np.float64, ndmin=2)
    if arr.ndim != 2 or arr.shape[0] != arr.shape[1]:
        raise ValueError(f"{name} must be a square matrix, got shape {arr.shape}")
    if n is not None and arr.shape[0] != n:
        raise ValueError(f"{name} must be {n}x{n} like the mass matrix, got shape {arr.shape}")
    if not np.all(np.isfinite(arr)):
        raise ValueError(f"{name} has non-finite entries")
    return arr


def _vector(name: str, value: npt.ArrayLike | None, n: int, default: float) -> FloatArray:
    if value is None:
        return np.full(n, default)
    arr = np.array(value, dtype=np.float64, ndmin=1)
    if arr.shape != (n,):
        raise ValueError(f"{name} must have {n} values, got shape {arr.shape}")
    if not np.all(np.isfinite(arr)):
        raise ValueError(f"{name} has non-finite entries: {arr}")
    return arr


class ExplicitNewmark:
    """Explicit Newmark integrator with experimental story elements in the loop.

    ``mass``, ``damping`` and ``stiffness`` (the linear, non-updated numerical part) are
    ``n x n`` over the floor DOFs of a shear building, bottom floor first, so that story ``i``
    (0-based) joins floor ``i - 1`` (ground) and floor ``i``. ``ground_accel[n]`` is the ground
    acceleration at ``n * dt`` in units consistent with the mass (mm/s^2 for kN*s^2/mm); a
    :class:`GroundMotion` is converted with ``accel_mm_s2`` and must have the same dt.
    ``experimental_stiffness`` (initial stiffness estimates of the experimental elements) only
    enters the stability check; without it the check sees ``stiffness`` alone.
    """

    GAMMA = 0.5

    def __init__(
        self,
        mass: npt.ArrayLike,
        damping: npt.ArrayLike,
        stiffness: npt.ArrayLike,
        dt: float,
        ground_accel: npt.ArrayLike | GroundMotion,
        experimental_force: ExperimentalForce | None = None,
        experimental_stories: Sequence[int] = (),
        *,
        influence: npt.ArrayLike | None = None,
        experimental_stiffness: Sequence[float] | None = None,
        initial_displacement: npt.ArrayLike | None = None,
        initial_velocity: npt.ArrayLike | None = None,
    ) -> None:
        if not (isinstance(dt, int | float) and math.isfinite(dt) and dt > 0.0):
            raise ValueError(f"dt must be a finite number > 0, got {dt!r}")
        self.dt = float(dt)
        self.mass = _square("mass", mass, None)
        n = self.mass.shape[0]
        self.damping = _square("damping", damping, n)
        self.stiffness = _square("stiffness", stiffness, n)
        self.influence = _vector("influence", influence, n, 1.0)
        self.ground_accel = self._ground_accel(ground_accel)

        self.experimental_stories = tuple(int(s) for s in experimental_stories)
        self._t_exp = drift_matrix(n, self.experimental_stories)
        self._t_all = drift_matrix(n)
        n_exp = len(self.experimental_stories)
        if n_exp and experimental_force is None:
            raise ValueError(
                f"experimental stories {self.experimental_stories} need an experimental_force"
            )
        self._experimental_force = experimental_force
        self._k_exp = _vector("experimental_stiffness", experimental_stiffness, n_exp, 0.0)
        if np.any(self._k_exp < 0.0):
            raise ValueError(f"experimental_stiffness must be >= 0, got {self._k_exp}")

        eigenvalues, _ = generalized_eigen(self._stability_stiffness(), self.mass)
        self._omega_max = math.sqrt(max(float(eigenvalues[-1]), 0.0))
        if self.dt >= self.critical_dt():
            raise UnstableTimeStepError(self.dt, self.critical_dt(), self._omega_max)

        self._m_eff = self.mass + self.GAMMA * self.dt * self.damping
        steps = self.ground_accel.size
        self._d = np.zeros((steps, n))
        self._v = np.zeros((steps, n))
        self._a = np.zeros((steps, n))
        self._f = np.zeros((steps, n_exp))
        self._d[0] = _vector("initial_displacement", initial_displacement, n, 0.0)
        self._v[0] = _vector("initial_velocity", initial_velocity, n, 0.0)
        self._current = -1  # last committed step; -1 until step 0 has its force
        self._pending: TrialStep | None = None

    def _ground_accel(self, ground_accel: npt.ArrayLike | GroundMotion) -> FloatArray:
        if isinstance(ground_accel, GroundMotion):
            if not math.isclose(ground_accel.dt, self.dt, rel_tol=1e-9):
                raise ValueError(
                    f"ground motion {ground_accel.name!r} has dt={ground_accel.dt:g} s but the "
                    f"integrator dt is {self.dt:g} s; use GroundMotion.resampled({self.dt:g})"
                )
            arr = np.array(ground_accel.accel_mm_s2, dtype=np.float64)
        else:
            arr = np.array(ground_accel, dtype=np.float64)
        if arr.ndim != 1 or arr.size < 2:
            raise ValueError(f"ground_accel must be 1-D with >= 2 samples, got shape {arr.shape}")
        bad = np.flatnonzero(~np.isfinite(arr))
        if bad.size:
            raise ValueError(f"ground_accel has a non-finite value at index {bad[0]}")
        return arr

    def _stability_stiffness(self) -> FloatArray:
        return np.asarray(self.stiffness + self._t_exp.T @ np.diag(self._k_exp) @ self._t_exp)

    # -- properties ---------------------------------------------------------------------------

    @property
    def n_dof(self) -> int:
        return int(self.mass.shape[0])

    @property
    def n_steps(self) -> int:
        """Time steps in the record (its samples minus the initial one)."""
        return int(self.ground_accel.size - 1)

    @property
    def current_step(self) -> int:
        """Index of the last committed step, -1 before step 0 is committed."""
        return self._current

    @property
    def done(self) -> bool:
        return self._current >= self.n_steps

    @property
    def omega_max(self) -> float:
        return self._omega_max

    def critical_dt(self) -> float:
        """The stability limit 2 / omega_max of ``stiffness`` (+ experimental_stiffness)."""
        return math.inf if self._omega_max == 0.0 else 2.0 / self._omega_max

    # -- stepping -----------------------------------------------------------------------------

    def trial(self) -> TrialStep:
        """The next step's trial displacement; calling it again returns the same trial."""
        if self._pending is not None:
            return self._pending
        step = self._current + 1
        if step > self.n_steps:
            raise IntegrationError(step, f"the record ends at step {self.n_steps}")
        if step == 0:
            disp = self._d[0].copy()
        else:
            n = self._current
            disp = self._d[n] + self.dt * self._v[n] + 0.5 * self.dt**2 * self._a[n]
        disp.flags.writeable = False
        drift = self._t_exp @ disp
        drift.flags.writeable = False
        self._pending = TrialStep(step=step, time=step * self.dt, displacement=disp, drift=drift)
        return self._pending

    def commit(self, experimental_force: npt.ArrayLike) -> StepState:
        """Complete the pending trial with the measured forces of the experimental elements."""
        trial = self._pending
        if trial is None:
            raise IntegrationError(self._current + 1, "commit() called without a pending trial()")
        force = self._check_force(trial.step, experimental_force)
        k = trial.step
        resisting = self.stiffness @ trial.displacement + self._t_exp.T @ force
        load = -self.mass @ self.influence * self.ground_accel[k]
        if k == 0:
            accel = np.linalg.solve(self.mass, load - self.damping @ self._v[0] - resisting)
            vel = self._v[0].copy()
        else:
            n = k - 1
            v_pred = self._v[n] + (1.0 - self.GAMMA) * self.dt * self._a[n]
            accel = np.linalg.solve(self._m_eff, load - resisting - self.damping @ v_pred)
            vel = v_pred + self.GAMMA * self.dt * accel
        if not (np.all(np.isfinite(accel)) and np.all(np.isfinite(vel))):
            raise IntegrationError(k, "the response became non-finite")
        self._d[k], self._v[k], self._a[k], self._f[k] = trial.displacement, vel, accel, force
        self._current = k
        self._pending = None
        return StepState(
            step=k,
            time=trial.time,
            displacement=self._d[k].copy(),
            velocity=vel.copy(),
            acceleration=accel.copy(),
            experimental_force=force.copy(),
        )

    def _check_force(self, step: int, value: npt.ArrayLike) -> FloatArray:
        n_exp = len(self.experimental_stories)
        try:
            force = np.array(value, dtype=np.float64, ndmin=1)
        except (TypeError, ValueError) as exc:
            raise IntegrationError(step, f"experimental force is not numeric: {value!r}") from exc
        if n_exp == 0 and force.size == 0:
            return np.zeros(0)
        if force.shape != (n_exp,):
            raise IntegrationError(
                step,
                f"expected {n_exp} experimental force(s) for stories "
                f"{self.experimental_stories}, got shape {force.shape}",
            )
        if not np.all(np.isfinite(force)):
            raise IntegrationError(step, f"experimental force is not finite: {force}")
        return force

    def step(self) -> StepState:
        """Advance one step, asking ``experimental_force`` for the forces at the trial drift."""
        trial = self.trial()
        if self._experimental_force is None:
            return self.commit(np.zeros(0))
        try:
            force = self._experimental_force(trial.step, trial.time, trial.drift.copy())
        except Exception as exc:
            raise IntegrationError(
                trial.step,
                f"experimental_force raised {type(exc).__name__} at t={trial.time:g} s: {exc}",
            ) from exc
        return self.commit(force)

    def run(
        self,
        n_steps: int | None = None,
        progress: Callable[[int, int], None] | None = None,
    ) -> Response:
        """Commit step 0 if needed, then ``n_steps`` more (default: to the end of the record).

        ``progress(done, total)`` is called after each of those steps. Returns the whole history.
        """
        if self._current < 0:
            self.step()
        remaining = self.n_steps - self._current
        count = remaining if n_steps is None else n_steps
        if not (0 <= count <= remaining):
            raise ValueError(
                f"n_steps={n_steps} is outside 0..{remaining} (steps left in the record after "
                f"step {self._current})"
            )
        for done in range(1, count + 1):
            self.step()
            if progress is not None:
                progress(done, count)
        return self.response()

    # -- results ------------------------------------------------------------------------------

    def response(self) -> Response:
        end = self._current + 1
        disp = self._d[:end].copy()
        return Response(
            time=np.arange(end, dtype=np.float64) * self.dt,
            displacement=disp,
            velocity=self._v[:end].copy(),
            acceleration=self._a[:end].copy(),
            drift=disp @ self._t_all.T,
            experimental_drift=disp @ self._t_exp.T,
            experimental_force=self._f[:end].copy(),
            ground_accel=self.ground_accel[:end].copy(),
            experimental_stories=self.experimental_stories,
            influence=self.influence.copy(),
        )

    def energy_balance(self) -> EnergyBalance:
        """Energies of the committed history; works as a check of the measured forces too."""
        r = self.response()
        d, v = r.displacement, r.velocity
        dd = np.diff(d, axis=0)

        def cumulative(increments: FloatArray) -> FloatArray:
            return np.concatenate(([0.0], np.cumsum(increments)))

        def quadratic(x: FloatArray, matrix: FloatArray) -> FloatArray:
            e = 0.5 * np.einsum("ni,ij,nj->n", x, matrix, x)
            return np.asarray(e - e[0])

        eff_load = np.outer(r.ground_accel, self.mass @ self.influence)
        input_inc = -np.sum(0.5 * (eff_load[1:] + eff_load[:-1]) * dd, axis=1)
        cv = v @ self.damping.T
        damping_inc = np.sum(0.5 * (cv[1:] + cv[:-1]) * dd, axis=1)
        f, dx = r.experimental_force, np.diff(r.experimental_drift, axis=0)
        exp_inc = np.sum(0.5 * (f[1:] + f[:-1]) * dx, axis=1)
        return EnergyBalance(
            time=r.time,
            input=cumulative(input_inc),
            kinetic=quadratic(v, self.mass),
            elastic=quadratic(d, self.stiffness),
            damping=cumulative(damping_inc),
            experimental=cumulative(exp_inc),
        )
