"""The Bilinear law identified online: the offline start's own family, refitted on the tested
element's recent history (``refit.RefitUpdater``), the twin running it on its own history.

Why: ``online_improved`` must be able to represent the law a lab calibrates offline. Where the
specimen is a Bilinear, every other expert only approximates it (the Baber-Wen law's finite
sharpness, the bases' saturating branches) and transfers that approximation to a twin in
another state; this law can be exactly right, and ``law_trust`` then gives it all the weight
(its misfit is the smallest). The fit starts from the calibrated Bilinear
(``lawfit.calibrate_bilinear``, the offline start), bounds a decade either side.

The law is ``sim_actuator.models.Bilinear`` (a closed-form return mapping, so the compressed
history gives exactly the state of the whole one).
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

import numpy as np
import numpy.typing as npt

from fresco_bridge.lawfit import FitSpace, LawFamily, calibrate_bilinear
from fresco_bridge.updating.base import UpdaterError
from fresco_bridge.updating.degrading import REFIT_SCHEDULE
from fresco_bridge.updating.refit import RefitUpdater
from sim_actuator.models import Bilinear
from sim_actuator.models.base import HysteresisModel

__all__ = ["BILINEAR", "bilinear_refit"]

FloatArray = npt.NDArray[np.float64]


def _build(params: Mapping[str, float]) -> HysteresisModel:
    return Bilinear(**params)


def _space(disp: FloatArray, force: FloatArray) -> FitSpace:
    try:
        start = calibrate_bilinear(disp, force)
    except ValueError as exc:
        raise UpdaterError(f"online_improved: offline: {exc}") from exc
    k0, fy, alpha = start["k0"], start["fy"], start["alpha"]
    return FitSpace(start=(k0, fy, alpha), lower=(0.1 * k0, 0.1 * fy, 0.0),
                    upper=(10.0 * k0, 10.0 * fy, 0.5),
                    scale=(k0, fy, max(alpha, 0.01)))  # fmt: skip


BILINEAR = LawFamily("bilinear", ("k0", "fy", "alpha"), _build, _space)
"""The Bilinear (k0, fy, alpha): the offline calibration's family."""


def bilinear_refit(offline: tuple[npt.ArrayLike, npt.ArrayLike], *,
                   name: str = "online_improved", **schedule: Any) -> RefitUpdater:
    """The Bilinear refitted online (the Baber-Wen law's ``REFIT_SCHEDULE`` unless
    overridden)."""
    return RefitUpdater(BILINEAR, offline=offline, name=name, **{**REFIT_SCHEDULE, **schedule})
