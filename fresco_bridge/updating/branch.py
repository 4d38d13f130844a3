"""A reversal-coordinate hysteresis basis, linear in its weights, learned by RLS: the experts of
``online_improved`` (``fresco_bridge.updating.improved``) are built from it.

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

``memory_terms=True`` adds what the element's *previous* branch and its envelope say about the
current one (why: a Menegotto-Pinto element that has barely yielded still has sharp, stiff
branches, one that has cycled widely has round ones; range and travel alone cannot tell the
twin's small cycles from the tested element's large ones): ``exp(-L/l_k)`` of the previous
branch's length ``L``, ``exp(-P/p_k)`` of its plastic part ``P = |Δd - ΔF/k_init|`` (``k_init``
from the first loading of the offline data) and the distance from the reversal to the element's
envelope (max excursion so far) in the direction of motion.

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
from typing import Generic, Protocol, TypeVar

import numpy as np
import numpy.typing as npt

from fresco_bridge.updating.base import OwnsTwin, UpdaterError, check_measurement
from sim_actuator.models.base import HysteresisModel, trial_input_error

__all__ = [
    "BasisTwin",
    "BranchMemory",
    "BranchRls",
    "KeptFeatures",
    "ReversalBasis",
    "TwinBasis",
    "WeightedRls",
    "initial_stiffness",
    "offline_arrays",
]

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
    prev_dd: float = 0.0
    """Displacement change over the previous branch (the one that ended at ``d_r``)."""
    prev_df: float = 0.0
    """Force change over it."""

    def reversal(self, d: float) -> bool:
        """Whether a trial at ``d`` reverses the direction of motion at the committed point."""
        step = d - self.d
        return step != 0.0 and (1.0 if step > 0.0 else -1.0) != self.direction

    def branch(self, d: float) -> tuple[float, float, float]:
        """(direction, d_r, F_r) of the branch that a trial at ``d`` lies on."""
        step = d - self.d
        if step == 0.0:
            return self.direction, self.d_r, self.f_r
        direction = 1.0 if step > 0.0 else -1.0
        if direction != self.direction:
            return direction, self.d, self.f  # a reversal at the committed point
        return direction, self.d_r, self.f_r

    def previous_branch(self, d: float) -> tuple[float, float]:
        """(Δd, ΔF) of the branch before the one a trial at ``d`` lies on."""
        if self.reversal(d):
            return self.d - self.d_r, self.f - self.f_r
        return self.prev_dd, self.prev_df

    def advanced(self, d: float, f: float) -> BranchMemory:
        direction, d_r, f_r = self.branch(d)
        prev_dd, prev_df = self.previous_branch(d)
        return BranchMemory(d, f, direction, d_r, f_r, max(self.d_max, d), min(self.d_min, d),
                            self.travel + abs(d - self.d), prev_dd, prev_df)  # fmt: skip


def initial_stiffness(disp: FloatArray, force: FloatArray) -> float:
    """Secant stiffness of the first loading: least squares F = k d over the samples before
    |d| first exceeds a tenth of its maximum (generic: no yield point is assumed)."""
    limit = 0.1 * float(np.max(np.abs(disp)))
    end = int(np.argmax(np.abs(disp) > limit)) or disp.size
    d, f = disp[: max(end, 2)], force[: max(end, 2)]
    dd = float(d @ d)
    return float(d @ f) / dd if dd > 0.0 else 0.0


def offline_data(offline: tuple[npt.ArrayLike, npt.ArrayLike],
                 name: str = "online_improved") -> tuple[FloatArray, FloatArray]:
    """The offline (displacement, force) as checked float arrays (UpdaterError naming ``name``)."""
    disp = np.asarray(offline[0], dtype=np.float64)
    force = np.asarray(offline[1], dtype=np.float64)
    if disp.ndim != 1 or disp.shape != force.shape or disp.size < 20:
        raise UpdaterError(f"{name}: offline data must be two equal 1-D arrays of "
                           f">= 20 samples, got shapes {disp.shape} and {force.shape}")
    if not (np.all(np.isfinite(disp)) and np.all(np.isfinite(force))):
        raise UpdaterError(f"{name}: offline data contain NaN or inf")
    return disp, force


def offline_arrays(offline: tuple[npt.ArrayLike, npt.ArrayLike], forgetting: float, ridge: float,
                   gate: float) -> tuple[FloatArray, FloatArray]:
    """The offline (displacement, force) as checked float arrays, the learning options checked."""
    disp, force = offline_data(offline)
    if not (0.9 <= forgetting <= 1.0 and ridge > 0.0 and gate > 0.0):
        raise UpdaterError(f"online_improved: need 0.9 <= forgetting <= 1, ridge > 0, "
                           f"gate > 0 (got {forgetting}, {ridge}, {gate})")  # fmt: skip
    return disp, force


class WeightedRls:
    """Exponentially weighted least squares, ridge-regularised, with Huber gating.

    Starts from a ridge fit to offline ``rows``/``targets`` that counts as one forgetting
    horizon (``1 / (1 - forgetting)`` samples). Each update forgets by ``forgetting`` and adds
    ``(1 - forgetting) * ridge`` back, pulling the weights towards their current value (no
    covariance wind-up in quiet phases: unexcited directions keep their value) or, with
    ``shrink``, towards zero. Innovations beyond ``gate`` robust standard deviations get a
    bounded (Huber) weight: a load-cell spike cannot throw the weights.
    """

    def __init__(self, rows: FloatArray, targets: FloatArray, *, forgetting: float,
                 ridge: float, gate: float, noise_floor: float, shrink: bool = False) -> None:
        n = rows.shape[1]
        info = rows.T @ rows
        scale = float(np.trace(info)) / n if rows.size else 1.0
        self.weights: FloatArray = np.asarray(
            np.linalg.solve(info + ridge * scale * np.eye(n), rows.T @ targets), dtype=np.float64
        )
        horizon = 1.0 / max(1.0 - forgetting, 1e-6)
        self.forgetting = forgetting
        self.gate = gate
        self._ridge = ridge * scale * np.eye(n)
        self._info = info * (horizon / max(len(targets), 1)) + self._ridge
        self._ridge_step = (1.0 - forgetting) * self._ridge
        self._rhs = self._info @ self.weights
        self._shrink = shrink
        residual = rows @ self.weights - targets
        self._noise_var = max(float(np.mean(residual**2)), noise_floor)

    def update(self, phi: FloatArray, target: float) -> None:
        """Learn one sample: ``target ≈ phi @ weights``."""
        innovation = target - float(phi @ self.weights)
        sigma = math.sqrt(self._noise_var)
        z = abs(innovation) / sigma
        weight = 1.0 if z <= self.gate else self.gate / z  # Huber: bounded influence
        self._noise_var = 0.99 * self._noise_var + 0.01 * min(innovation**2,
                                                              (self.gate * sigma) ** 2)
        lam = self.forgetting
        # the same operations in the same order as lam * info + w * phi phi' + (1 - lam) * ridge,
        # in place, the constant term computed once
        info = self._info
        info *= lam
        info += np.multiply(np.outer(phi, phi), weight)
        info += self._ridge_step
        self._rhs = lam * self._rhs + weight * target * phi
        if not self._shrink:
            self._rhs += (1.0 - lam) * (self._ridge @ self.weights)
        self.weights = np.asarray(np.linalg.solve(info, self._rhs), dtype=np.float64)


class ReversalBasis:
    """The feature map; ``disp_scale``/``force_scale`` normalise it (from the offline data)."""

    RANGE_SCALES = (0.05, 0.15, 0.4)
    SATURATIONS = (0.02, 0.06, 0.17, 0.5)
    TRAVEL_SCALE = 50.0
    PREVIOUS_LENGTH_SCALES = (0.1, 0.4)
    PREVIOUS_PLASTIC_SCALES = (0.02, 0.1)

    def __init__(self, disp_scale: float, force_scale: float, *,
                 stiffness: float | None = None) -> None:
        """``stiffness`` (k_init) switches the memory terms on (module docstring)."""
        if not (disp_scale > 0.0 and force_scale > 0.0):
            raise UpdaterError(
                f"online_improved: the offline data must move and carry force (displacement "
                f"scale {disp_scale!r}, force scale {force_scale!r})"
            )
        self.disp_scale = float(disp_scale)
        self.force_scale = float(force_scale)
        self._c = self.disp_scale * np.array(self.SATURATIONS)
        self._ranges = 2.0 * self.disp_scale * np.array(self.RANGE_SCALES)
        if stiffness is not None and not (math.isfinite(stiffness) and stiffness > 0.0):
            raise UpdaterError(f"online_improved: the first loading of the offline data must "
                               f"have a positive stiffness (got {stiffness!r})")
        self.stiffness = stiffness
        self._lengths = self.disp_scale * np.array(self.PREVIOUS_LENGTH_SCALES)
        self._plastic = self.disp_scale * np.array(self.PREVIOUS_PLASTIC_SCALES)
        memory = 0 if stiffness is None else self._lengths.size + self._plastic.size + 1
        self._n_g = 4 + self._ranges.size + memory
        self.size = (1 + len(self.SATURATIONS)) * self._n_g

    def virgin(self) -> BranchMemory:
        return BranchMemory()

    def advanced(self, memory: BranchMemory, d: float, f: float) -> BranchMemory:
        return memory.advanced(d, f)

    def features(self, memory: BranchMemory, d: float) -> tuple[float, float, FloatArray]:
        """(direction, F_r, phi): the force at ``d`` is ``F_r + direction * phi @ w``."""
        direction, d_r, f_r = memory.branch(d)
        u = abs(d - d_r)
        psi = np.empty(1 + self._c.size)
        psi[0] = u
        psi[1:] = self._c * -np.expm1(-u / self._c)
        span = max(memory.d_max, d) - min(memory.d_min, d)
        g = np.empty(self._n_g)
        g[0] = 1.0
        g[1] = direction * f_r / self.force_scale
        g[2] = direction * d_r / self.disp_scale
        end = 3 + self._ranges.size
        g[3:end] = np.exp(-span / self._ranges)
        g[end] = (memory.travel + abs(d - memory.d)) / (self.TRAVEL_SCALE * self.disp_scale)
        if self.stiffness is not None:
            prev_dd, prev_df = memory.previous_branch(d)
            plastic = abs(prev_dd - prev_df / self.stiffness)
            n_l = self._lengths.size
            g[end + 1:end + 1 + n_l] = np.exp(-abs(prev_dd) / self._lengths)
            g[end + 1 + n_l:-1] = np.exp(-plastic / self._plastic)
            envelope = memory.d_max if direction > 0.0 else -memory.d_min
            g[-1] = (envelope - direction * d_r) / self.disp_scale
        return direction, f_r, np.outer(psi, g).ravel()


class _Memory(Protocol):
    @property
    def d(self) -> float: ...
    @property
    def f(self) -> float: ...


M = TypeVar("M", bound=_Memory)


class TwinBasis(Protocol[M]):
    """What a twin needs of a basis written in reversal coordinates (``ReversalBasis`` and the
    stop experts' ``play.BranchStopBasis``)."""

    @property
    def disp_scale(self) -> float: ...
    def virgin(self) -> M: ...
    def features(self, memory: M, d: float) -> tuple[float, float, FloatArray]: ...
    def advanced(self, memory: M, d: float, f: float) -> M: ...


class KeptFeatures(Generic[M]):
    """``basis.features(memory, d)``, the last one kept: the ``observe`` that follows a
    ``predict`` at the same point reuses it (``online_improved`` asks both every step: one
    computation, not two)."""

    def __init__(self, basis: TwinBasis[M]) -> None:
        self._basis = basis
        self._kept: tuple[M, float, tuple[float, float, FloatArray]] | None = None

    def __call__(self, memory: M, d: float) -> tuple[float, float, FloatArray]:
        kept = self._kept
        if kept is not None and kept[0] is memory and kept[1] == d:
            return kept[2]
        out = self._basis.features(memory, d)
        self._kept = (memory, d, out)
        return out


class BasisTwin(Generic[M]):
    """The twin of an expert: the learner's current weights (read at each call) on its own
    memory of its own history (material semantics)."""

    name = "online_improved"

    def __init__(self, basis: TwinBasis[M], learner: WeightedRls,
                 memory: M | None = None) -> None:
        """``memory``: start from this committed memory instead of the virgin state."""
        self._basis = basis
        self._learner = learner
        self._committed = basis.virgin() if memory is None else memory
        self._trial = self._committed

    def _force(self, memory: M, d: float) -> float:
        direction, f_r, phi = self._basis.features(memory, d)
        return f_r + direction * float(phi @ self._learner.weights)

    def set_trial(self, d: float) -> tuple[float, float]:
        if not math.isfinite(d):
            raise trial_input_error(self.name, d)
        c = self._committed
        if d == c.d:
            self._trial = c
            return c.f, self.initial_tangent
        force = self._force(c, d)
        h = 1e-6 * self._basis.disp_scale
        probe = d + h if d > c.d else d - h
        tangent = (self._force(c, probe) - force) / (probe - d)
        self._trial = self._basis.advanced(c, d, force)
        return force, tangent

    def commit(self) -> None:
        self._committed = self._trial

    def advance(self, d: float) -> float:
        """``set_trial(d)`` and ``commit()`` in one, the force only (no tangent probe): half the
        cost, for the free runs that score the experts (``improved``)."""
        c = self._committed
        if d == c.d:
            self._trial = c
            return c.f
        force = self._force(c, d)
        self._committed = self._trial = self._basis.advanced(c, d, force)
        return force

    def revert_to_last_commit(self) -> None:
        self._trial = self._committed

    def revert_to_start(self) -> None:
        self._committed = self._trial = self._basis.virgin()

    @property
    def initial_tangent(self) -> float:
        h = 1e-6 * self._basis.disp_scale
        return self._force(self._basis.virgin(), h) / h

    @property
    def committed(self) -> tuple[float, float]:
        return self._committed.d, self._committed.f

    def clone(self) -> HysteresisModel:
        twin = BasisTwin(self._basis, self._learner)
        twin._committed, twin._trial = self._committed, self._trial
        return twin


class BranchRls(OwnsTwin):
    """One expert (see the module docstring); ``offline`` = (displacement, force) arrays."""

    name = "online_improved"

    def __init__(
        self,
        *,
        offline: tuple[npt.ArrayLike, npt.ArrayLike],
        forgetting: float = 0.998,
        ridge: float = 1e-3,
        gate: float = 4.0,
        memory_terms: bool = False,
        force_scale: float | None = None,
        stiffness: float | None = None,
        shrink: bool = False,
    ) -> None:
        """``force_scale``/``stiffness`` (k_init of the memory terms) default to the offline
        data's; a residual expert passes those of the whole force instead. ``shrink``: the
        ridge pulls the weights towards zero (a residual that is not supported by recent data
        fades) instead of towards their current value."""
        disp, force = offline_arrays(offline, forgetting, ridge, gate)
        if memory_terms and stiffness is None:
            stiffness = initial_stiffness(disp, force)
        self.basis = ReversalBasis(
            float(np.max(np.abs(disp))),
            float(np.max(np.abs(force))) if force_scale is None else force_scale,
            stiffness=stiffness if memory_terms else None,
        )  # fmt: skip
        rows, targets = self._offline_rows(disp, force)
        self.rls = WeightedRls(rows, targets, forgetting=forgetting, ridge=ridge, gate=gate,
                               noise_floor=1e-6 * self.basis.force_scale**2, shrink=shrink)
        self._source = BranchMemory()
        self._source_features = KeptFeatures(self.basis)
        self._twin = BasisTwin(self.basis, self.rls)
        self._last_update = 0.0

    @property
    def weights(self) -> FloatArray:
        return self.rls.weights

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

    def predict(self, d: float) -> float:
        """One-step-ahead force of the *tested* element at ``d`` (before observing it)."""
        memory = self._source
        if d == memory.d:
            return memory.f
        direction, f_r, phi = self._source_features(memory, d)
        return f_r + direction * float(phi @ self.weights)

    def observe(self, d: float, force: float) -> None:
        d, force = check_measurement(self.name, d, force)
        start = time.perf_counter()
        memory = self._source
        if d != memory.d:
            direction, f_r, phi = self._source_features(memory, d)
            self.rls.update(phi, direction * (force - f_r))
        self._source = memory.advanced(d, force)
        self._last_update = time.perf_counter() - start

