"""Hysteresis models of specimens, pure and deterministic."""

from sim_actuator.models.base import (
    MODEL_DEFAULTS,
    MODEL_PARAMETERS,
    HysteresisModel,
    ModelInputError,
    ModelParameterError,
    make_model,
)
from sim_actuator.models.bilinear import Bilinear
from sim_actuator.models.bouc_wen import BoucWen
from sim_actuator.models.bwbn import BoucWenBaberNoori
from sim_actuator.models.elastic import Elastic

__all__ = [
    "MODEL_DEFAULTS",
    "MODEL_PARAMETERS",
    "Bilinear",
    "BoucWen",
    "BoucWenBaberNoori",
    "Elastic",
    "HysteresisModel",
    "ModelInputError",
    "ModelParameterError",
    "make_model",
]
