"""A degrading law identified online: Bouc-Wen with energy-driven strength and stiffness
degradation and *no pinching* (Baber & Wen 1981), refitted on the tested element's whole history
(``refit.RefitUpdater``), the twin running it on its own history.

Why: the rig's damper (``bwbn``) loses strength and stiffness with the hysteretic energy it has
dissipated. That is a state of the element, which the weights of a reversal basis fitted to the
tested element's *recent* past cannot carry over to a twin in another state; a law with the
energy as a state variable can: the parameters are shared, the energy is each element's own.
What it achieves against the other experts: ``BENCHMARKS.md``, "Online updating".

The law: ``sim_actuator.models.bwbn`` with the pinching off (``zeta_s = 0``: h = 1, its
equations are then exactly Baber-Wen's), ``A0 = 1``, ``delta_a = 0`` and ``gamma = 1 - beta``
fixed (``_FIXED``: one of the scale parameters is redundant); free: k0, fy, alpha, n, beta,
delta_nu, delta_eta. Why this is honest (no family may contain either study specimen's own
law): the family has no pinching term at all, and the specimen pinches (``zeta_s = 0.3``), so
the specimen is not in it; it contains no Menegotto-Pinto law either (a smooth Bouc-Wen
transition, no Steel02 curvature memory, no isotropic hardening). The code is ``bwbn``'s (never
written twice), the family is not.

Fit: through the JIT drive of ``sim_actuator.models.paths`` (the same algorithm as the object,
much faster; a Baber-Wen evaluation costs RK4 substeps in proportion to the travel in yield
displacements, not to the number of samples, so compressing the history saves less than for a
closed-form law). Fit and twin use the same ``BABER_WEN_DZ_MAX``, and the law objects step
through the same kernel (``stepped``: the same bits).
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

import numpy as np
import numpy.typing as npt

from fresco_bridge.lawfit import FitSpace, LawFamily
from fresco_bridge.updating.physics import data_scales
from fresco_bridge.updating.refit import RefitUpdater
from sim_actuator.models.base import HysteresisModel, ModelState
from sim_actuator.models.paths import LAW_BWBN, STATE_SIZE, bwbn_vector, drive, drive_from
from sim_actuator.models.stepped import SteppedBaberNoori

__all__ = ["BABER_WEN", "BABER_WEN_DZ_MAX", "N_MAX", "REFIT_SCHEDULE", "baber_wen_refit"]

FloatArray = npt.NDArray[np.float64]

BABER_WEN_DZ_MAX = 0.1
"""RK4 step of the law in z, fit and twin alike: a model, not a reference (halving it does not
change the updater's scores; most steps need one substep either way)."""

N_MAX = 3.0
"""Upper bound of the sharpness n. Why: RK4 substeps grow with n (|dz/du| up to ~n near z_u), and
a fit to a sharply yielding element (Menegotto-Pinto) drives n up until each refit costs seconds,
while a degrading damper fits n near 1. With gamma = 1 - beta >= 0 (beta <= 1) the substep bound
stays <= 1 + N_MAX."""

_FREE = ("k0", "fy", "alpha", "n", "beta", "delta_nu", "delta_eta")
_FIXED = {"A0": 1.0, "delta_a": 0.0, "zeta_s": 0.0, "p": 0.0, "q": 0.0, "psi0": 1.0,
          "delta_psi": 0.0, "lam": 1.0}  # fmt: skip
"""No pinching (zeta_s = 0 makes p, q, psi0, delta_psi, lam inert), no decay of A; and
gamma = 1 - beta (``_law``): with A0 fixed, the scaling z -> s*z, fy -> fy/s, (beta, gamma) ->
(beta, gamma)/s**n, deltas -> deltas/s**2 leaves every force unchanged, so one of them is
redundant (a free gamma made the fit wander along that valley)."""

REFIT_SCHEDULE: dict[str, Any] = {"every": 300, "stride": 5, "max_nfev": 5, "offline_nfev": 200,
                                  "warmup": 50}  # fmt: skip
"""Refit schedule (chosen on the design records, ``BENCHMARKS.md``, "Online updating"): every 300
steps 5 evaluations (each 8 law runs with the finite-difference Jacobian) on every 5th sample
plus the reversals of the history so far and of the offline database; the offline database
stays in every refit (without it the first refits, on 50-250 noisy steps, diverged)."""


def _law(params: Mapping[str, float]) -> dict[str, float]:
    """Every parameter of the ``bwbn`` law from the free ones."""
    return {**params, "gamma": 1.0 - params["beta"], **_FIXED}


def _build(params: Mapping[str, float]) -> HysteresisModel:
    return SteppedBaberNoori(**_law(params), dz_max=BABER_WEN_DZ_MAX)


def _forces(params: Mapping[str, float], disp: FloatArray) -> FloatArray:
    return drive(LAW_BWBN, bwbn_vector(_law(params)), disp, 0.0, BABER_WEN_DZ_MAX)


def _forces_from(params: Mapping[str, float], disp: FloatArray, state: ModelState
                 ) -> FloatArray:
    """``_forces`` from a committed ``BwbnState`` (d, f, k, z, e) instead of the virgin one."""
    start = np.zeros(STATE_SIZE)
    d, f, _k, z, e = state  # BwbnState
    start[:4] = (d, f, z, e)  # the kernel's [d, f, z, e]
    return drive_from(LAW_BWBN, bwbn_vector(_law(params)), disp, start, BABER_WEN_DZ_MAX)


def _space(disp: FloatArray, force: FloatArray) -> FitSpace:
    k_init, f_peak = data_scales(disp, force, "Baber-Wen")
    return FitSpace(start=(k_init, f_peak, 0.05, 2.0, 0.5, 1e-3, 1e-3),
                    lower=(0.1 * k_init, 0.05 * f_peak, 0.0, 1.0, 0.01, 0.0, 0.0),
                    upper=(10.0 * k_init, 5.0 * f_peak, 0.5, N_MAX, 1.0, 0.2, 0.2),
                    scale=(k_init, f_peak, 0.01, 1.0, 0.1, 1e-3, 1e-3))  # fmt: skip


BABER_WEN = LawFamily("baber-wen", _FREE, _build, _space, forces=_forces)
"""Bouc-Wen with energy-driven strength and stiffness degradation, no pinching."""


def baber_wen_refit(offline: tuple[npt.ArrayLike, npt.ArrayLike], *,
                    name: str = "online_improved", **schedule: Any) -> RefitUpdater:
    """The Baber-Wen law refitted online (``REFIT_SCHEDULE`` unless overridden)."""
    return RefitUpdater(BABER_WEN, offline=offline, name=name, forces_from=_forces_from,
                        **{**REFIT_SCHEDULE, **schedule})
