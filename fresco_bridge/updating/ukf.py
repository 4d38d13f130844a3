"""``online_ukf``: an unscented Kalman filter on the Bilinear parameters (paper, Section 3.2.3).

State ``z = [k0, alpha, Fy]`` (kN/mm, -, kN), a random walk (``fx`` = identity, process noise Q).
Measurement: the tested element's force ``F_i``. The measurement function runs the Bilinear law
of ``sim_actuator.models`` (Steel01, never re-written here) for one step, from the tested
element's *measured* committed state ``(d_{i-1}, F_{i-1})`` to ``d_i``, with the sigma point's
parameters: for Steel01 the committed force is the whole hysteretic state, and it is measured.
Sigma points and means are projected onto the valid set (``k0, Fy > 0``, ``0 <= alpha < 1``)
before use (a constrained UKF by projection).

The twin is a Bilinear with its own committed state whose parameters are replaced by the
posterior mean after every update.

Start values (the paper's Table 1 and Eqs. 6-8, stated in N and mm) converted to kN and mm:
``k0 = 68000 N/mm = 68 kN/mm``, ``alpha = 0.008``, ``Fy = 35000 N = 35 kN``. Covariances scale
with the square of the unit factor (1 N = 1e-3 kN): ``P0 = diag(1e3 (N/mm)^2, 0.2, 1 N^2) =
diag(1e-3 (kN/mm)^2, 0.2, 1e-6 kN^2)``, ``Q0 = 1e-6 I -> diag(1e-12, 1e-6, 1e-12)``,
``R0 = 1e2 N^2 = 1e-4 kN^2``. Sigma points: Merwe scaled, ``alpha_ut = 1e-3, beta = 2, kappa = 0``
(filterpy's recommended defaults; the paper does not state them).
"""

from __future__ import annotations

import time
from collections.abc import Sequence

import numpy as np
import numpy.typing as npt

from sim_actuator.models import Bilinear, BilinearState

from .base import OwnsTwin, UpdaterError, check_measurement

FloatArray = npt.NDArray[np.float64]

__all__ = ["PAPER_UKF", "BilinearTwin", "OnlineUkfUpdater", "bilinear_step"]

PAPER_UKF: dict[str, float | tuple[float, float, float]] = {
    "k0": 68.0,
    "alpha": 0.008,
    "fy": 35.0,
    "p0": (1e3 * 1e-6, 0.2, 1.0 * 1e-6),
    "q": (1e-6 * 1e-6, 1e-6, 1e-6 * 1e-6),
    "r": 1e2 * 1e-6,
}
"""The paper's UKF start (Table 1, Eqs. 6-8) in kN and mm."""

_K_MIN = 1e-9
_FY_MIN = 1e-9
_ALPHA_MAX = 1.0 - 1e-9


def project(z: FloatArray) -> FloatArray:
    """[k0, alpha, Fy] clipped onto the valid Bilinear parameter set."""
    return np.array([max(z[0], _K_MIN), min(max(z[1], 0.0), _ALPHA_MAX), max(z[2], _FY_MIN)])


_TEMPLATE = Bilinear(k0=1.0, fy=1.0, alpha=0.0)


def _params(z: FloatArray) -> dict[str, float]:
    return {"k0": float(z[0]), "alpha": float(z[1]), "fy": float(z[2])}


def bilinear_step(z: FloatArray, d_c: float, f_c: float, d: float) -> float:
    """Force of the Bilinear law with parameters z stepping from the committed (d_c, f_c) to d."""
    p = project(z)
    law = _TEMPLATE.with_params(_params(p), BilinearState(d_c, f_c, float(p[0])))
    return law.set_trial(d)[0]


def _triple(name: str, value: float | Sequence[float]) -> FloatArray:
    arr = np.asarray(value, dtype=np.float64).reshape(-1)
    if arr.size == 1:
        arr = np.repeat(arr, 3)
    if arr.shape != (3,) or not np.all(np.isfinite(arr)) or np.any(arr <= 0.0):
        raise UpdaterError(f"online_ukf: {name} must be one or three positive finite numbers, "
                           f"got {value!r}")
    return arr


def _random_walk(z: FloatArray, dt: float) -> FloatArray:
    """The UKF's process model: the parameters stay (a module function, so the updater
    pickles: a served twin's learner snapshots it)."""
    return z


class BilinearTwin:
    """A Bilinear twin whose parameters can be replaced between steps, keeping its state.

    The object stays the same for the caller; the Steel01 inside is rebuilt with the new
    parameters from the committed (d, F).
    """

    __slots__ = ("law",)

    name = "bilinear"

    def __init__(self, law: Bilinear) -> None:
        self.law = law

    def __repr__(self) -> str:
        return f"BilinearTwin({self.law!r}, committed={self.law.committed!r})"

    def retarget(self, z: FloatArray) -> None:
        """New parameters [k0, alpha, Fy] from the next trial on."""
        self.law = self.law.with_params(_params(project(z)), self.law.state())

    def set_trial(self, d: float) -> tuple[float, float]:
        return self.law.set_trial(d)

    def commit(self) -> None:
        self.law.commit()

    def revert_to_last_commit(self) -> None:
        self.law.revert_to_last_commit()

    def revert_to_start(self) -> None:
        self.law.revert_to_start()

    @property
    def initial_tangent(self) -> float:
        return self.law.initial_tangent

    @property
    def committed(self) -> tuple[float, float]:
        return self.law.committed

    def clone(self) -> BilinearTwin:
        return BilinearTwin(self.law.clone())


class OnlineUkfUpdater(OwnsTwin):
    """UKF on [k0, alpha, Fy] of a Bilinear twin (filterpy 2.0.0 ``UnscentedKalmanFilter``)."""

    _twin: BilinearTwin

    name = "online_ukf"

    def __init__(
        self,
        *,
        k0: float = 68.0,
        alpha: float = 0.008,
        fy: float = 35.0,
        p0: float | Sequence[float] = PAPER_UKF["p0"],
        q: float | Sequence[float] = PAPER_UKF["q"],
        r: float = 1e-4,
        sigma_alpha: float = 1.0,
        sigma_beta: float = 2.0,
        sigma_kappa: float = 0.0,
    ) -> None:
        from filterpy.kalman import (  # type: ignore[import-untyped]
            MerweScaledSigmaPoints,
            UnscentedKalmanFilter,
        )

        start = np.array([k0, alpha, fy], dtype=np.float64)
        if not np.all(np.isfinite(start)) or not np.array_equal(project(start), start):
            raise UpdaterError(f"online_ukf: start must have k0 > 0, 0 <= alpha < 1, fy > 0, "
                               f"got k0={k0!r}, alpha={alpha!r}, fy={fy!r}")
        if not (np.isfinite(r) and r > 0.0):
            raise UpdaterError(f"online_ukf: r must be a positive finite number, got {r!r}")
        points = MerweScaledSigmaPoints(3, alpha=sigma_alpha, beta=sigma_beta, kappa=sigma_kappa)
        self._d_c = 0.0
        self._f_c = 0.0
        self._d_i = 0.0
        self._ukf = UnscentedKalmanFilter(
            dim_x=3, dim_z=1, dt=1.0, hx=self._hx, fx=_random_walk, points=points
        )
        self._ukf.x = start.copy()
        self._ukf.P = np.diag(_triple("p0", p0))
        self._ukf.Q = np.diag(_triple("q", q))
        self._ukf.R = np.array([[float(r)]])
        self._twin = BilinearTwin(Bilinear(k0=k0, fy=fy, alpha=alpha))
        self._last_update = 0.0
        self.skipped_updates = 0
        self.steps = 0

    def __repr__(self) -> str:
        k0, alpha, fy = self.parameters
        return f"OnlineUkfUpdater(k0={k0:.6g}, alpha={alpha:.6g}, fy={fy:.6g})"

    def _hx(self, z: FloatArray) -> FloatArray:
        return np.array([bilinear_step(z, self._d_c, self._f_c, self._d_i)])

    @property
    def parameters(self) -> tuple[float, float, float]:
        """Posterior mean (k0 kN/mm, alpha, Fy kN)."""
        z = self._ukf.x
        return float(z[0]), float(z[1]), float(z[2])

    @property
    def covariance(self) -> FloatArray:
        return np.array(self._ukf.P, copy=True)

    def observe(self, d: float, force: float) -> None:
        d, force = check_measurement(self.name, d, force)
        start = time.perf_counter()
        ukf = self._ukf
        saved = (ukf.x.copy(), ukf.P.copy())
        self._d_i = d
        try:
            ukf.predict()
            ukf.update(np.array([force]))
            ukf.x = project(ukf.x)
            if not (np.all(np.isfinite(ukf.x)) and np.all(np.isfinite(ukf.P))):
                raise np.linalg.LinAlgError("non-finite posterior")
        except np.linalg.LinAlgError:
            ukf.x, ukf.P = saved  # a lost covariance: keep the last good estimate
            self.skipped_updates += 1
        self._d_c, self._f_c = d, force
        self._twin.retarget(ukf.x)
        self.steps += 1
        self._last_update = time.perf_counter() - start
