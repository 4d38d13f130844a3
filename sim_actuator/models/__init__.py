"""Hysteresis models of specimens, pure and deterministic."""

from sim_actuator.models.base import (
    HysteresisBase,
    HysteresisModel,
    ModelInputError,
    ModelKind,
    ModelParameterError,
    ModelState,
    Param,
    ParametricModel,
)
from sim_actuator.models.bilinear import Bilinear, BilinearState
from sim_actuator.models.bouc_wen import BoucWen, BoucWenState
from sim_actuator.models.bwbn import BoucWenBaberNoori, BwbnState
from sim_actuator.models.elastic import Elastic, ElasticState
from sim_actuator.models.isotropic_bilinear import IsotropicBilinear, IsotropicBilinearState
from sim_actuator.models.menegotto_pinto import MenegottoPinto, MenegottoPintoState
from sim_actuator.models.registry import (
    MODEL_DEFAULTS,
    MODEL_KINDS,
    MODEL_PARAMETERS,
    make_model,
    model_kind,
    model_kinds_markdown,
)

__all__ = [
    "MODEL_DEFAULTS",
    "MODEL_KINDS",
    "MODEL_PARAMETERS",
    "Bilinear",
    "BilinearState",
    "BoucWen",
    "BoucWenBaberNoori",
    "BoucWenState",
    "BwbnState",
    "Elastic",
    "ElasticState",
    "HysteresisBase",
    "HysteresisModel",
    "IsotropicBilinear",
    "IsotropicBilinearState",
    "MenegottoPinto",
    "MenegottoPintoState",
    "ModelInputError",
    "ModelKind",
    "ModelParameterError",
    "ModelState",
    "Param",
    "ParametricModel",
    "make_model",
    "model_kind",
    "model_kinds_markdown",
]
