"""``conventional_calibrated``: the Bilinear a careful engineer fits to the offline database.

Least squares of the force over the offline history, the Bilinear (Steel01) driven by the
offline displacements: a coarse grid (60 points around the small-amplitude secant stiffness and
30-90 % of the peak force), then a pattern search in log-parameter space from its best point
(about 150 more model runs; no scipy). alpha is kept in [1e-4, 0.5].
"""

from __future__ import annotations

import math

import numpy as np
import numpy.typing as npt

from sim_actuator.models import Bilinear

__all__ = ["bilinear_rms", "calibrate_bilinear"]


def bilinear_rms(params: dict[str, float], disp: npt.ArrayLike, force: npt.ArrayLike) -> float:
    """RMS force error of a Bilinear driven through ``disp`` against ``force``."""
    model = Bilinear(**params)
    d = np.asarray(disp, dtype=np.float64)
    f = np.asarray(force, dtype=np.float64)
    total = 0.0
    for di, fi in zip(d.tolist(), f.tolist(), strict=True):
        pred, _ = model.set_trial(di)
        model.commit()
        total += (pred - fi) ** 2
    return math.sqrt(total / max(len(d), 1))


def calibrate_bilinear(disp: npt.ArrayLike, force: npt.ArrayLike) -> dict[str, float]:
    """Bilinear parameters (k0, fy, alpha) minimising the RMS force error on the data."""
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

    def unpack(v: npt.NDArray[np.float64]) -> dict[str, float]:
        return {"k0": float(math.exp(v[0])), "fy": float(math.exp(v[1])),
                "alpha": float(min(max(math.exp(v[2]), 1e-4), 0.5))}  # fmt: skip

    # Coarse grid first (the error surface has poor local minima, e.g. k0 -> small with noisy
    # data), then a pattern search from the best grid point.
    grid = [
        np.log([k_est * kf, peak * ff, a])
        for kf in (0.5, 0.75, 1.0, 1.5, 2.0)
        for ff in (0.3, 0.5, 0.7, 0.9)
        for a in (0.01, 0.04, 0.15)
    ]
    scores = [bilinear_rms(unpack(v), d, f) for v in grid]
    x = grid[int(np.argmin(scores))]
    best = min(scores)
    step = 0.3
    while step > 0.005:
        improved = False
        for axis in range(3):
            for sign in (1.0, -1.0):
                trial = x.copy()
                trial[axis] += sign * step
                value = bilinear_rms(unpack(trial), d, f)
                if value < best:
                    x, best, improved = trial, value, True
        if not improved:
            step *= 0.5
    return unpack(x)
