"""The ``reversal+stops`` expert of ``online_improved``: the reversal basis plus stop operators
(Prandtl-Ishlinskii) driven by the element's own displacement, scheduled on its own plastic
deformation.

Why: the reversal basis (``branch``) writes a branch in the coordinates of its last reversal
``(d_r, F_r)``. Where a law's knee sits in *absolute* displacement — a virgin element yields at
``d_y`` whatever small elastic cycles came before — the reversal coordinates cannot place it
(the saturation lengths are fixed), and the tested element, which has cycled, teaches round
branches that a still-virgin twin does not have. Stop operators carry that state:
``s_i = clip(s_i + Δd, -r_i, r_i)`` (elastic-perfectly plastic, unit stiffness, threshold
``r_i``), each element running its own. Their increments since the reversal are added to the
branch's features::

    F = F_r + s * (phi_branch @ w_b + sum_j h_j(q) * (sum_i w_ij * s * Δs_i + w_uj * u))

``s`` the direction of motion, ``u = |d - d_r|``, ``Δs_i = s_i(d) - s_i(at the reversal)``.
``q`` is the element's accumulated plastic deformation: the travel of the play ``d - s_y`` of a
reference stop of threshold ``d_y`` (:func:`yield_threshold`, estimated from the offline data).
``h_j`` is a partition of unity (hat functions on ``q`` = 0, 1, 4 ``d_y``): the weights of a
virgin element (``q`` ≈ 0) are learned on the tested element while *it* is virgin and kept for a
twin that still is, while the cycled levels follow the tested element as it hardens or degrades.
The stops and ``q`` are functions of the displacement history alone (no predicted force enters
them). Linear in the weights: learned by the same exponentially weighted, ridge-regularised
least squares with Huber gating as the branch experts (``branch.WeightedRls``).
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass

import numpy as np
import numpy.typing as npt

from fresco_bridge.updating.base import OwnsTwin, UpdaterError, check_measurement
from fresco_bridge.updating.branch import (
    BasisTwin,
    BranchMemory,
    KeptFeatures,
    ReversalBasis,
    WeightedRls,
    initial_stiffness,
    offline_arrays,
)

__all__ = ["BranchStopBasis", "BranchStopRls", "StopBasis", "StopMemory", "yield_threshold"]

FloatArray = npt.NDArray[np.float64]


def stop_outputs(disp: FloatArray, thresholds: FloatArray) -> FloatArray:
    """(samples, thresholds): every stop operator's output along ``disp`` from the virgin state."""
    out = np.empty((disp.size, thresholds.size))
    s = np.zeros(thresholds.size)
    previous = 0.0
    for i, d in enumerate(disp.tolist()):
        s = np.clip(s + (d - previous), -thresholds, thresholds)
        out[i] = s
        previous = d
    return out


def yield_threshold(disp: FloatArray, force: FloatArray, points: int = 40) -> float:
    """Yield displacement of the elastic-plastic law that fits the data best: for thresholds r
    on a geometric grid (1 % to 100 % of the peak displacement), least squares of
    ``F = a * s_r(d) + b * d`` (``s_r`` a stop operator); the r of the smallest residual."""
    scale = float(np.max(np.abs(disp)))
    if not (math.isfinite(scale) and scale > 0.0):
        raise UpdaterError(f"online_improved: the offline data must move (peak displacement "
                           f"{scale!r})")
    r = scale * np.geomspace(0.01, 1.0, points)
    stops = stop_outputs(disp, r)
    best, best_r = math.inf, float(r[-1])
    for j in range(points):
        x = np.column_stack((stops[:, j], disp))
        coef, *_ = np.linalg.lstsq(x, force, rcond=None)
        residual = float(np.sum((x @ coef - force) ** 2))
        if residual < best:
            best, best_r = residual, float(r[j])
    return best_r


@dataclass(frozen=True, slots=True, eq=False)
class StopMemory:
    """One element's stops (the last one is the reference stop of threshold ``d_y``) and its
    accumulated plastic deformation ``q``."""

    stops: FloatArray
    q: float = 0.0


class StopBasis:
    """Stop thresholds (fractions of ``disp_scale``) and the schedule on ``q``."""

    THRESHOLDS = tuple(float(x) for x in np.geomspace(0.01, 0.8, 16))
    NODES = (0.0, 1.0, 4.0)
    """Nodes of the partition of unity in ``q``, in multiples of ``d_y``."""

    def __init__(self, disp_scale: float, yield_disp: float) -> None:
        if not (math.isfinite(disp_scale) and disp_scale > 0.0 and math.isfinite(yield_disp)
                and yield_disp > 0.0):  # fmt: skip
            raise UpdaterError(f"online_improved: stop operators need a positive displacement "
                               f"scale and yield displacement (got {disp_scale!r}, "
                               f"{yield_disp!r})")
        self.r = disp_scale * np.array(self.THRESHOLDS)
        self._lower = -self.r
        self.r_y = float(yield_disp)
        self.nodes = self.r_y * np.array(self.NODES)
        self.size = (self.r.size + 1) * self.nodes.size

    def virgin(self) -> StopMemory:
        return StopMemory(np.zeros(self.r.size + 1), 0.0)

    def advanced(self, memory: StopMemory, step: float) -> StopMemory:
        """The memory after a displacement step ``step``."""
        stops = memory.stops.copy()
        # np.clip's arithmetic (min(max(x, -r), r)) without its Python wrappers: per step
        np.minimum(np.maximum(stops[:-1] + step, self._lower), self.r, out=stops[:-1])
        s_y = min(max(stops[-1] + step, -self.r_y), self.r_y)
        q = memory.q + abs(step - (s_y - stops[-1]))
        stops[-1] = s_y
        return StopMemory(stops, q)

    def schedule(self, q: float) -> FloatArray:
        """Hat functions on the nodes at ``q`` (a partition of unity, constant past the last)."""
        nodes = self.nodes
        h = np.zeros(nodes.size)
        if q >= nodes[-1]:
            h[-1] = 1.0
            return h
        j = int(np.searchsorted(nodes, q, side="right")) - 1
        t = (q - nodes[j]) / (nodes[j + 1] - nodes[j])
        h[j], h[j + 1] = 1.0 - t, t
        return h


@dataclass(frozen=True, slots=True, eq=False)
class DualMemory:
    """One element: its branch memory, its stops, and the stops at its branch's reversal."""

    branch: BranchMemory
    stops: StopMemory
    stops_r: FloatArray

    @property
    def d(self) -> float:
        return self.branch.d

    @property
    def f(self) -> float:
        return self.branch.f


class BranchStopBasis:
    """The reversal basis plus the scheduled stop increments (module docstring)."""

    def __init__(self, branch: ReversalBasis, stops: StopBasis) -> None:
        self.branch = branch
        self.stops = stops
        self.disp_scale = branch.disp_scale
        self.size = branch.size + stops.size

    def virgin(self) -> DualMemory:
        s = self.stops.virgin()
        return DualMemory(BranchMemory(), s, s.stops)

    def features(self, memory: DualMemory, d: float) -> tuple[float, float, FloatArray]:
        """(direction, F_r, phi): the force at ``d`` is ``F_r + direction * phi @ w``."""
        direction, f_r, phi_branch = self.branch.features(memory.branch, d)
        stops = self.stops.advanced(memory.stops, d - memory.branch.d)
        stops_r = memory.stops.stops if memory.branch.reversal(d) else memory.stops_r
        x = np.empty(self.stops.r.size + 1)
        x[:-1] = direction * (stops.stops[:-1] - stops_r[:-1])
        x[-1] = abs(d - memory.branch.branch(d)[1])
        phi_stops = np.outer(self.stops.schedule(stops.q), x).ravel()
        return direction, f_r, np.concatenate((phi_branch, phi_stops))

    def advanced(self, memory: DualMemory, d: float, f: float) -> DualMemory:
        stops = self.stops.advanced(memory.stops, d - memory.branch.d)
        stops_r = memory.stops.stops if memory.branch.reversal(d) else memory.stops_r
        return DualMemory(memory.branch.advanced(d, f), stops, stops_r)


class BranchStopRls(OwnsTwin):
    """The expert (module docstring); ``offline`` = (displacement, force) arrays.

    ``memory_terms`` adds the branch memory terms of ``reversal+memory`` (an optional expert:
    not in the default mixture; why: ``BENCHMARKS.md``, "Online updating")."""

    name = "online_improved"

    def __init__(self, *, offline: tuple[npt.ArrayLike, npt.ArrayLike],
                 forgetting: float = 0.998, ridge: float = 1e-3, gate: float = 4.0,
                 memory_terms: bool = False) -> None:
        disp, force = offline_arrays(offline, forgetting, ridge, gate)
        scale, force_scale = float(np.max(np.abs(disp))), float(np.max(np.abs(force)))
        self.basis = BranchStopBasis(
            ReversalBasis(scale, force_scale,
                          stiffness=initial_stiffness(disp, force) if memory_terms else None),
            StopBasis(scale, yield_threshold(disp, force)),
        )  # fmt: skip
        memory = self.basis.virgin()
        rows, targets = [], []
        for d, f in zip(disp.tolist(), force.tolist(), strict=True):
            if d != memory.branch.d:
                direction, f_r, phi = self.basis.features(memory, d)
                rows.append(phi)
                targets.append(direction * (f - f_r))
            memory = self.basis.advanced(memory, d, f)
        self.rls = WeightedRls(np.array(rows), np.array(targets), forgetting=forgetting,
                               ridge=ridge, gate=gate, noise_floor=1e-6 * force_scale**2)
        self._source = self.basis.virgin()
        self._source_features = KeptFeatures(self.basis)
        self._twin = BasisTwin(self.basis, self.rls)
        self._last_update = 0.0

    @property
    def weights(self) -> FloatArray:
        return self.rls.weights

    def predict(self, d: float) -> float:
        """One-step-ahead force of the *tested* element at ``d`` (before observing it)."""
        memory = self._source
        if d == memory.branch.d:
            return memory.branch.f
        direction, f_r, phi = self._source_features(memory, d)
        return f_r + direction * float(phi @ self.rls.weights)

    def observe(self, d: float, force: float) -> None:
        d, force = check_measurement(self.name, d, force)
        start = time.perf_counter()
        memory = self._source
        if d != memory.branch.d:
            direction, f_r, phi = self._source_features(memory, d)
            self.rls.update(phi, direction * (force - f_r))
        self._source = self.basis.advanced(memory, d, force)
        self._last_update = time.perf_counter() - start
