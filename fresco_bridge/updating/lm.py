"""Weighted Levenberg-Marquardt for the MLP, in the form of MATLAB's ``trainlm`` (the paper's tool).

Cost: ``C(theta) = sum_i w_i * (net(x_i; theta) - y_i)**2`` with the weights scaled to mean 1, so
``J^T W J`` has the scale of ``trainlm``'s unweighted ``J^T J`` over the same samples and the
paper's damping ``mu = 1e-5`` means what it meant there.

One iteration (``trainlm``): with the Jacobian ``J`` and residuals ``r`` at ``theta``, solve
``(J^T W J + mu I) delta = -J^T W r`` (Cholesky); the step is ``delta + momentum * previous
step``; accept it if the cost decreases (then ``mu *= mu_decrease``), else ``mu *= mu_increase``,
drop the momentum term and solve again, until accepted or ``mu > mu_max``.

Stopping rule, first that holds: ``max_iterations`` accepted iterations; gradient norm
``|J^T W r| < min_gradient``; ``mu > mu_max`` (no decrease found); with a validation set,
``max_fail`` iterations in a row whose validation cost is above the best so far (MATLAB's
"validation stop"; the fit returned is then the one of the best validation cost, as ``train``
returns it); and, only when ``rtol > 0``, an accepted iteration that lowered the cost by less
than ``rtol`` (relative). ``rtol = 0`` is ``trainlm`` with its defaults (epochs, min_grad 1e-7,
mu_max 1e10, max_fail 6). ``mu`` restarts at ``mu`` on every call, as every ``train`` call
does in MATLAB. :func:`divide_rand` is MATLAB's ``dividerand`` (the default data division of
``train``: 70 % training, 15 % validation, 15 % test, at random).

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

__all__ = ["DIVIDERAND_RATIOS", "LmOptions", "LmResult", "divide_rand", "levenberg_marquardt"]

DIVIDERAND_RATIOS = (0.70, 0.15, 0.15)
"""MATLAB ``dividerand``'s default training / validation / test ratios."""


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
    max_fail: int = 6
    """Validation stop after this many iterations above the best validation cost (needs a
    validation set; ``trainlm``'s default)."""
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
            "max_fail": self.max_fail >= 1,
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
    """``max_iterations``, ``gradient``, ``mu_max``, ``validation``, ``rtol`` or ``cost_zero``."""
    costs: list[float] = field(default_factory=list)
    factorisations: int = 0
    """Cholesky factorisations (one per damping tried: accepted steps plus rejected trials)."""
    best_iteration: int = -1
    """With a validation set: the iteration whose parameters are returned (0: the start)."""
    validation_costs: list[float] = field(default_factory=list)
    """With a validation set: its weighted cost at the start and after every iteration."""


def divide_rand(n: int, rng: np.random.Generator,
                ratios: tuple[float, float, float] = DIVIDERAND_RATIOS,
                ) -> tuple[npt.NDArray[np.intp], npt.NDArray[np.intp], npt.NDArray[np.intp]]:
    """MATLAB ``dividerand``: (training, validation, test) indices of ``n`` samples, each sorted.

    A random permutation split by the ratios (normalised to sum 1): ``round(n * val)``
    validation and ``round(n * test)`` test samples (MATLAB's round: halves away from zero),
    the rest for training.
    """
    if n < 0 or len(ratios) != 3 or any(not (math.isfinite(r) and r >= 0.0) for r in ratios) \
            or ratios[0] <= 0.0:
        raise UpdaterError(f"divide_rand: need n >= 0 and 3 finite ratios >= 0 with a positive "
                           f"training ratio, got n={n}, ratios={ratios!r}")
    total = sum(ratios)
    n_val = math.floor(n * ratios[1] / total + 0.5)
    n_test = math.floor(n * ratios[2] / total + 0.5)
    perm = rng.permutation(n)
    val = np.sort(perm[:n_val])
    test = np.sort(perm[n_val:n_val + n_test])
    train = np.sort(perm[n_val + n_test:])
    return train, val, test


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
    validation: tuple[FloatArray, FloatArray, FloatArray | None] | None = None,
) -> LmResult:
    """Minimise the weighted squared error of ``net`` on (x, y) from ``theta0`` (not modified).

    ``progress(iteration, max_iterations)`` is called after every accepted iteration.
    ``validation`` = (x, y, w or None): held-out samples for MATLAB's validation stop.
    """
    with one_blas_thread():
        return _levenberg_marquardt(net, theta0, x, y, w, options, progress, validation)


class _Validation:
    """MATLAB ``train``'s validation check: best cost so far, its parameters, failures in a row."""

    __slots__ = ("best", "best_iteration", "best_theta", "fails", "net", "w", "x", "y")

    def __init__(self, net: Mlp, data: tuple[FloatArray, FloatArray, FloatArray | None]) -> None:
        x, y, w = data
        if x.ndim != 2 or y.shape != (x.shape[0],) or y.size == 0:
            raise UpdaterError(f"LM: the validation set needs n >= 1 samples with one target "
                               f"each, got {x.shape}, {y.shape}")
        self.net, self.x, self.y, self.w = net, x, y, _weights(w, y.size)
        self.best = math.inf
        self.best_theta = np.empty(0)
        self.best_iteration = -1
        self.fails = 0

    def failed(self, theta: FloatArray, iteration: int, result: LmResult, max_fail: int) -> bool:
        """Score ``theta``; True when the validation cost has stayed above its best long enough."""
        r = self.net.forward(theta, self.x) - self.y
        cost = float(self.w @ (r * r))
        result.validation_costs.append(cost)
        if cost < self.best:
            self.best, self.best_theta, self.best_iteration, self.fails = cost, theta, iteration, 0
        elif cost > self.best:
            self.fails += 1
        return self.fails >= max_fail


def _levenberg_marquardt(
    net: Mlp,
    theta0: FloatArray,
    x: FloatArray,
    y: FloatArray,
    w: FloatArray | None,
    options: LmOptions,
    progress: Callable[[int, int], None] | None,
    validation: tuple[FloatArray, FloatArray, FloatArray | None] | None,
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
    check = None if validation is None else _Validation(net, validation)
    if check is not None:
        check.failed(theta, 0, result, options.max_fail)
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
        if check is not None and check.failed(theta, result.iterations, result,
                                              options.max_fail):
            result.stop = "validation"
            break
        if options.rtol > 0.0 and decrease < options.rtol:
            result.stop = "rtol"
            break
    if check is not None and check.best_iteration != result.iterations:
        # MATLAB returns the network of the best validation cost, whatever stopped the fit.
        theta = check.best_theta
        r = net.forward(theta, x) - y
        cost = float(weights @ (r * r))
    result.theta = theta
    result.cost = cost
    if check is not None:
        result.best_iteration = check.best_iteration
    return result
