"""Shear-building model: lumped floor masses joined by story springs (rigid floors).

Units default to mm, kN, s (masses in kN*s^2/mm, stiffness in kN/mm), as in the source paper.

Indexing and signs (0-based, as in the arrays): story ``i`` joins floor ``i - 1`` (the ground for
``i = 0``) to floor ``i``; its drift is ``u[i] - u[i - 1]``. A story element with restoring force
``f[i]`` (positive for positive drift) pushes floor ``i - 1`` by ``+f[i]`` and floor ``i`` by
``-f[i]``; moved to the left-hand side of ``M a + C v + r = p`` this is the resisting force
``r = T^T f`` with ``T`` the drift matrix (``drift = T u``), so ``r[i] = f[i] - f[i + 1]``.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
import numpy.typing as npt

__all__ = ["Modes", "ShearBuilding", "drift_matrix", "generalized_eigen"]

FloatArray = npt.NDArray[np.float64]


def drift_matrix(n_stories: int, stories: Sequence[int] | None = None) -> FloatArray:
    """Rows of ``T`` (``drift = T u``) for ``stories`` (all stories when None)."""
    if n_stories < 1:
        raise ValueError(f"a shear building needs at least 1 story, got {n_stories}")
    full = np.eye(n_stories) - np.eye(n_stories, k=-1)
    if stories is None:
        return full
    rows = list(stories)
    for story in rows:
        if not (isinstance(story, int | np.integer) and 0 <= story < n_stories):
            raise ValueError(f"story index {story!r} is not in 0..{n_stories - 1}")
    if len(set(rows)) != len(rows):
        raise ValueError(f"story indices must be distinct, got {rows}")
    return np.asarray(full[rows, :], dtype=np.float64)


def generalized_eigen(stiffness: FloatArray, mass: FloatArray) -> tuple[FloatArray, FloatArray]:
    """Solve ``K phi = w^2 M phi``: (w^2 ascending, mass-normalized shapes as columns).

    Uses the Cholesky factor of ``M`` to reach a symmetric standard problem (no scipy needed).
    Each shape is signed so that its last (roof) component is >= 0.
    """
    try:
        lower = np.linalg.cholesky(mass)
    except np.linalg.LinAlgError as exc:
        raise ValueError("mass matrix is not symmetric positive definite") from exc
    lower_inv = np.linalg.inv(lower)
    symmetric = lower_inv @ stiffness @ lower_inv.T
    eigenvalues, vectors = np.linalg.eigh(0.5 * (symmetric + symmetric.T))
    shapes = lower_inv.T @ vectors
    signs = np.where(shapes[-1, :] < 0.0, -1.0, 1.0)
    return eigenvalues, shapes * signs


@dataclass(frozen=True, eq=False)
class Modes:
    """Undamped modes, ordered by frequency; ``shapes[:, j]`` is mode ``j + 1``, mass-normalized."""

    omega: FloatArray
    shapes: FloatArray
    participation: FloatArray

    @property
    def period(self) -> FloatArray:
        with np.errstate(divide="ignore"):
            return np.asarray(2.0 * np.pi / self.omega, dtype=np.float64)


@dataclass(eq=False)
class ShearBuilding:
    """Floor masses (kN*s^2/mm) and the frame's story stiffnesses (kN/mm), bottom story first."""

    masses: FloatArray
    story_stiffness: FloatArray

    def __post_init__(self) -> None:
        self.masses = np.array(self.masses, dtype=np.float64, ndmin=1)
        self.story_stiffness = np.array(self.story_stiffness, dtype=np.float64, ndmin=1)
        if self.masses.ndim != 1 or self.masses.size == 0:
            raise ValueError(f"masses must be a non-empty 1-D list, got shape {self.masses.shape}")
        if self.story_stiffness.shape != self.masses.shape:
            raise ValueError(
                f"story_stiffness has {self.story_stiffness.size} values but there are "
                f"{self.masses.size} floor masses"
            )
        for i, m in enumerate(self.masses):
            if not (math.isfinite(m) and m > 0.0):
                raise ValueError(f"mass of floor {i} must be finite and > 0, got {m}")
        for i, k in enumerate(self.story_stiffness):
            if not (math.isfinite(k) and k >= 0.0):
                raise ValueError(f"stiffness of story {i} must be finite and >= 0, got {k}")

    @property
    def n_stories(self) -> int:
        return int(self.masses.size)

    def drift_matrix(self, stories: Sequence[int] | None = None) -> FloatArray:
        return drift_matrix(self.n_stories, stories)

    def mass_matrix(self) -> FloatArray:
        return np.diag(self.masses)

    def _story_k(self, extra_story_stiffness: Sequence[float] | FloatArray | None) -> FloatArray:
        if extra_story_stiffness is None:
            return self.story_stiffness.copy()
        extra = np.asarray(extra_story_stiffness, dtype=np.float64)
        if extra.shape != self.story_stiffness.shape:
            raise ValueError(
                f"extra_story_stiffness needs {self.n_stories} values (one per story, 0 for "
                f"none), got shape {extra.shape}"
            )
        if not np.all(np.isfinite(extra)) or np.any(extra < 0.0):
            raise ValueError(f"extra_story_stiffness must be finite and >= 0, got {extra}")
        return np.asarray(self.story_stiffness + extra, dtype=np.float64)

    def stiffness_matrix(
        self, extra_story_stiffness: Sequence[float] | FloatArray | None = None
    ) -> FloatArray:
        """``T^T diag(k) T``; ``extra_story_stiffness`` adds e.g. a damper's initial stiffness."""
        t = self.drift_matrix()
        return np.asarray(t.T @ np.diag(self._story_k(extra_story_stiffness)) @ t)

    def modes(self, extra_story_stiffness: Sequence[float] | FloatArray | None = None) -> Modes:
        mass = self.mass_matrix()
        eigenvalues, shapes = generalized_eigen(self.stiffness_matrix(extra_story_stiffness), mass)
        omega = np.sqrt(np.clip(eigenvalues, 0.0, None))
        ones = np.ones(self.n_stories)
        participation = shapes.T @ mass @ ones  # shapes are mass-normalized
        return Modes(omega=omega, shapes=shapes, participation=participation)

    def rayleigh(
        self,
        zeta: float = 0.05,
        modes: tuple[int, int] = (1, 2),
        extra_story_stiffness: Sequence[float] | FloatArray | None = None,
    ) -> tuple[float, float, FloatArray]:
        """Rayleigh damping ``C = a_m M + b_k K`` giving ``zeta`` in the two (1-based) modes.

        ``K`` includes ``extra_story_stiffness`` both for the frequencies and in ``C``.
        """
        if not (math.isfinite(zeta) and zeta >= 0.0):
            raise ValueError(f"damping ratio must be finite and >= 0, got {zeta}")
        i, j = modes
        n = self.n_stories
        if not (1 <= i <= n and 1 <= j <= n) or i == j:
            raise ValueError(f"Rayleigh modes must be two distinct modes in 1..{n}, got {modes}")
        omega = self.modes(extra_story_stiffness).omega
        wi, wj = float(omega[i - 1]), float(omega[j - 1])
        if wi <= 0.0 or wj <= 0.0 or math.isclose(wi, wj):
            raise ValueError(
                f"Rayleigh damping needs two distinct non-zero frequencies, got {wi}, {wj} rad/s"
            )
        alpha_m = 2.0 * zeta * wi * wj / (wi + wj)
        beta_k = 2.0 * zeta / (wi + wj)
        damping = alpha_m * self.mass_matrix() + beta_k * self.stiffness_matrix(
            extra_story_stiffness
        )
        return alpha_m, beta_k, damping

    def floor_to_drifts(self, u: npt.ArrayLike) -> FloatArray:
        """Story drifts from floor displacements; works on (n,) or a (steps, n) history."""
        arr = np.asarray(u, dtype=np.float64)
        if arr.shape[-1] != self.n_stories:
            raise ValueError(f"expected {self.n_stories} floor values, got shape {arr.shape}")
        return np.asarray(arr @ self.drift_matrix().T)

    def story_forces_to_floor(self, f_story: npt.ArrayLike) -> FloatArray:
        """Floor resisting forces ``T^T f`` from story restoring forces (see module doc)."""
        arr = np.asarray(f_story, dtype=np.float64)
        if arr.shape[-1] != self.n_stories:
            raise ValueError(f"expected {self.n_stories} story forces, got shape {arr.shape}")
        return np.asarray(arr @ self.drift_matrix())
