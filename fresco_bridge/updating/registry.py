"""One registry of updaters: ``make_updater(name, **options)``.

A new updater is one line in :data:`UPDATERS`: its name, the module and factory (a function or
the class) that build it (imported only when used, so the CLI starts fast), one sentence for
``--help`` and the options of which it needs one (its data: a network or an offline history).
``make_updater`` passes options by keyword and rejects unknown option names with the list of
the allowed ones, and a missing needed one by name, before anything is built.
"""

from __future__ import annotations

import importlib
import inspect
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Final

import numpy.typing as npt

from fresco_bridge.lawfit import calibrate_bilinear
from sim_actuator.models import HysteresisModel, ModelParameterError, make_model

from .base import Updater, UpdaterError

__all__ = [
    "PAPER_BILINEAR",
    "UPDATERS",
    "UpdaterEntry",
    "calibrated_bilinear",
    "make_none",
    "make_offline_ann",
    "make_online_ann",
    "make_online_ukf",
    "make_updater",
    "updater_options",
]

PAPER_BILINEAR: Final[dict[str, float]] = {"k0": 68.0, "fy": 35.0, "alpha": 0.008}
"""The source paper's assumed Bilinear (Table 1: k0 68000 N/mm, Fy 35000 N, alpha 0.008) in kN
and mm: the law of ``none`` and the start of ``online_ukf`` when no offline data are given."""


@dataclass(frozen=True, slots=True)
class UpdaterEntry:
    module: str
    factory: str
    description: str
    needs: tuple[str, ...] = ()
    """Options of which one must be given (none: the updater has a default for everything)."""

    def load(self) -> Callable[..., Updater]:
        fn: Callable[..., Updater] = getattr(importlib.import_module(self.module), self.factory)
        return fn


UPDATERS: dict[str, UpdaterEntry] = {
    "none": UpdaterEntry(__name__, "make_none", "a fixed hysteresis law, no updating (default: "
                         "the paper's Bilinear k0 68 kN/mm, Fy 35 kN, alpha 0.008; with "
                         "offline: the Bilinear calibrated to it)"),
    "offline_ann": UpdaterEntry(__name__, "make_offline_ann", "the pre-trained ANN, no updating "
                                "(the paper's offline calibration)",
                                needs=("model", "model_file", "offline")),
    "online_ann": UpdaterEntry(__name__, "make_online_ann", "the paper's online ANN: 500 random "
                               "offline + 200 forgetting-window samples, LM every step (8 "
                               "iterations, float32 J^T W J: equal in accuracy to the "
                               "paper's 50)", needs=("model", "model_file", "offline")),
    "online_ukf": UpdaterEntry(__name__, "make_online_ukf", "the paper's UKF on the Bilinear "
                               "parameters [k0, alpha, Fy] (start: the paper's values; "
                               "with offline: the calibrated Bilinear)"),
    "online_improved": UpdaterEntry("fresco_bridge.updating.improved", "OnlineImproved",
                                    "ours: reversal-basis, stop-operator and Bouc-Wen-plus-"
                                    "residual experts (RLS with forgetting, ridge, gating) "
                                    "weighted by their free-run and one-step errors on the "
                                    "tested element (needs offline; shadow=true also scores "
                                    "them on a stretch matched to the twin's state)",
                                    needs=("offline",)),
}
"""Name -> where its factory lives and what it is."""


def updater_options(name: str) -> list[str]:
    """The option names the updater ``name`` accepts."""
    factory = _entry(name).load()
    kinds = (inspect.Parameter.KEYWORD_ONLY, inspect.Parameter.POSITIONAL_OR_KEYWORD)
    return [p.name for p in inspect.signature(factory).parameters.values() if p.kind in kinds]


def _entry(name: str) -> UpdaterEntry:
    try:
        return UPDATERS[name]
    except KeyError:
        raise UpdaterError(f"unknown updater {name!r}; known: {', '.join(UPDATERS)}") from None


def make_updater(name: str, **options: Any) -> Updater:
    """Build the updater ``name`` with keyword ``options`` (UpdaterError on a bad name/option)."""
    entry = _entry(name)
    factory = entry.load()
    allowed = updater_options(name)
    unknown = sorted(set(options) - set(allowed))
    if unknown:
        raise UpdaterError(f"updater {name!r}: unknown option(s) {', '.join(unknown)}; "
                           f"allowed: {', '.join(allowed) or '(none)'}")
    if entry.needs and all(options.get(k) is None for k in entry.needs):
        raise UpdaterError(f"updater {name!r} needs the option {' or '.join(entry.needs)}")
    return factory(**options)


# -- the paper's updaters -------------------------------------------------------------------


def make_none(*, model: str | HysteresisModel = "bilinear",
              params: dict[str, float] | None = None,
              offline: tuple[npt.ArrayLike, npt.ArrayLike] | None = None) -> Updater:
    """A fixed law: a model kind of ``sim_actuator.models`` with ``params``, or a model object.

    ``model="bilinear"`` without params is the paper's assumed Bilinear; with ``offline`` (an
    offline (d, F) history) it is the Bilinear calibrated to that history, the study's
    ``conventional_calibrated``: the baseline a lab compares an updater with. A model object
    (e.g. the specimen's true law for the reference case) is cloned, state included.
    """
    from .updaters import FixedModelUpdater

    if not isinstance(model, str):
        if params is not None or offline is not None:
            raise UpdaterError("updater 'none': give params or offline only with a model kind "
                               "name")
        return FixedModelUpdater("none", model.clone())
    if offline is not None:
        if model != "bilinear" or params is not None:
            raise UpdaterError(f"updater 'none': offline calibrates the Bilinear; give it "
                               f"without params and with model bilinear (got model {model!r}"
                               f"{', params' if params is not None else ''})")
        params = calibrated_bilinear("none", offline)
    if params is None:
        if model != "bilinear":
            raise UpdaterError(f"updater 'none': model {model!r} needs params")
        params = dict(PAPER_BILINEAR)
    try:
        law = make_model(model, **params)
    except ModelParameterError as exc:
        raise UpdaterError(f"updater 'none': {exc}") from exc
    return FixedModelUpdater("none", law)


def calibrated_bilinear(name: str, offline: tuple[npt.ArrayLike, npt.ArrayLike]
                        ) -> dict[str, float]:
    """The Bilinear (k0, fy, alpha) fitted to an offline (d, F) history
    (``lawfit.calibrate_bilinear``), its errors as UpdaterError naming updater ``name``."""
    try:
        return calibrate_bilinear(offline[0], offline[1])
    except ValueError as exc:
        raise UpdaterError(f"updater {name!r}: offline: {exc}") from exc


_PRETRAINED: dict[tuple[str, int, int], Any] = {}
"""In-process memo of ``offline=`` pre-training (digest of the data, seed, iterations)."""


def _pretrained(offline: tuple[npt.ArrayLike, npt.ArrayLike], seed: int, iterations: int) -> Any:
    """``pretrain`` on an offline history, once per process for the same data and settings."""
    import hashlib
    from dataclasses import replace

    import numpy as np

    from .ann import PRETRAIN_LM, pretrain

    d = np.ascontiguousarray(offline[0], dtype=np.float64)
    f = np.ascontiguousarray(offline[1], dtype=np.float64)
    key = (hashlib.sha1(d.tobytes() + b"|" + f.tobytes()).hexdigest(), seed, iterations)
    if key not in _PRETRAINED:
        if len(_PRETRAINED) >= 4:
            _PRETRAINED.pop(next(iter(_PRETRAINED)))
        _PRETRAINED[key] = pretrain(d, f, seed=seed,
                                    options=replace(PRETRAIN_LM, max_iterations=iterations),
                                    source="offline history given in-process")
    return _PRETRAINED[key]


def _ann_model(name: str, model: Any, model_file: str | Path | None,
               offline: tuple[npt.ArrayLike, npt.ArrayLike] | None, seed: int,
               pretrain_iterations: int) -> Any:
    """The AnnModel from exactly one of: an object, a model file, an offline (d, F) history."""
    from .ann import AnnModel

    given = [k for k, v in (("model", model), ("model_file", model_file), ("offline", offline))
             if v is not None]
    if len(given) != 1:
        raise UpdaterError(f"updater {name!r}: give exactly one of model, model_file, offline "
                           f"(got {', '.join(given) or 'none'})")
    if model is not None:
        if not isinstance(model, AnnModel):
            raise UpdaterError(f"updater {name!r}: model must be an AnnModel, "
                               f"got {type(model).__name__}")
        return model
    if model_file is not None:
        from .modelfile import load_model

        return load_model(Path(model_file))
    assert offline is not None
    if pretrain_iterations < 1:
        raise UpdaterError(f"updater {name!r}: pretrain_iterations must be >= 1, "
                           f"got {pretrain_iterations}")
    return _pretrained(offline, seed, pretrain_iterations)


def make_offline_ann(*, model: Any = None, model_file: str | Path | None = None,
                     offline: tuple[npt.ArrayLike, npt.ArrayLike] | None = None,
                     seed: int = 0, pretrain_iterations: int = 1000) -> Updater:
    """The pre-trained network as a fixed twin (from a model object, file or offline history).

    With ``offline`` the network is pre-trained here (LM, ``pretrain_iterations``, ``seed``).
    """
    from .ann import AnnTwin
    from .updaters import FixedModelUpdater

    return FixedModelUpdater("offline_ann",
                             AnnTwin(_ann_model("offline_ann", model, model_file, offline, seed,
                                                pretrain_iterations)))


def make_online_ann(*, model: Any = None, model_file: str | Path | None = None,
                    offline: tuple[npt.ArrayLike, npt.ArrayLike] | None = None,
                    offline_samples: int = 500, window: int = 200, forgetting: float = 0.1,
                    window_share: float | None = None, max_iterations: int | None = None,
                    rtol: float | None = None, single_precision_hessian: bool | None = None,
                    seed: int = 0, pretrain_iterations: int = 1000) -> Updater:
    """The paper's online ANN: LM every step, by default 8 iterations with a float32 J^T W J
    (``ONLINE_ANN_LM``: equal in accuracy to the paper's 50 in float64, BENCHMARKS.md, "Online
    updating"); ``max_iterations=50, single_precision_hessian=False`` is the paper's exact fit.

    ``rtol`` adds a relative-decrease stop. ``seed`` drives both the pre-training start (with
    ``offline``) and the random choice of offline samples.
    """
    from .updaters import ONLINE_ANN_LM, OnlineAnnUpdater, online_lm_options

    ann = _ann_model("online_ann", model, model_file, offline, seed, pretrain_iterations)
    return OnlineAnnUpdater(ann, offline_samples=offline_samples, window=window,
                            forgetting=forgetting, window_share=window_share,
                            lm=online_lm_options(max_iterations, rtol, ONLINE_ANN_LM,
                                                 single_precision_hessian),
                            seed=seed)


def make_online_ukf(*, k0: float | None = None, alpha: float | None = None,
                    fy: float | None = None, p0: Any = None, q: Any = None,
                    r: float | None = None, sigma_alpha: float = 1.0,
                    offline: tuple[npt.ArrayLike, npt.ArrayLike] | None = None) -> Updater:
    """The paper's UKF; start values and covariances in kN and mm (defaults: the paper's).

    With ``offline`` the start values are the Bilinear calibrated to that history (the paper's
    start suits only its own damper); ``k0``/``alpha``/``fy`` given as well override it.
    """
    from .ukf import PAPER_UKF, OnlineUkfUpdater

    start = dict(PAPER_BILINEAR) if offline is None else calibrated_bilinear("online_ukf",
                                                                               offline)
    return OnlineUkfUpdater(
        k0=start["k0"] if k0 is None else k0,
        alpha=start["alpha"] if alpha is None else alpha,
        fy=start["fy"] if fy is None else fy,
        p0=PAPER_UKF["p0"] if p0 is None else p0,
        q=PAPER_UKF["q"] if q is None else q,
        r=float(PAPER_UKF["r"]) if r is None else r,  # type: ignore[arg-type]
        sigma_alpha=sigma_alpha,
    )
