"""A physics expert for ``online_improved``: a Bouc-Wen law fitted to the offline data, plus a
reversal basis (``branch.BranchRls``) learning its residual online.

Why: a smooth state-variable law generalises from the tested element's history to the twin's
through its own state ``z`` (each element integrates its own), which a basis of branch
coordinates has to learn from data; the residual basis corrects what the law cannot express.
Why Bouc-Wen and why it is honest: the classic Bouc-Wen (``sim_actuator.models.bouc_wen``, six
parameters, n free) has no degradation and no pinching, so neither study specimen (the rig's
BWBN with energy-driven degradation and pinching, Menegotto-Pinto with isotropic hardening and
excursion-dependent curvature) lies in its family, nor in the family of law plus basis.

The fit: ``lawfit.fit_law`` of the Bouc-Wen force along the offline displacement history,
every second sample, from a start taken from the data (k_init of the first loading, the peak
force, n = 2, beta = gamma = 0.5). The law's parameters stay fixed online; only the residual
basis learns (the fit costs seconds, an online step does not), and its ridge pulls it towards
zero, so the expert falls back on the law where recent data do not support a residual. Fit and
online law run the JIT drive of ``sim_actuator.models.paths`` (``LAW_BOUC_WEN``, ``stepped``:
the object's algorithm, bit for bit, at a fraction of the cost of stepping the object;
BENCHMARKS.md, "Online updating").
"""

from __future__ import annotations

import time
from collections.abc import Mapping
from typing import Any

import numpy as np
import numpy.typing as npt

from fresco_bridge.lawfit import FitSpace, LawFamily, fit_law, law_forces
from fresco_bridge.updating.base import OwnsTwin, UpdaterError, check_measurement
from fresco_bridge.updating.branch import BasisTwin, BranchRls, initial_stiffness
from sim_actuator.models.base import HysteresisModel
from sim_actuator.models.bouc_wen import BoucWen
from sim_actuator.models.paths import LAW_BOUC_WEN, bouc_wen_vector, drive
from sim_actuator.models.stepped import SteppedBoucWen

__all__ = [
    "BOUC_WEN",
    "BOUC_WEN_DZ_MAX",
    "PhysicsResidual",
    "bouc_wen_forces",
    "data_scales",
    "fit_bouc_wen",
]

FloatArray = npt.NDArray[np.float64]

BOUC_WEN_DZ_MAX = 0.05
"""RK4 step of the law in z (fit and online alike): 5x the specimen default, a model not a
reference (the fit absorbs the integration error; keeps an online step cheap: BENCHMARKS.md,
"Online updating")."""

_FIT_STRIDE = 2
_FIT_EVALUATIONS = 60
_PARAMS = ("k0", "fy", "alpha", "n", "beta", "gamma")


def _jit_forces(params: Mapping[str, float], disp: FloatArray) -> FloatArray:
    """The law's force along ``disp`` by the JIT drive (NaN where the law refuses); the object
    is built first so that parameters it rejects raise as they did."""
    BoucWen(**params, dz_max=BOUC_WEN_DZ_MAX)
    return drive(LAW_BOUC_WEN, bouc_wen_vector(params), disp, 0.0, BOUC_WEN_DZ_MAX)


def bouc_wen_forces(params: dict[str, float], disp: FloatArray) -> FloatArray:
    """The law's force along a displacement history from the virgin state."""
    forces = _jit_forces(params, disp)
    if np.all(np.isfinite(forces)):
        return forces
    return law_forces(BoucWen(**params, dz_max=BOUC_WEN_DZ_MAX), disp)  # raises as the law does


def data_scales(disp: FloatArray, force: FloatArray, law: str) -> tuple[float, float]:
    """(first-loading stiffness, peak |force|) of a (d, F) history: where a law's fit starts;
    UpdaterError naming ``law`` when the data never load."""
    k_init = initial_stiffness(disp, force)
    f_peak = float(np.max(np.abs(force)))
    if not (k_init > 0.0 and f_peak > 0.0):
        raise UpdaterError(f"online_improved: cannot fit a {law} law to offline data with "
                           f"first-loading stiffness {k_init!r} and peak force {f_peak!r}")
    return k_init, f_peak


def _bouc_wen_space(disp: FloatArray, force: FloatArray) -> FitSpace:
    k_init, f_peak = data_scales(disp, force, "Bouc-Wen")
    return FitSpace(start=(k_init, f_peak, 0.05, 2.0, 0.5, 0.5),
                    lower=(0.1 * k_init, 0.05 * f_peak, 0.0, 1.0, 0.01, 0.0),
                    upper=(10.0 * k_init, 5.0 * f_peak, 0.5, 20.0, 5.0, 5.0),
                    scale=(k_init, f_peak, 0.01, 1.0, 0.1, 0.1))  # fmt: skip


BOUC_WEN = LawFamily("bouc-wen", _PARAMS,
                     lambda p: BoucWen(**p, dz_max=BOUC_WEN_DZ_MAX), _bouc_wen_space,
                     forces=_jit_forces)
"""The classic Bouc-Wen law, all six parameters free (``lawfit.LawFamily``)."""


def fit_bouc_wen(disp: FloatArray, force: FloatArray) -> dict[str, float]:
    """Bouc-Wen parameters fitted to a (d, F) history (see the module docstring)."""
    space = _bouc_wen_space(disp, force)
    d, f = disp[::_FIT_STRIDE], force[::_FIT_STRIDE]
    x = fit_law(BOUC_WEN, [(d, f, 1.0)], space, max_nfev=_FIT_EVALUATIONS,
                penalty=10.0 * float(np.max(np.abs(force))))  # fmt: skip
    return BOUC_WEN.params(x)


class _PhysicsTwin:
    """Law plus residual on the twin's own history (material semantics)."""

    name = "online_improved"

    def __init__(self, law: HysteresisModel, residual: HysteresisModel) -> None:
        self._law = law
        self._residual = residual

    def set_trial(self, d: float) -> tuple[float, float]:
        f_law, k_law = self._law.set_trial(d)
        f_res, k_res = self._residual.set_trial(d)
        return f_law + f_res, k_law + k_res

    def commit(self) -> None:
        self._law.commit()
        self._residual.commit()

    def advance(self, d: float) -> float:
        """``set_trial(d)`` and ``commit()`` in one, the force only (the free runs that score
        the experts)."""
        force = self._law.set_trial(d)[0]
        self._law.commit()
        residual = self._residual
        if isinstance(residual, BasisTwin):
            return force + residual.advance(d)
        force += residual.set_trial(d)[0]
        residual.commit()
        return force

    def revert_to_last_commit(self) -> None:
        self._law.revert_to_last_commit()
        self._residual.revert_to_last_commit()

    def revert_to_start(self) -> None:
        self._law.revert_to_start()
        self._residual.revert_to_start()

    @property
    def initial_tangent(self) -> float:
        return self._law.initial_tangent + self._residual.initial_tangent

    @property
    def committed(self) -> tuple[float, float]:
        d, f_law = self._law.committed
        return d, f_law + self._residual.committed[1]

    def clone(self) -> HysteresisModel:
        return _PhysicsTwin(self._law.clone(), self._residual.clone())


class PhysicsResidual(OwnsTwin):
    """Bouc-Wen law (fitted offline, fixed) + residual reversal basis (RLS online)."""

    name = "online_improved"

    def __init__(self, *, offline: tuple[npt.ArrayLike, npt.ArrayLike],
                 law: dict[str, float] | None = None, shrink: bool = True,
                 **rls: Any) -> None:
        """``law``: Bouc-Wen parameters (fitted to ``offline`` when None); ``shrink``: the
        residual's ridge pulls towards zero (the residual learned on the tested element otherwise
        transfers to the twin where the law alone was right: BENCHMARKS.md, "Online updating")."""
        disp = np.asarray(offline[0], dtype=np.float64)
        force = np.asarray(offline[1], dtype=np.float64)
        self.law = fit_bouc_wen(disp, force) if law is None else dict(law)
        residual = force - bouc_wen_forces(self.law, disp)
        # scales and k_init from the whole force (the residual may even be zero); the memory's
        # forces are the residual's, so its plastic-part term is close to the branch length
        self.residual = BranchRls(offline=(disp, residual), memory_terms=True,
                                  force_scale=float(np.max(np.abs(force))),
                                  stiffness=initial_stiffness(disp, force), shrink=shrink,
                                  **rls)  # fmt: skip
        self._source = SteppedBoucWen(**self.law, dz_max=BOUC_WEN_DZ_MAX)
        self._twin = _PhysicsTwin(SteppedBoucWen(**self.law, dz_max=BOUC_WEN_DZ_MAX),
                                  self.residual.twin)  # fmt: skip
        self._last_update = 0.0

    def predict(self, d: float) -> float:
        """One-step-ahead force of the tested element at ``d`` (nothing committed)."""
        f_law = self._source.set_trial(d)[0]
        self._source.revert_to_last_commit()
        return f_law + self.residual.predict(d)

    def observe(self, d: float, force: float) -> None:
        d, force = check_measurement(self.name, d, force)
        start = time.perf_counter()
        f_law = self._source.set_trial(d)[0]
        self._source.commit()
        self.residual.observe(d, force - f_law)
        self._last_update = time.perf_counter() - start
