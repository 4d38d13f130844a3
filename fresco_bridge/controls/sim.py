"""In-process simulated specimen, one model per actuator (OpenFresco: ``SimUniaxialMaterials``).

Material semantics, like OpenSees: every trial is evaluated from the last committed state and
only a commit (action 5) advances the history. With a ``bilinear`` model the bridge therefore
returns exactly what ``Steel01`` would inside OpenSees.
"""

from __future__ import annotations

from typing import Literal

import numpy as np
from pydantic import Field, model_validator

from sim_actuator.config import ModelKindName
from sim_actuator.effects import Sensor
from sim_actuator.models import MODEL_PARAMETERS, HysteresisModel, ModelParameterError, make_model

from .base import Daq, InlineController, diagonal
from .kind import ControllerConfigBase, ControllerKind


class SimControllerConfig(ControllerConfigBase):
    """In-process simulated specimen (one model per actuator)."""

    kind: Literal["sim"] = "sim"
    model: ModelKindName = "bilinear"
    params: dict[str, float] = Field(
        default_factory=lambda: {"k0": 8.0, "fy": 12.0, "alpha": 0.05}
    )
    reset_on_new_session: bool = True
    """A new integrator connection starts from a virgin specimen (a simulation, not a lab)."""
    load_cell_noise: float = Field(default=0.0, ge=0.0, allow_inf_nan=False)
    """Std of Gaussian noise on each force reading (kN), one draw per trial, as the study's
    ``MeasuredElement`` (``study paper --integrator opensees --noise``); 0: exact readings."""
    noise_seed: int = Field(default=0, ge=0)
    """Seed of the load cells' noise (actuator i: its own stream from ``[seed, i]``; one
    actuator: ``seed`` itself, the study's stream). The stream goes on across sessions."""

    @model_validator(mode="after")
    def _params_fit_model(self) -> SimControllerConfig:
        try:
            make_model(self.model, **self.params)
        except ModelParameterError as exc:
            allowed = ", ".join(MODEL_PARAMETERS.get(self.model, {}))
            raise ValueError(f"{exc} (parameters of {self.model}: {allowed})") from None
        return self


class SimController(InlineController):
    """A specimen model per actuator, answering at once (the site calls it synchronously)."""

    def __init__(self, models: list[HysteresisModel],
                 load_cells: list[Sensor] | None = None) -> None:
        if not models:
            raise ValueError("SimController needs at least one specimen model")
        if load_cells is not None and len(load_cells) != len(models):
            raise ValueError(f"SimController: {len(load_cells)} load cell(s) for "
                             f"{len(models)} model(s)")
        self.n_actuators = len(models)
        self._models = models
        self._cells = load_cells
        self._disp = tuple(0.0 for _ in models)
        self._force = tuple(m.committed[1] for m in models)
        self._tangent = tuple(m.initial_tangent for m in models)
        self._diag_of: tuple[float, ...] = ()
        self._diag: tuple[float, ...] = ()

    @classmethod
    def from_params(cls, n_actuators: int, kind: str, params: dict[str, float], *,
                    load_cell_noise: float = 0.0, noise_seed: int = 0) -> SimController:
        cells = None
        if load_cell_noise > 0.0:
            seeds = [noise_seed] if n_actuators == 1 else [[noise_seed, i]
                                                          for i in range(n_actuators)]
            cells = [Sensor(noise_std=load_cell_noise, rng=np.random.default_rng(seed))
                     for seed in seeds]
        return cls([make_model(kind, **params) for _ in range(n_actuators)], cells)

    def set_ctrl_now(self, disp: tuple[float, ...]) -> None:
        cells = self._cells
        if len(self._models) == 1:
            f, k = self._models[0].set_trial(disp[0])
            if cells is not None:
                f = cells[0].read(f)
            self._disp, self._force, self._tangent = disp, (f,), (k,)
            return
        results = [m.set_trial(d) for m, d in zip(self._models, disp, strict=True)]
        self._disp = disp
        self._force = tuple(r[0] for r in results) if cells is None else tuple(
            c.read(r[0]) for c, r in zip(cells, results, strict=True))
        self._tangent = tuple(r[1] for r in results)

    def get_daq_now(self) -> Daq:
        return Daq(self._disp, self._force)

    def commit_now(self) -> None:
        for m in self._models:
            m.commit()

    def tangent_stiffness_now(self) -> tuple[float, ...]:
        tangent = self._tangent
        if tangent != self._diag_of:  # the same matrix object while the tangent is unchanged
            self._diag_of, self._diag = tangent, diagonal(tangent)
        return self._diag

    def initial_stiffness_now(self) -> tuple[float, ...]:
        return diagonal(tuple(m.initial_tangent for m in self._models))

    def reset(self) -> None:
        """Back to the virgin specimen (a new integrator session starts from zero)."""
        for m in self._models:
            m.revert_to_start()
        self._disp = tuple(0.0 for _ in self._models)
        self._force = tuple(m.committed[1] for m in self._models)
        self._tangent = tuple(m.initial_tangent for m in self._models)


KIND = ControllerKind(
    name="sim",
    config=SimControllerConfig,
    factory=lambda config, n: SimController.from_params(
        n, config.model, dict(config.params), load_cell_noise=config.load_cell_noise,
        noise_seed=config.noise_seed),
    summary="in-process specimen model (`controller.model`) per actuator, material semantics = "
    "OpenSees",
    max_actuators=None,
)
