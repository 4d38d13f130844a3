"""Weighted Levenberg-Marquardt for the MLP, in the form of MATLAB's ``trainlm`` (the paper's tool).

Cost: ``C(theta) = sum_i w_i * (net(x_i; theta) - y_i)**2`` with the weights scaled to mean 1, so
``J^T W J`` has the scale of ``trainlm``'s unweighted ``J^T J`` over the same samples and the
paper's damping ``mu = 1e-5`` means what it meant there.

One iteration (``trainlm``): with the Jacobian ``J`` and residuals ``r`` at ``theta``, solve
``(J^T W J + mu I) delta = -J^T W r`` (Cholesky); the step is ``delta + momentum * previous
step``; accept it if the cost decreases (then ``mu *= mu_decrease``), else ``mu *= mu_increase``,
drop the momentum term and solve again, until accepted or ``mu > mu_max``.

Stopping rule, first that holds: ``max_iterations`` accepted iterations; gradient norm
``|J^T W r| < min_gradient``; ``mu > mu_max`` (no decrease found); and, only when
``rtol > 0``, an accepted iteration that lowered the cost by less than ``rtol`` (relative).
``rtol = 0`` is ``trainlm`` with its defaults (epochs, min_grad 1e-7, mu_max 1e10) and no data
division (MATLAB's validation stop lost on the twin: ``BENCHMARKS.md``, "Online updating").
``mu`` restarts at ``mu`` on every call, as every ``train`` call does in MATLAB.

BLAS runs on one thread inside a fit: numpy's and scipy's OpenBLAS pools each spin 2 threads,
and alternating gemm (numpy) with Cholesky (scipy) on 2 cores makes one fit several times
slower (``BENCHMARKS.md``, "Online updating").
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any

import numpy as np
import numpy.typing as npt
from scipy.linalg.blas import dsyrk, ssyrk  # type: ignore[import-untyped]
from scipy.linalg.lapack import dpotrf, dpotrs  # type: ignore[import-untyped]
from threadpoolctl import ThreadpoolController  # type: ignore[import-untyped]

from .base import UpdaterError
from .mlp import Mlp

FloatArray = npt.NDArray[np.float64]

__all__ = ["LmOptions", "LmResult", "levenberg_marquardt"]


@dataclass(frozen=True, slots=True)
class LmOptions:
    """Levenberg-Marquardt settings; the defaults are the paper's online settings."""

    max_iterations: int = 50
    mu: float = 1e-5
    mu_decrease: float = 0.1
    mu_increase: float = 10.0
    mu_max: float = 1e10
    momentum: float = 0.1
    min_gradient: float = 1e-7
    rtol: float = 0.0
    single_precision_hessian: bool = False
    """J and J^T W J in float32 (BLAS ssyrk, faster); gradient, Cholesky, costs and parameters
    stay float64. Not exact: ``BENCHMARKS.md``, "Online updating", measures what it changes."""

    def __post_init__(self) -> None:
        checks = {
            "max_iterations": self.max_iterations >= 0,
            "mu": self.mu > 0.0 and math.isfinite(self.mu),
            "mu_decrease": 0.0 < self.mu_decrease < 1.0,
            "mu_increase": self.mu_increase > 1.0 and math.isfinite(self.mu_increase),
            "mu_max": self.mu_max > self.mu,
            "momentum": 0.0 <= self.momentum < 1.0,
            "min_gradient": self.min_gradient >= 0.0,
            "rtol": 0.0 <= self.rtol < 1.0,
        }
        bad = [name for name, ok in checks.items() if not ok]
        if bad:
            raise UpdaterError(f"LM options: invalid {', '.join(bad)} in {self!r}")


@dataclass(slots=True)
class LmResult:
    """The fitted parameters and how the iteration ended."""

    theta: FloatArray
    cost: float
    initial_cost: float
    iterations: int
    jacobians: int
    stop: str
    """``max_iterations``, ``gradient``, ``mu_max``, ``rtol`` or ``cost_zero``."""
    costs: list[float] = field(default_factory=list)
    factorisations: int = 0
    """Cholesky factorisations (one per damping tried: accepted steps plus rejected trials)."""


_CONTROLLER: ThreadpoolController | None = None


def one_blas_thread() -> Any:
    """A context that limits every loaded BLAS pool to one thread. Entering it calls into every
    loaded BLAS library, so it wraps a whole fit, never one iteration."""
    global _CONTROLLER
    if _CONTROLLER is None:
        _CONTROLLER = ThreadpoolController()
    return _CONTROLLER.limit(limits=1)


def _weights(w: FloatArray | None, n: int) -> FloatArray:
    if w is None:
        return np.ones(n)
    if w.shape != (n,) or not np.all(np.isfinite(w)) or np.any(w < 0.0) or w.sum() <= 0.0:
        raise UpdaterError("LM: weights must be n finite non-negative numbers with a positive sum")
    scaled: FloatArray = w * (n / w.sum())
    return scaled


def levenberg_marquardt(
    net: Mlp,
    theta0: FloatArray,
    x: FloatArray,
    y: FloatArray,
    w: FloatArray | None = None,
    options: LmOptions = LmOptions(),
    progress: Callable[[int, int], None] | None = None,
) -> LmResult:
    """Minimise the weighted squared error of ``net`` on (x, y) from ``theta0`` (not modified).

    ``progress(iteration, max_iterations)`` is called after every accepted iteration.
    """
    with one_blas_thread():
        return _levenberg_marquardt(net, theta0, x, y, w, options, progress)


def _levenberg_marquardt(
    net: Mlp,
    theta0: FloatArray,
    x: FloatArray,
    y: FloatArray,
    w: FloatArray | None,
    options: LmOptions,
    progress: Callable[[int, int], None] | None,
) -> LmResult:
    n = x.shape[0]
    if y.shape != (n,) or n == 0:
        raise UpdaterError(
            f"LM: need n >= 1 samples with one target each, got {x.shape}, {y.shape}"
        )
    weights = _weights(w, n)
    sqrt_w = np.sqrt(weights)
    theta = theta0.copy()
    n_params = net.n_params
    # J^T W J as (sqrt(W) J)^T (sqrt(W) J) by BLAS syrk (half the flops of a general product):
    # the rows of J come out of the Jacobian already scaled by sqrt(w), Fortran-ordered, so
    # syrk (trans) reads it in place. Only the lower triangle is formed; LAPACK's Cholesky
    # (potrf/potrs) reads only that, from a copy, so mu retries reuse it.
    single = options.single_precision_hessian
    dtype = np.float32 if single else np.float64
    syrk = ssyrk if single else dsyrk
    jac = np.empty((n, n_params), dtype=dtype, order="F")
    hess = np.zeros((n_params, n_params), dtype=dtype, order="F")
    work = np.empty((n_params, n_params), order="F")
    diag = np.arange(n_params)
    acts = net.activations(theta, x)
    r = acts[-1][:, 0] - y
    cost = float(weights @ (r * r))
    result = LmResult(theta, cost, cost, 0, 0, "max_iterations", [cost])
    mu = options.mu
    step_prev = np.zeros(n_params)
    while result.iterations < options.max_iterations:
        if cost == 0.0:
            result.stop = "cost_zero"
            break
        net.jacobian(theta, x, out=jac, acts=acts, row_scale=sqrt_w)
        result.jacobians += 1
        grad = (jac.T @ (r * sqrt_w).astype(dtype)).astype(np.float64, copy=False)
        if float(np.linalg.norm(grad)) < options.min_gradient:
            result.stop = "gradient"
            break
        hess = syrk(1.0, jac, lower=1, trans=1, c=hess, overwrite_c=1)
        accepted = False
        while mu <= options.mu_max:
            work[...] = hess  # (cast to float64 when J^T W J is single precision)
            work[diag, diag] += mu
            factor, info = dpotrf(work, lower=1, clean=0, overwrite_a=1)
            result.factorisations += 1
            if info != 0:  # not positive definite at this mu
                mu *= options.mu_increase
                step_prev[:] = 0.0
                continue
            step, _ = dpotrs(factor, grad, lower=1)
            step = -step + options.momentum * step_prev
            candidate = theta + step
            cand_acts = net.activations(candidate, x)
            r_new = cand_acts[-1][:, 0] - y
            cost_new = float(weights @ (r_new * r_new))
            if cost_new < cost:
                accepted = True
                mu *= options.mu_decrease
                break
            mu *= options.mu_increase
            step_prev[:] = 0.0
        if not accepted:
            result.stop = "mu_max"
            break
        decrease = (cost - cost_new) / cost
        theta, cost, step_prev, acts, r = candidate, cost_new, step, cand_acts, r_new
        result.iterations += 1
        result.costs.append(cost)
        if progress is not None:
            progress(result.iterations, options.max_iterations)
        if options.rtol > 0.0 and decrease < options.rtol:
            result.stop = "rtol"
            break
    result.theta = theta
    result.cost = cost
    return result
