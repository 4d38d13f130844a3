"""``online_improved``: a reversal-coordinate hysteresis basis, linear in its weights, by RLS.

Why not the paper's ANN: its twin feeds its own predicted force back every step, so small
errors integrate (low-amplitude drift, divergence under load-cell noise). Here the force of an
element is written in the coordinates of its current branch (Masing's idea, generalised)::

    F = F_r + s * sum_kj w_kj * psi_k(u) * g_j(memory)

with ``s`` the direction of motion, ``(d_r, F_r)`` the last reversal point, ``u = |d - d_r|``,
``psi`` = {u, c_k (1 - exp(-u / c_k))} (slope 1 at u = 0, saturating at c_k) and ``g`` = {1,
s·F_r, s·d_r, exp(-range/r_m) (virgin vs cycled), travel} where range = max d − min d and travel
= cumulative |Δd| of *that* element (so the twin degrades and hardens by its own history).
The only recurrence is ``F_r``, taken once per reversal, and every branch saturates onto a
learned asymptote, so errors are forgotten after a large excursion instead of integrating.

Learning: the weights are shared by the tested element and its twin (same law, different
histories). They start from a ridge fit to the offline database and are updated every step by
exponentially weighted least squares regularised towards the current estimate (no covariance
wind-up in quiet phases: unexcited directions keep their value), with Huber gating of
innovations larger than ``gate`` robust standard deviations (load-cell spikes).
Cost: one rank-1 update and one n×n solve per step (n = 35): tens of microseconds.
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass

import numpy as np
import numpy.typing as npt

from fresco_bridge.updating.base import UpdaterError, UpdaterInputError
from sim_actuator.models.base import HysteresisModel, trial_input_error

__all__ = ["BranchMemory", "OnlineImproved", "ReversalBasis"]

FloatArray = npt.NDArray[np.float64]


@dataclass(frozen=True, slots=True)
class BranchMemory:
    """What one element remembers: last committed point, its branch, extremes and travel."""

    d: float = 0.0
    f: float = 0.0
    direction: float = 0.0
    d_r: float = 0.0
    f_r: float = 0.0
    d_max: float = 0.0
    d_min: float = 0.0
    travel: float = 0.0

    def branch(self, d: float) -> tuple[float, float, float]:
        """(direction, d_r, F_r) of the branch that a trial at ``d`` lies on."""
        step = d - self.d
        if step == 0.0:
            return self.direction, self.d_r, self.f_r
        direction = 1.0 if step > 0.0 else -1.0
        if direction != self.direction:
            return direction, self.d, self.f  # a reversal at the committed point
        return direction, self.d_r, self.f_r

    def advanced(self, d: float, f: float) -> BranchMemory:
        direction, d_r, f_r = self.branch(d)
        return BranchMemory(d, f, direction, d_r, f_r, max(self.d_max, d), min(self.d_min, d),
                            self.travel + abs(d - self.d))  # fmt: skip


class ReversalBasis:
    """The feature map; ``disp_scale``/``force_scale`` normalise it (from the offline data)."""

    RANGE_SCALES = (0.05, 0.15, 0.4)
    SATURATIONS = (0.02, 0.06, 0.17, 0.5)
    TRAVEL_SCALE = 50.0

    def __init__(self, disp_scale: float, force_scale: float) -> None:
        if not (disp_scale > 0.0 and force_scale > 0.0):
            raise UpdaterError(
                f"online_improved: the offline data must move and carry force (displacement "
                f"scale {disp_scale!r}, force scale {force_scale!r})"
            )
        self.disp_scale = float(disp_scale)
        self.force_scale = float(force_scale)
        self._c = self.disp_scale * np.array(self.SATURATIONS)
        self._ranges = 2.0 * self.disp_scale * np.array(self.RANGE_SCALES)
        self.size = (1 + len(self.SATURATIONS)) * (3 + len(self.RANGE_SCALES) + 1)

    def features(self, memory: BranchMemory, d: float) -> tuple[float, float, FloatArray]:
        """(direction, F_r, phi): the force at ``d`` is ``F_r + direction * phi @ w``."""
        direction, d_r, f_r = memory.branch(d)
        u = abs(d - d_r)
        psi = np.empty(1 + self._c.size)
        psi[0] = u
        psi[1:] = self._c * -np.expm1(-u / self._c)
        span = max(memory.d_max, d) - min(memory.d_min, d)
        g = np.empty(4 + self._ranges.size)
        g[0] = 1.0
        g[1] = direction * f_r / self.force_scale
        g[2] = direction * d_r / self.disp_scale
        g[3:-1] = np.exp(-span / self._ranges)
        g[-1] = (memory.travel + abs(d - memory.d)) / (self.TRAVEL_SCALE * self.disp_scale)
        return direction, f_r, np.outer(psi, g).ravel()


class _Twin:
    """The twin: the shared weights on its own branch memory (material semantics)."""

    name = "online_improved"

    def __init__(self, owner: OnlineImproved) -> None:
        self._owner = owner
        self._committed = BranchMemory()
        self._trial = self._committed

    def _force(self, memory: BranchMemory, d: float) -> float:
        direction, f_r, phi = self._owner.basis.features(memory, d)
        return f_r + direction * float(phi @ self._owner.weights)

    def set_trial(self, d: float) -> tuple[float, float]:
        if not math.isfinite(d):
            raise trial_input_error(self.name, d)
        c = self._committed
        if d == c.d:
            self._trial = c
            return c.f, self.initial_tangent
        force = self._force(c, d)
        h = 1e-6 * self._owner.basis.disp_scale
        probe = d + h if d > c.d else d - h
        tangent = (self._force(c, probe) - force) / (probe - d)
        self._trial = c.advanced(d, force)
        return force, tangent

    def commit(self) -> None:
        self._committed = self._trial

    def revert_to_last_commit(self) -> None:
        self._trial = self._committed

    def revert_to_start(self) -> None:
        self._committed = self._trial = BranchMemory()

    @property
    def initial_tangent(self) -> float:
        h = 1e-6 * self._owner.basis.disp_scale
        return self._force(BranchMemory(), h) / h

    @property
    def committed(self) -> tuple[float, float]:
        return self._committed.d, self._committed.f

    def clone(self) -> HysteresisModel:
        twin = _Twin(self._owner)
        twin._committed, twin._trial = self._committed, self._trial
        return twin


class OnlineImproved:
    """Our updater (see the module docstring); ``offline`` = (displacement, force) arrays.

    Keyword options only, so the class itself is the registry's factory."""

    name = "online_improved"

    def __init__(
        self,
        *,
        offline: tuple[npt.ArrayLike, npt.ArrayLike],
        forgetting: float = 0.998,
        ridge: float = 1e-3,
        gate: float = 4.0,
    ) -> None:
        disp = np.asarray(offline[0], dtype=np.float64)
        force = np.asarray(offline[1], dtype=np.float64)
        if disp.ndim != 1 or disp.shape != force.shape or disp.size < 20:
            raise UpdaterError(f"online_improved: offline data must be two equal 1-D arrays of "
                               f">= 20 samples, got shapes {disp.shape} and {force.shape}")
        if not (np.all(np.isfinite(disp)) and np.all(np.isfinite(force))):
            raise UpdaterError("online_improved: offline data contain NaN or inf")
        if not (0.9 <= forgetting <= 1.0 and ridge > 0.0 and gate > 0.0):
            raise UpdaterError(f"online_improved: need 0.9 <= forgetting <= 1, ridge > 0, "
                               f"gate > 0 (got {forgetting}, {ridge}, {gate})")  # fmt: skip
        self.forgetting = forgetting
        self.gate = gate
        self.basis = ReversalBasis(float(np.max(np.abs(disp))), float(np.max(np.abs(force))))
        n = self.basis.size
        rows, targets = self._offline_rows(disp, force)
        info = rows.T @ rows
        scale = float(np.trace(info)) / n if rows.size else 1.0
        self.weights: FloatArray = np.asarray(
            np.linalg.solve(info + ridge * scale * np.eye(n), rows.T @ targets), dtype=np.float64
        )
        # The offline fit counts as one forgetting horizon, 1 / (1 - forgetting) samples.
        horizon = 1.0 / max(1.0 - forgetting, 1e-6)
        self._ridge = ridge * scale * np.eye(n)
        self._info = info * (horizon / max(len(targets), 1)) + self._ridge
        self._rhs = self._info @ self.weights
        residual = rows @ self.weights - targets
        self._noise_var = max(float(np.mean(residual**2)), 1e-6 * self.basis.force_scale**2)
        self._source = BranchMemory()
        self._twin = _Twin(self)
        self._last_update = 0.0

    def _offline_rows(self, disp: FloatArray, force: FloatArray) -> tuple[FloatArray, FloatArray]:
        memory = BranchMemory()
        rows, targets = [], []
        for d, f in zip(disp.tolist(), force.tolist(), strict=True):
            if d != memory.d:
                direction, f_r, phi = self.basis.features(memory, d)
                rows.append(phi)
                targets.append(direction * (f - f_r))
            memory = memory.advanced(d, f)
        return np.array(rows), np.array(targets)

    def observe(self, d: float, force: float) -> None:
        if not (isinstance(d, int | float) and isinstance(force, int | float)
                and math.isfinite(d) and math.isfinite(force)):  # fmt: skip
            raise UpdaterInputError(
                f"online_improved: measurement must be finite numbers, got d={d!r}, "
                f"force={force!r}; nothing was learned from it"
            )
        start = time.perf_counter()
        memory = self._source
        if d != memory.d:
            direction, f_r, phi = self.basis.features(memory, d)
            target = direction * (force - f_r)
            innovation = target - float(phi @ self.weights)
            sigma = math.sqrt(self._noise_var)
            z = abs(innovation) / sigma
            weight = 1.0 if z <= self.gate else self.gate / z  # Huber: bounded influence
            self._noise_var = 0.99 * self._noise_var + 0.01 * min(innovation**2,
                                                                  (self.gate * sigma) ** 2)
            lam = self.forgetting
            self._info = lam * self._info + weight * np.outer(phi, phi) + (1.0 - lam) * self._ridge
            self._rhs = (lam * self._rhs + weight * target * phi
                         + (1.0 - lam) * (self._ridge @ self.weights))  # fmt: skip
            self.weights = np.asarray(np.linalg.solve(self._info, self._rhs), dtype=np.float64)
        self._source = memory.advanced(d, force)
        self._last_update = time.perf_counter() - start

    @property
    def twin(self) -> HysteresisModel:
        return self._twin

    @property
    def last_update_seconds(self) -> float:
        return self._last_update

