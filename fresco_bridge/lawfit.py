"""Fitting a hysteresis law to a measured (displacement, force) history: the one home.

The study's calibration, the updaters' refits and the diagnosis' baselines all fit a law of
``sim_actuator.models`` to a measured history, so the fitting itself lives here, below
``updating/``, ``study/`` and ``diagnosis/``, pure numerics (no I/O, no updater or record
types):

* :func:`bounded_least_squares`: scipy's trust-region least squares inside bounds, from a start
  clipped into them; every caller's tolerances, scales and Jacobian pass through unchanged;
* :func:`difference_step` and :func:`parameter_std`: the forward-difference step of a
  Jacobian column and the Gauss-Newton uncertainty of a fit, for every caller that builds its
  own (batched or per-record) Jacobian;
* :func:`multi_start`: a few evaluations from each start, then the best one to convergence
  (a law's misfit surface has local minima: a smooth and a sharp transition fit apart);
* :class:`LawFamily` and :func:`fit_law`: a law with named free parameters, fitted on one or
  several weighted histories, each from the virgin state (the updaters' online refits);
* :func:`calibrate_bilinear`: the Bilinear a careful engineer fits to an offline database,
  the baseline every updater is compared with (``conventional_calibrated``).
"""

from __future__ import annotations

import math
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass
from typing import Any, TypeVar

import numpy as np
import numpy.typing as npt

from sim_actuator.models import Bilinear
from sim_actuator.models.base import HysteresisModel, ModelInputError, ModelParameterError

__all__ = [
    "FitSpace",
    "LawFamily",
    "Solution",
    "autocorrelation",
    "bounded_least_squares",
    "calibrate_bilinear",
    "difference_step",
    "fit_law",
    "law_forces",
    "multi_start",
    "parameter_std",
]

FloatArray = npt.NDArray[np.float64]
Start = TypeVar("Start")
Result = TypeVar("Result")


@dataclass(frozen=True)
class Solution:
    """Where a bounded least-squares fit stopped."""

    x: FloatArray
    residual: FloatArray
    jacobian: FloatArray
    success: bool
    message: str


def bounded_least_squares(residual: Callable[[FloatArray], FloatArray],
                          start: Sequence[float] | FloatArray, lower: FloatArray,
                          upper: FloatArray, *, scale: FloatArray | str, max_nfev: int,
                          jac: Callable[[FloatArray], FloatArray] | None = None,
                          tolerance: float = 1e-8) -> Solution:
    """Minimise the sum of squares of ``residual(x)`` for ``lower <= x <= upper`` (scipy's
    ``trf``), from ``start`` clipped into the bounds. ``scale``: ``least_squares``'s
    ``x_scale`` (each parameter's typical magnitude, or ``"jac"``); ``jac``: the Jacobian
    (a forward difference when None); ``tolerance``: ``ftol`` and ``xtol``."""
    from scipy.optimize import least_squares  # type: ignore[import-untyped]

    x0 = np.clip(np.array(start, dtype=np.float64), lower, upper)
    fit: Any = least_squares(residual, x0, jac="2-point" if jac is None else jac,
                             bounds=(lower, upper), method="trf", x_scale=scale,
                             max_nfev=max_nfev, ftol=tolerance, xtol=tolerance,
                             gtol=1e-8)  # fmt: skip
    return Solution(np.asarray(fit.x, dtype=np.float64), np.asarray(fit.fun, dtype=np.float64),
                    np.asarray(fit.jac, dtype=np.float64), bool(fit.success), str(fit.message))


def difference_step(x: float, lower: float, upper: float) -> float:
    """The forward-difference step of a Jacobian column: 1e-3 of the parameter's magnitude (of
    1 % of its range when nearer zero), taken backwards when it would cross the upper bound."""
    h = 1e-3 * max(abs(x), 1e-2 * (upper - lower))
    return -h if x + h > upper else h


def autocorrelation(r: FloatArray) -> float:
    """The lag-1 autocorrelation of a residual (0 for a constant one)."""
    r = r - r.mean()
    denom = float(np.dot(r, r))
    return float(np.dot(r[1:], r[:-1])) / denom if denom > 0.0 else 0.0


def parameter_std(residual: FloatArray, jacobian: FloatArray) -> FloatArray:
    """Each parameter's std from the Gauss-Newton covariance ``s² (JᵀJ)⁺`` at a fit, with s²
    inflated by (1 + ρ)/(1 − ρ) for the residual's lag-1 autocorrelation ρ (clipped to
    [0, 0.99]): correlated residuals carry less information than their count says."""
    dof = max(residual.size - jacobian.shape[1], 1)
    rho = min(max(autocorrelation(residual), 0.0), 0.99)
    s2 = float(np.dot(residual, residual)) / dof * (1.0 + rho) / (1.0 - rho)
    cov = s2 * np.linalg.pinv(jacobian.T @ jacobian)
    return np.sqrt(np.maximum(np.diag(cov), 0.0))


def multi_start(fit: Callable[[Start, int], Result], starts: Sequence[Start], *,
                cost: Callable[[Result], float], resume: Callable[[Result], Start],
                scout: int, final: int) -> Result:
    """``fit(start, evaluations)`` from every start with ``scout`` evaluations, then from where
    the lowest ``cost`` stopped (the first of equals) with ``final``."""
    best = min((fit(start, scout) for start in starts), key=cost)
    return fit(resume(best), final)


@dataclass(frozen=True)
class FitSpace:
    """Start, bounds and scale of the free parameters (in ``LawFamily.free`` order)."""

    start: tuple[float, ...]
    lower: tuple[float, ...]
    upper: tuple[float, ...]
    scale: tuple[float, ...]
    """Typical magnitude of each parameter (``least_squares``'s ``x_scale``)."""


@dataclass(frozen=True)
class LawFamily:
    """A law with named free parameters: ``build(params)`` a virgin model from the free
    parameters by name (the fixed ones closed over), ``space(disp, force)`` where to start and
    the bounds, from a measured (d, F) history."""

    name: str
    free: tuple[str, ...]
    build: Callable[[Mapping[str, float]], HysteresisModel]
    space: Callable[[FloatArray, FloatArray], FitSpace]
    forces: Callable[[Mapping[str, float], FloatArray], FloatArray] | None = None
    """Optional fast form of ``law_forces(build(params), disp)`` for the fit (e.g. a JIT drive
    of ``sim_actuator.models.paths``, the same algorithm); NaN where the law refuses."""

    def params(self, x: Sequence[float] | FloatArray) -> dict[str, float]:
        """The free parameters by name."""
        return dict(zip(self.free, (float(v) for v in x), strict=True))


def law_forces(model: HysteresisModel, disp: FloatArray) -> FloatArray:
    """Force of ``model`` (moved along ``disp`` and committed step by step) at every sample."""
    out = np.empty(disp.size)
    trial, commit = model.set_trial, model.commit
    for i, d in enumerate(disp.tolist()):
        out[i] = trial(d)[0]
        commit()
    return out


def fit_law(family: LawFamily, histories: Sequence[tuple[FloatArray, FloatArray, float]],
            space: FitSpace, start: Sequence[float] | FloatArray | None = None, max_nfev: int = 20,
            penalty: float | None = None) -> FloatArray:
    """Free parameters minimising sum over ``histories`` (disp, force, weight), each run from the
    virgin state, of weight × squared force error; warm start ``start`` (``space.start`` when
    None), clipped into the bounds. A parameter set the law rejects scores ``penalty`` at every
    sample (default: 10 × the peak |force|)."""
    roots = [np.sqrt(w) for _, _, w in histories]
    size = sum(d.size for d, _, _ in histories)
    peak = max((float(np.max(np.abs(f))) for _, f, _ in histories if f.size), default=1.0)
    bad = np.full(size, 10.0 * peak if penalty is None else penalty)

    def residual(x: FloatArray) -> FloatArray:
        try:
            params = family.params(x)
            parts = [r * ((family.forces(params, d) if family.forces is not None
                           else law_forces(family.build(params), d)) - f)
                     for (d, f, _), r in zip(histories, roots, strict=True)]  # fmt: skip
        except (ModelInputError, ModelParameterError):
            return bad
        out = np.concatenate(parts) if parts else np.zeros(0)
        return out if np.all(np.isfinite(out)) else bad

    return bounded_least_squares(residual, space.start if start is None else start,
                                 np.array(space.lower), np.array(space.upper),
                                 scale=np.array(space.scale), max_nfev=max_nfev).x


def _bilinear_rms(params: dict[str, float], disp: FloatArray, force: FloatArray) -> float:
    """RMS force error of a Bilinear driven through ``disp`` against ``force``."""
    total = 0.0
    for pred, fi in zip(law_forces(Bilinear(**params), disp).tolist(), force.tolist(),
                        strict=True):  # fmt: skip
        total += (pred - fi) ** 2
    return math.sqrt(total / max(len(disp), 1))


def calibrate_bilinear(disp: npt.ArrayLike, force: npt.ArrayLike) -> dict[str, float]:
    """Bilinear parameters (k0, fy, alpha) minimising the RMS force error on a (d, F) history.

    A coarse grid (60 points around the small-amplitude secant stiffness and 30-90 % of the
    peak force) first, since the error surface has poor local minima (k0 -> small with noisy
    data), then a pattern search in log-parameter space from its best point; alpha is kept in
    [1e-4, 0.5]. ValueError for histories that are not two equal 1-D arrays of >= 10 samples.
    """
    d = np.asarray(disp, dtype=np.float64)
    f = np.asarray(force, dtype=np.float64)
    if d.shape != f.shape or d.ndim != 1 or d.size < 10:
        raise ValueError(f"calibration needs two equal 1-D histories of >= 10 samples, got "
                         f"shapes {d.shape} and {f.shape}")  # fmt: skip
    peak = float(np.max(np.abs(f)))
    small = np.abs(d) < 0.25 * float(np.max(np.abs(d)))
    denom = float(np.dot(d[small], d[small]))
    if denom > 0.0:
        k_est = float(np.dot(d[small], f[small]) / denom)
    else:
        k_est = peak / max(float(np.max(np.abs(d))), 1e-9)
    k_est = max(k_est, 1e-6)

    def unpack(v: FloatArray) -> dict[str, float]:
        return {"k0": float(math.exp(v[0])), "fy": float(math.exp(v[1])),
                "alpha": float(min(max(math.exp(v[2]), 1e-4), 0.5))}  # fmt: skip

    grid = [
        np.log([k_est * kf, peak * ff, a])
        for kf in (0.5, 0.75, 1.0, 1.5, 2.0)
        for ff in (0.3, 0.5, 0.7, 0.9)
        for a in (0.01, 0.04, 0.15)
    ]
    scores = [_bilinear_rms(unpack(v), d, f) for v in grid]
    x = grid[int(np.argmin(scores))]
    best = min(scores)
    step = 0.3
    while step > 0.005:
        improved = False
        for axis in range(3):
            for sign in (1.0, -1.0):
                trial = x.copy()
                trial[axis] += sign * step
                value = _bilinear_rms(unpack(trial), d, f)
                if value < best:
                    x, best, improved = trial, value, True
        if not improved:
            step *= 0.5
    return unpack(x)
