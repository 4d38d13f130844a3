"""The paper's feature map and its min-max normalisation (pure numpy, no state beyond arrays).

For step ``i`` of a displacement/force history the input row is (Kim et al. 2012, used by the
source paper)::

    x_i = [d_i, d_{i-1}, F_{i-1}, F_{i-1}*d_{i-1}, F_{i-1}*(d_i - d_{i-1}), E_{i-1}]
    E_{i-1} = E_{i-2} + |F_{i-1}*d_{i-1}|        (E_{-1} = 0)

and the target is ``F_i``. A history starts from the virgin state ``d_{-1} = F_{-1} = 0``, so a
record of ``n`` committed steps gives ``n`` rows. ``E`` is the paper's "cumulative energy": the
running sum of ``|F*d|`` (not the integral of F dd), reproduced as published.

Normalisation (the paper's Eq. 4): every input column and the target are mapped to [0, 1] with
the *offline* database's min and max; online data outside that range map outside [0, 1]
(nothing is clipped). A column that is constant offline gets a unit range, so it maps to
``x - min`` instead of dividing by zero.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np
import numpy.typing as npt

from .base import UpdaterError

FloatArray = npt.NDArray[np.float64]

__all__ = [
    "PAPER_FEATURES",
    "FeatureSpec",
    "MinMaxScaler",
    "feature_row",
    "feature_rows",
    "next_energy",
]


@dataclass(frozen=True, slots=True)
class FeatureSpec:
    """Which feature map a network was trained on; a model file records it and is checked."""

    name: str
    version: int
    inputs: tuple[str, ...]
    output: str

    def as_dict(self) -> dict[str, Any]:
        return {"name": self.name, "version": self.version, "inputs": list(self.inputs),
                "output": self.output}

    @classmethod
    def from_dict(cls, data: Any, *, where: str) -> FeatureSpec:
        """The spec a file claims; UpdaterError when it is not one this code computes."""
        if not isinstance(data, dict):
            raise UpdaterError(
                f"{where}: feature spec must be a mapping, got {type(data).__name__}"
            )
        try:
            spec = cls(str(data["name"]), int(data["version"]),
                       tuple(str(v) for v in data["inputs"]), str(data["output"]))
        except (KeyError, TypeError, ValueError) as exc:
            raise UpdaterError(f"{where}: malformed feature spec {data!r} ({exc})") from exc
        if spec != PAPER_FEATURES:
            raise UpdaterError(
                f"{where}: feature spec {spec.name!r} v{spec.version} "
                f"(inputs {', '.join(spec.inputs)}) is not the one this fresco-bridge computes "
                f"({PAPER_FEATURES.name!r} v{PAPER_FEATURES.version}: "
                f"{', '.join(PAPER_FEATURES.inputs)}); retrain the model with "
                "`fresco-bridge updater pretrain`"
            )
        return spec


PAPER_FEATURES = FeatureSpec(
    name="paper6",
    version=1,
    inputs=("d_i", "d_im1", "F_im1", "F_im1*d_im1", "F_im1*dd_i", "E_im1"),
    output="F_i",
)
"""The source paper's 6-input map (Kim et al. 2012); units mm and kN (E in kN*mm)."""

N_FEATURES = len(PAPER_FEATURES.inputs)


def next_energy(energy: float, d: float, force: float) -> float:
    """E_i = E_{i-1} + |F_i*d_i|: the energy after committing (d_i, F_i)."""
    return energy + abs(force * d)


def feature_row(d: float, d_prev: float, f_prev: float, e_prev: float,
                out: FloatArray | None = None) -> FloatArray:
    """One input row for a trial ``d`` after the committed (d_prev, f_prev, e_prev)."""
    row = np.empty(N_FEATURES) if out is None else out
    row[0] = d
    row[1] = d_prev
    row[2] = f_prev
    row[3] = f_prev * d_prev
    row[4] = f_prev * (d - d_prev)
    row[5] = e_prev
    return row


def feature_rows(d: npt.ArrayLike, force: npt.ArrayLike) -> tuple[FloatArray, FloatArray]:
    """(X, y) for a whole history from the virgin state: X is n x 6, y = force (n,)."""
    disp = np.asarray(d, dtype=np.float64)
    f = np.asarray(force, dtype=np.float64)
    if disp.ndim != 1 or disp.shape != f.shape:
        raise UpdaterError(
            f"feature_rows: d and force must be 1-D of equal length, got {disp.shape} and {f.shape}"
        )
    if not (np.all(np.isfinite(disp)) and np.all(np.isfinite(f))):
        raise UpdaterError("feature_rows: d and force must be finite (found NaN or inf)")
    d_prev = np.concatenate(([0.0], disp[:-1]))
    f_prev = np.concatenate(([0.0], f[:-1]))
    e_steps = np.abs(f * disp)
    e_prev = np.concatenate(([0.0], np.cumsum(e_steps)[:-1]))
    x = np.column_stack((disp, d_prev, f_prev, f_prev * d_prev, f_prev * (disp - d_prev), e_prev))
    return x, f.copy()


@dataclass(frozen=True, slots=True)
class MinMaxScaler:
    """Min-max map of the inputs and the target to [0, 1] over a reference (offline) data set."""

    x_min: FloatArray
    x_range: FloatArray
    y_min: float
    y_range: float

    @classmethod
    def fit(cls, x: FloatArray, y: FloatArray) -> MinMaxScaler:
        if x.ndim != 2 or x.shape[0] == 0 or y.shape != (x.shape[0],):
            raise UpdaterError(f"MinMaxScaler.fit: need n x k inputs and n targets, n >= 1, "
                               f"got {x.shape} and {y.shape}")
        x_min = x.min(axis=0)
        x_range = x.max(axis=0) - x_min
        x_range = np.where(x_range > 0.0, x_range, 1.0)
        y_min = float(y.min())
        y_range = float(y.max()) - y_min
        return cls(x_min, x_range, y_min, y_range if y_range > 0.0 else 1.0)

    @classmethod
    def from_bounds(cls, x_min: npt.ArrayLike, x_max: npt.ArrayLike, y_min: float,
                    y_max: float, *, where: str = "normalisation") -> MinMaxScaler:
        """Rebuild from stored bounds (a model file); checks shapes and finiteness."""
        lo = np.asarray(x_min, dtype=np.float64).reshape(-1)
        hi = np.asarray(x_max, dtype=np.float64).reshape(-1)
        if lo.shape != (N_FEATURES,) or hi.shape != (N_FEATURES,):
            raise UpdaterError(f"{where}: x bounds must have {N_FEATURES} entries, "
                               f"got {lo.size} and {hi.size}")
        values = [*lo, *hi, y_min, y_max]
        if not all(math.isfinite(float(v)) for v in values) or np.any(hi < lo) or y_max < y_min:
            raise UpdaterError(f"{where}: bounds must be finite with max >= min")
        rng = hi - lo
        y_rng = float(y_max) - float(y_min)
        return cls(lo, np.where(rng > 0.0, rng, 1.0), float(y_min), y_rng if y_rng > 0 else 1.0)

    @property
    def x_max(self) -> FloatArray:
        return self.x_min + self.x_range

    @property
    def y_max(self) -> float:
        return self.y_min + self.y_range

    def x(self, x: FloatArray) -> FloatArray:
        """Inputs to normalised inputs (rows or one row)."""
        return (x - self.x_min) / self.x_range

    def y(self, y: FloatArray) -> FloatArray:
        """Targets to normalised targets."""
        return (y - self.y_min) / self.y_range

    def y_inverse(self, y_norm: float) -> float:
        """A normalised network output back to a force (kN)."""
        return y_norm * self.y_range + self.y_min
