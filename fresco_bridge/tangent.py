"""Measured tangent stiffness: the answer to an implicit integrator's tangent request (action
13) estimated from the specimen's committed increments, as OpenFresco's
``expTangentStiff Broyden | BFGS | Transpose`` do.

An implicit scheme (Newton) asks the element's tangent on every iteration, and each iteration
is a physical move of the actuators. A constant initial stiffness is wrong past yield, so
Newton needs more moves; a secant estimate from the committed steps follows the specimen.
The estimators work in actuator space on (Δctrl, Δdaq force) of consecutive committed steps;
the site maps the estimate to basic DOFs through its setup.

Within a step the estimate must still make Newton contract: OpenSees' Newton with a tangent K
converges for specimen slopes between 0 and 2K only, and a secant below half the elastic
stiffness (the post-yield slope) makes it cycle once an iteration re-enters the elastic
branch. So the trials of the step are watched: when a correction is no smaller than the one
before it, the rest of the step is answered with the initial stiffness, under which a
hardening specimen always contracts (BENCHMARKS.md, "Measured tangent").

An update that would give the integrator a matrix
it cannot use — not finite, singular, or
with a symmetric part that is not positive definite (a step whose force increment opposes its
displacement: noise, a reversal inside a step) — is refused: the previous estimate stays and
the caller raises an event. Pure numerics: no I/O, no clock.
"""

from __future__ import annotations

from collections import deque
from typing import Literal

import numpy as np
import numpy.typing as npt

Matrix = npt.NDArray[np.float64]
TangentMethod = Literal["controller", "initial", "broyden", "bfgs", "transpose"]
"""``controller``: the controller's own answer (a sim specimen's exact tangent, a lab
controller's configured stiffness); ``initial``: the first answer, kept; ``broyden``,
``bfgs``, ``transpose``: estimated from the committed increments."""

BFGS_EPS = 0.1
"""BFGS skips an increment whose force and displacement are closer to orthogonal than this
cosine (OpenFresco's ``-eps``): it carries no curvature information."""
CONDITION_LIMIT = 1e12
"""An estimate with a worse condition number is singular for the integrator's solver."""


class TangentEstimate:
    """The tangent estimate of one site session, ``n`` × ``n`` in actuator space."""

    def __init__(self, method: TangentMethod, n: int, *, columns: int | None = None) -> None:
        self.method = method
        self.n = n
        self.k: Matrix | None = None
        self.k_initial: Matrix | None = None
        self._last: tuple[Matrix, Matrix] | None = None
        self.columns = columns if columns is not None else 2 * n
        """Transpose: how many of the latest increments the least-squares fit uses."""
        self._history: deque[tuple[Matrix, Matrix]] = deque(maxlen=self.columns)
        self.updates = 0
        self.refusals = 0
        self.fallbacks = 0
        """Steps answered with the initial stiffness because Newton stopped contracting."""
        self._step: list[Matrix] = []
        self._initial_for_step = False

    def answer(self, controller_k: tuple[float, ...]) -> tuple[float, ...]:
        """The tangent to answer (column-major) given the controller's; the first answer
        seeds the estimate."""
        if self.method == "controller":
            return controller_k
        if self.k is None:
            k0 = np.array(controller_k, dtype=np.float64).reshape(self.n, self.n, order="F")
            self.k, self.k_initial = k0.copy(), k0.copy()
        k = self.k_initial if self._initial_for_step else self.k
        assert k is not None
        return tuple(k.ravel(order="F").tolist())

    def trial(self, disp: tuple[float, ...]) -> str | None:
        """A trial of the current step (actuator displacements); returns why the rest of the
        step is answered with the initial stiffness, once, or None."""
        if self.method == "controller" or self.method == "initial" or self._initial_for_step:
            return None
        self._step.append(np.asarray(disp, dtype=np.float64))
        if len(self._step) < 3:
            return None
        a, b, c = self._step[-3:]
        if float(np.linalg.norm(c - b)) < float(np.linalg.norm(b - a)):
            return None
        self._initial_for_step = True
        self.fallbacks += 1
        return (f"Newton stopped contracting under the {self.method} tangent (correction "
                f"{float(np.linalg.norm(c - b)):.3g} after {float(np.linalg.norm(b - a)):.3g}); "
                "the initial stiffness answers for the rest of this step")

    def committed(self, disp: tuple[float, ...], force: tuple[float, ...]) -> str | None:
        """A committed step's actuator displacements and forces; returns why an update was
        refused (the estimate is unchanged then), or None."""
        if self.method == "controller" or self.method == "initial":
            return None  # nothing to learn (the step path pays one comparison)
        self._step.clear()
        self._initial_for_step = False
        d, f = np.asarray(disp, dtype=np.float64), np.asarray(force, dtype=np.float64)
        if not (np.all(np.isfinite(d)) and np.all(np.isfinite(f))):
            return self._refuse("a non-finite measurement")  # and it is no new base either
        last, self._last = self._last, (d, f)
        if last is None or self.k is None:
            return None
        dd, df = d - last[0], f - last[1]
        if not np.any(dd):
            return None  # no motion, no information (OpenFresco keeps the estimate too)
        assert self.k_initial is not None
        if self.method == "broyden":
            k = broyden(self.k, dd, df)
        elif self.method == "bfgs":
            k = bfgs(self.k, self.k_initial, dd, df)
        else:
            self._history.append((dd, df))
            k = transpose(self._history, self.k_initial)
        why = unusable(k)
        if why is not None:
            return self._refuse(why)
        self.k = k
        self.updates += 1
        return None

    def _refuse(self, why: str) -> str:
        self.refusals += 1
        return f"{self.method} tangent update refused ({why}); the previous estimate stays"


def broyden(k: Matrix, dd: Matrix, df: Matrix) -> Matrix:
    """Broyden's rank-one update: the least change of ``k`` that maps Δd onto Δf."""
    out: Matrix = k + np.outer(df - k @ dd, dd) / float(dd @ dd)
    return out


def bfgs(k: Matrix, k_initial: Matrix, dd: Matrix, df: Matrix) -> Matrix:
    """The BFGS-type update of Thewalt and Igarashi as OpenFresco applies it: skipped when
    Δfᵀ Δd ≤ eps ‖Δd‖ ‖Δf‖; else from the previous or the initial estimate, whichever
    changes less (Frobenius norm)."""
    fd = float(df @ dd)
    if BFGS_EPS * float(np.linalg.norm(dd) * np.linalg.norm(df)) >= fd:
        return k

    def change(base: Matrix) -> Matrix:
        kd = base @ dd
        factor = (1.0 + float(dd @ kd) / fd) / fd
        out: Matrix = (factor * np.outer(df, df) - np.outer(df, dd @ base) / fd
                       - np.outer(kd, df) / fd)
        return out

    from_initial, from_previous = change(k_initial), change(k)
    if np.linalg.norm(from_initial) <= np.linalg.norm(from_previous):
        return k_initial + from_initial
    return k + from_previous


def transpose(history: deque[tuple[Matrix, Matrix]], k_initial: Matrix) -> Matrix:
    """The stiffness that best maps the latest increments: K = F Dᵀ (D Dᵀ)⁻¹ over the stored
    columns (exact with n of them); the initial stiffness until there are n."""
    n = k_initial.shape[0]
    if len(history) < n:
        return k_initial
    d = np.column_stack([dd for dd, _ in history])
    f = np.column_stack([df for _, df in history])
    try:
        out: Matrix = np.asarray(np.linalg.solve(d @ d.T, d @ f.T).T, dtype=np.float64)
    except np.linalg.LinAlgError:
        return np.full_like(k_initial, np.nan)
    return out


def unusable(k: Matrix) -> str | None:
    """Why ``k`` cannot be an integrator's tangent, or None."""
    if not np.all(np.isfinite(k)):
        return "not finite"
    sym = 0.5 * (k + k.T)
    eig = np.linalg.eigvalsh(sym)
    if eig[0] <= 0.0:
        return f"not positive definite: smallest eigenvalue {eig[0]:.3g}"
    if eig[-1] / eig[0] > CONDITION_LIMIT:
        return f"singular: condition number {eig[-1] / eig[0]:.3g}"
    return None
