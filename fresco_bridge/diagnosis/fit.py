"""Least-squares fit of a model (baseline + effects) to the calibration part of a record.

A fit only ever receives the calibration part (``Record.part``): the law is causal, so the
prediction of the first samples needs nothing after them, and the withheld samples never reach
the residual. Residuals are the two channels, each normalised by its RMS (force by the measured
force, displacement by the command), so a 1 % displacement error weighs like a 1 % force error.

The solver, the difference step and the uncertainty are ``lawfit``'s
(``bounded_least_squares``, ``difference_step``, ``parameter_std``); the residual and the
Jacobian's batching are the diagnosis' own: every column that changes the law is one member of
a population driven in parallel (``drive_many`` of ``sim_actuator.models.paths``); columns of
output effects (friction, viscosity, offsets) reuse the base drive.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass

import numpy as np
import numpy.typing as npt

from fresco_bridge.lawfit import bounded_least_squares, difference_step, parameter_std
from sim_actuator.models.paths import drive_many

from .model import DZ_MAX, Context, Param, Spec, finish, law_force, law_vector, piston_path

__all__ = ["Fit", "fit_spec", "predict"]

FloatArray = npt.NDArray[np.float64]


@dataclass(frozen=True)
class Fit:
    """A fitted model: every parameter value (fitted and held) and the fitted ones' std."""

    spec: Spec
    values: dict[str, float]
    std: dict[str, float]
    cost: float
    """Mean squared normalised residual on the calibration part."""
    evaluations: int
    ok: bool
    message: str


def predict(spec: Spec, ctx: Context,
            values: Mapping[str, float]) -> tuple[FloatArray, FloatArray]:
    """(force, displacement) the model predicts for every sample of ``ctx``'s record."""
    return finish(ctx, values, law_force(spec, ctx, values))


class _Problem:
    """The residual and its batched Jacobian over the free parameters of ``spec``."""

    def __init__(self, spec: Spec, ctx: Context) -> None:
        self.spec, self.ctx = spec, ctx
        self.free: list[Param] = [p for p in spec.params if p.role != "noise"]
        self.lo = np.array([p.lo for p in self.free])
        self.hi = np.array([p.hi for p in self.free])
        rec = ctx.record
        self.f_scale = float(np.sqrt(np.mean(rec.force**2))) or 1.0
        self.d_scale = float(np.sqrt(np.mean(rec.cmd**2))) or 1.0
        self._cache: tuple[bytes, FloatArray] | None = None
        self.evaluations = 0

    def values(self, x: FloatArray) -> dict[str, float]:
        out = dict(self.spec.fixed)
        out.update({p.name: float(v) for p, v in zip(self.free, x, strict=True)})
        return out

    def law(self, x: FloatArray) -> FloatArray:
        key = x.tobytes()
        if self._cache is not None and self._cache[0] == key:
            return self._cache[1]
        self.evaluations += 1
        force = law_force(self.spec, self.ctx, self.values(x))
        self._cache = (key, force)
        return force

    def residual_from(self, x: FloatArray, force: FloatArray) -> FloatArray:
        rec = self.ctx.record
        f_hat, d_hat = finish(self.ctx, self.values(x), force)
        parts = [(f_hat - rec.force) / self.f_scale]
        if rec.meas_disp is not None:
            parts.append((d_hat - rec.meas_disp) / self.d_scale)
        r = np.concatenate(parts)
        return np.where(np.isfinite(r), r, 1e3)  # a refused history is a very bad fit

    def fun(self, x: FloatArray) -> FloatArray:
        return self.residual_from(x, self.law(x))

    def jac(self, x: FloatArray) -> FloatArray:
        base = self.law(x)
        r0 = self.residual_from(x, base)
        jac = np.empty((r0.size, x.size))
        population: list[tuple[int, float, FloatArray]] = []
        for j, p in enumerate(self.free):
            h = difference_step(float(x[j]), p.lo, p.hi)
            xj = x.copy()
            xj[j] += h
            if p.role == "out":
                jac[:, j] = (self.residual_from(xj, base) - r0) / h
            elif p.role == "path":
                self.evaluations += 1
                force = law_force(self.spec, self.ctx, self.values(xj))
                jac[:, j] = (self.residual_from(xj, force) - r0) / h
            else:
                population.append((j, h, xj))
        if population:
            path, index = piston_path(self.ctx, self.values(x))
            rows, gaps = [], []
            law = 0
            for _j, _h, xj in population:
                values = self.values(xj)
                law, vec = law_vector(self.spec.law_kind, values)
                rows.append(vec)
                gaps.append(values.get("gap", 0.0))
            self.evaluations += len(population)
            forces = drive_many(law, np.array(rows), path[None, :], np.array(gaps), DZ_MAX)
            for (j, h, xj), force in zip(population, forces, strict=True):
                jac[:, j] = (self.residual_from(xj, force[index]) - r0) / h
        return jac


def fit_spec(spec: Spec, ctx: Context, start: Mapping[str, float] | None = None, *,
             max_evaluations: int = 60, tolerance: float = 1e-6) -> Fit:
    """Fit ``spec`` to the whole of ``ctx`` (give it the calibration part only)."""
    from threadpoolctl import threadpool_limits  # type: ignore[import-untyped]

    problem = _Problem(spec, ctx)
    start = dict(start or {})
    x0 = np.array([start.get(p.name, p.init) for p in problem.free], dtype=np.float64)
    if not problem.free:
        r = problem.fun(x0)
        return Fit(spec, problem.values(x0), {}, float(np.mean(r * r)), problem.evaluations,
                   True, "nothing to fit")
    # One BLAS thread: on a loaded 2-core machine the SVD of a tall Jacobian is many times
    # slower with two threads than with one (BENCHMARKS.md, "Diagnosis"); records run in
    # parallel processes instead.
    with threadpool_limits(1):
        result = bounded_least_squares(problem.fun, x0, problem.lo, problem.hi, scale="jac",
                                       max_nfev=max_evaluations, jac=problem.jac,
                                       tolerance=tolerance)  # fmt: skip
    x, r = result.x, result.residual
    stds = parameter_std(r, result.jacobian)
    std = {p.name: float(stds[i]) for i, p in enumerate(problem.free)}
    return Fit(spec, problem.values(x), std, float(np.mean(r * r)), problem.evaluations,
               result.success, result.message)
