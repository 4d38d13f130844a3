"""The paper's ANN restoring-force model: a trained network, its twin, and offline pre-training.

* :class:`AnnModel` — network shape + parameters + the offline data's normalisation + the
  feature spec + the offline database itself (the online updater re-samples it every step).
* :class:`AnnTwin` — the network as a hysteresis model with OpenSees material semantics: the
  features of a trial come from the twin's own last *committed* (d, F, E), so the force it
  feeds back is its own prediction (the paper's recurrence); trials never move that state.
* :func:`pretrain` — the paper's Step 1-2: Levenberg-Marquardt from a Nguyen-Widrow start on
  the whole offline database (``trainlm`` defaults: mu 1e-3, up to 1000 iterations).
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any

import numpy as np
import numpy.typing as npt

from sim_actuator.models.base import trial_input_error

from .base import UpdaterError
from .features import (
    PAPER_FEATURES,
    FeatureSpec,
    MinMaxScaler,
    feature_row,
    feature_rows,
    next_energy,
)
from .lm import LmOptions, LmResult, levenberg_marquardt
from .mlp import PAPER_LAYERS, Mlp

FloatArray = npt.NDArray[np.float64]

__all__ = ["PRETRAIN_LM", "AnnModel", "AnnTwin", "pretrain", "recurrence_warning"]

PRETRAIN_LM = LmOptions(max_iterations=1000, mu=1e-3, momentum=0.0)
"""Offline pre-training: MATLAB ``trainlm`` defaults (the paper does not state its own)."""


@dataclass(slots=True)
class AnnModel:
    """A trained restoring-force network and everything needed to use and update it."""

    net: Mlp
    theta: FloatArray
    scaler: MinMaxScaler
    offline_d: FloatArray
    """The offline database: displacement history (mm) of the tested element, in order."""
    offline_force: FloatArray
    """… and its measured force history (kN)."""
    spec: FeatureSpec = PAPER_FEATURES
    training: dict[str, Any] = field(default_factory=dict)
    """How it was trained (trainer, iterations, costs, seed, source); kept in model files."""

    def __post_init__(self) -> None:
        if self.theta.shape != (self.net.n_params,):
            raise UpdaterError(f"AnnModel: {self.net!r} needs {self.net.n_params} parameters, "
                               f"got {self.theta.shape}")
        if self.net.layers[0] != len(self.spec.inputs):
            raise UpdaterError(f"AnnModel: network has {self.net.layers[0]} inputs, feature spec "
                               f"{self.spec.name!r} has {len(self.spec.inputs)}")
        if not np.all(np.isfinite(self.theta)):
            raise UpdaterError("AnnModel: network parameters must be finite")

    def offline_samples(self) -> tuple[FloatArray, FloatArray]:
        """The offline database as normalised (X, y), one row per committed step."""
        x, y = feature_rows(self.offline_d, self.offline_force)
        return self.scaler.x(x), self.scaler.y(y)

    def predict_one_step(self, d: FloatArray, force: FloatArray) -> FloatArray:
        """Forces (kN) predicted from the *measured* previous step (teacher forcing)."""
        x, _ = feature_rows(d, force)
        return self.net.forward(self.theta, self.scaler.x(x)) * self.scaler.y_range \
            + self.scaler.y_min

    def simulate(self, d: FloatArray) -> FloatArray:
        """Forces (kN) of the twin driven through ``d`` from the virgin state (recurrence)."""
        twin = AnnTwin(self)
        out = np.empty(len(d))
        for i, di in enumerate(d):
            out[i] = twin.set_trial(float(di))[0]
            twin.commit()
        return out


class AnnTwin:
    """The network as a material: trial from the committed (d, F, E), commit advances it."""

    __slots__ = ("_d_c", "_d_t", "_e_c", "_f_c", "_f_t", "_k_c", "_k_t", "_params", "_row",
                 "model", "theta")

    name = "ann"

    def __init__(self, model: AnnModel, theta: FloatArray | None = None) -> None:
        self.model = model
        self._row = np.empty(len(model.spec.inputs))
        self.set_params(model.theta if theta is None else theta)
        self._d_c = self._d_t = 0.0
        self._f_c = self._f_t = 0.0
        self._e_c = 0.0
        self._k_c = self._k_t = self.initial_tangent

    def __repr__(self) -> str:
        return f"AnnTwin({self.model.net!r}, committed d={self._d_c!r}, F={self._f_c!r})"

    def set_params(self, theta: FloatArray) -> None:
        """Use new network parameters from now on; the committed (d, F, E) stay."""
        self.theta = theta
        self._params = self.model.net.unpack(theta)

    def _evaluate(self, d: float, d_c: float, f_c: float, e_c: float) -> tuple[float, float]:
        scaler = self.model.scaler
        xn = (feature_row(d, d_c, f_c, e_c, self._row) - scaler.x_min) / scaler.x_range
        acts = []
        a = xn
        for w, b in self._params[:-1]:
            a = np.tanh(w @ a + b)
            acts.append(a)
        w_last, b_last = self._params[-1]
        y = float(w_last[0] @ a + b_last[0])
        grad = w_last[0]
        for layer in range(len(self._params) - 2, -1, -1):
            grad = (grad * (1.0 - acts[layer] * acts[layer])) @ self._params[layer][0]
        # d x_0 / d d = 1 and d x_4 / d d = F_{i-1}; the other inputs do not depend on d.
        dy_dd = grad[0] / scaler.x_range[0] + grad[4] * f_c / scaler.x_range[4]
        return y * scaler.y_range + scaler.y_min, float(dy_dd) * scaler.y_range

    def set_trial(self, d: float) -> tuple[float, float]:
        if not math.isfinite(d):
            raise trial_input_error(self.name, d)
        force, tangent = self._evaluate(d, self._d_c, self._f_c, self._e_c)
        self._d_t, self._f_t, self._k_t = d, force, tangent
        return force, tangent

    def commit(self) -> None:
        self._e_c = next_energy(self._e_c, self._d_t, self._f_t)
        self._d_c, self._f_c, self._k_c = self._d_t, self._f_t, self._k_t

    def revert_to_last_commit(self) -> None:
        self._d_t, self._f_t, self._k_t = self._d_c, self._f_c, self._k_c

    def revert_to_start(self) -> None:
        self._d_c = self._d_t = 0.0
        self._f_c = self._f_t = 0.0
        self._e_c = 0.0
        self._k_c = self._k_t = self.initial_tangent

    @property
    def initial_tangent(self) -> float:
        return self._evaluate(0.0, 0.0, 0.0, 0.0)[1]

    @property
    def committed(self) -> tuple[float, float]:
        return self._d_c, self._f_c

    @property
    def committed_energy(self) -> float:
        """E of the last commit (the sixth feature of the next trial)."""
        return self._e_c

    def clone(self) -> AnnTwin:
        other = AnnTwin.__new__(AnnTwin)
        other.model, other._row = self.model, np.empty_like(self._row)
        other.set_params(self.theta)
        other._d_c, other._f_c, other._e_c, other._k_c = self._d_c, self._f_c, self._e_c, self._k_c
        other._d_t, other._f_t, other._k_t = self._d_t, self._f_t, self._k_t
        return other


def check_history(d: npt.ArrayLike, force: npt.ArrayLike, *, where: str,
                  min_len: int = 2) -> tuple[FloatArray, FloatArray]:
    """A (d, force) history as float arrays: 1-D, same length, finite, long enough."""
    disp = np.asarray(d, dtype=np.float64)
    f = np.asarray(force, dtype=np.float64)
    if disp.ndim != 1 or disp.shape != f.shape:
        raise UpdaterError(f"{where}: displacement and force must be 1-D of equal length, "
                           f"got shapes {disp.shape} and {f.shape}")
    if disp.size < min_len:
        raise UpdaterError(f"{where}: needs at least {min_len} samples, got {disp.size}")
    bad = np.flatnonzero(~(np.isfinite(disp) & np.isfinite(f)))
    if bad.size:
        raise UpdaterError(f"{where}: sample {int(bad[0])} is not finite "
                           f"(d={disp[bad[0]]!r}, F={f[bad[0]]!r})")
    return disp, f


def pretrain(
    d: npt.ArrayLike,
    force: npt.ArrayLike,
    *,
    layers: tuple[int, ...] = PAPER_LAYERS,
    options: LmOptions = PRETRAIN_LM,
    seed: int = 0,
    progress: Callable[[int, int], None] | None = None,
    source: str = "",
) -> AnnModel:
    """Train a network on an offline history (mm, kN) with LM from a Nguyen-Widrow start.

    The scaler comes from this history (the paper's Step 2(b)); every step is one sample.
    """
    disp, f = check_history(d, force, where="pretrain")
    x, y = feature_rows(disp, f)
    scaler = MinMaxScaler.fit(x, y)
    net = Mlp(layers)
    if net.layers[0] != x.shape[1]:
        raise UpdaterError(f"pretrain: the network needs {x.shape[1]} inputs, got {layers}")
    theta0 = net.init_params(np.random.default_rng(seed))
    result: LmResult = levenberg_marquardt(net, theta0, scaler.x(x), scaler.y(y),
                                           options=options, progress=progress)
    n = len(y)
    training = {
        "trainer": "numpy-lm", "seed": seed, "samples": n, "iterations": result.iterations,
        "stop": result.stop, "mse_normalised": result.cost / n,
        "initial_mse_normalised": result.initial_cost / n, "source": source,
    }
    return AnnModel(net, result.theta, scaler, disp.copy(), f.copy(), PAPER_FEATURES, training)


def recurrence_warning(free_run_maeth: float, measured_peak: float) -> str | None:
    """A warning when the network's own recurrence on its training data errs by more than the
    largest force measured: as a twin (``offline_ann``, and ``online_ann``'s start) it would
    feed back forces the element never had. A one-step fit can be excellent while this
    happens (a measured friction damper does it: ``BENCHMARKS.md``, "Online updating")."""
    if free_run_maeth <= measured_peak:
        return None
    return (f"warning: the network's own recurrence (the twin's mode) errs by up to "
            f"{free_run_maeth:.4g} kN on its training data, more than the largest measured "
            f"force ({measured_peak:.4g} kN): as a twin it is unstable on this element; "
            f"replay it before using it live (online_improved does not use this network)")
