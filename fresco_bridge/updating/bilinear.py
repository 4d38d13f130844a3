"""The Bilinear law identified online: the offline start's own family, refitted on the tested
element's recent history (``refit.RefitUpdater``), the twin running it on its own history.

Why: ``online_improved`` must be able to represent the law a lab calibrates offline. Where the
specimen is a Bilinear, every other expert only approximates it (the Baber-Wen law's finite
sharpness, the bases' saturating branches) and transfers that approximation to a twin in
another state; this law can be exactly right, and ``law_trust`` then gives it all the weight
(its misfit is the smallest). The fit starts from the calibrated Bilinear
(``lawfit.calibrate_bilinear``, the offline start) within bounds from the data's scales.

The law is ``sim_actuator.models.Bilinear`` (a closed-form return mapping, so the compressed
history gives exactly the state of the whole one); the fit drives it through the JIT kernel of
``sim_actuator.models.paths`` (the same algorithm).
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

import numpy as np
import numpy.typing as npt

from fresco_bridge.lawfit import FitSpace, LawFamily, calibrate_bilinear
from fresco_bridge.updating.base import UpdaterError
from fresco_bridge.updating.degrading import REFIT_SCHEDULE
from fresco_bridge.updating.physics import data_scales
from fresco_bridge.updating.refit import RefitUpdater
from sim_actuator.models import Bilinear
from sim_actuator.models.base import HysteresisModel, ModelState
from sim_actuator.models.paths import LAW_BILINEAR, STATE_SIZE, drive, drive_from

__all__ = ["BILINEAR", "bilinear_refit"]

FloatArray = npt.NDArray[np.float64]


def _build(params: Mapping[str, float]) -> HysteresisModel:
    return Bilinear(**params)


def _forces(params: Mapping[str, float], disp: FloatArray) -> FloatArray:
    return drive(LAW_BILINEAR, np.array([params["k0"], params["fy"], params["alpha"]]), disp)


def _forces_from(params: Mapping[str, float], disp: FloatArray, state: ModelState
                 ) -> FloatArray:
    """``_forces`` from a committed ``BilinearState`` (d, f, k) instead of the virgin one."""
    start = np.zeros(STATE_SIZE)
    start[:2] = state[:2]  # BilinearState (d, f, k): the kernel's [d, f]
    return drive_from(LAW_BILINEAR, np.array([params["k0"], params["fy"], params["alpha"]]),
                      disp, start)


def _space(disp: FloatArray, force: FloatArray) -> FitSpace:
    """Bounds from the data's scales (first-loading stiffness, peak force), as every online law's;
    the start is the calibrated Bilinear, clipped into them by the fit (a calibration that
    degenerates on poorly excited data, k0 -> 0, cannot trap the refits)."""
    k_init, f_peak = data_scales(disp, force, "Bilinear")
    try:
        start = calibrate_bilinear(disp, force)
    except ValueError as exc:
        raise UpdaterError(f"online_improved: offline: {exc}") from exc
    return FitSpace(start=(start["k0"], start["fy"], start["alpha"]),
                    lower=(0.1 * k_init, 0.05 * f_peak, 0.0),
                    upper=(10.0 * k_init, 5.0 * f_peak, 0.5),
                    scale=(k_init, f_peak, 0.01))  # fmt: skip


BILINEAR = LawFamily("bilinear", ("k0", "fy", "alpha"), _build, _space, forces=_forces)
"""The Bilinear (k0, fy, alpha): the offline calibration's family."""


def bilinear_refit(offline: tuple[npt.ArrayLike, npt.ArrayLike], *,
                   name: str = "online_improved", **schedule: Any) -> RefitUpdater:
    """The Bilinear refitted online (the Baber-Wen law's ``REFIT_SCHEDULE`` unless
    overridden)."""
    return RefitUpdater(BILINEAR, offline=offline, name=name, forces_from=_forces_from,
                        **{**REFIT_SCHEDULE, **schedule})
