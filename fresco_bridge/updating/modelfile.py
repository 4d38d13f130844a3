"""Versioned ANN model files (``.pt``, torch's format), read back safely (``weights_only``).

A file holds one mapping::

    format        "fresco-bridge-ann"
    version       1 (a reader refuses a newer version)
    feature_spec  {name, version, inputs, output}: checked against the map this code computes
    layers        e.g. [6, 10, 10, 10, 1];  activation "tanh" (hidden), linear output
    state_dict    torch ``nn.Sequential(Linear, Tanh, …, Linear)`` names: "0.weight", "0.bias", …
    normalisation {x_min, x_max (tensors), y_min, y_max}: the offline data's min-max ranges
    offline       {disp, force}: the offline database (mm, kN) that online updating re-samples
    units         {disp: "mm", force: "kN"}
    training      how it was trained (trainer, iterations, costs, seed, source)

torch is imported only here and only when a file is read or written (it is an optional extra).
"""

from __future__ import annotations

import math
import os
import zipfile
from pathlib import Path
from typing import Any

import numpy as np

from .ann import AnnModel
from .base import UpdaterError
from .features import FeatureSpec, MinMaxScaler
from .mlp import Mlp

__all__ = ["FORMAT", "VERSION", "load_model", "save_model", "state_dict_names"]

FORMAT = "fresco-bridge-ann"
VERSION = 1


def import_torch(purpose: str) -> Any:
    """torch, or an UpdaterError saying how to install it."""
    try:
        import torch
    except ImportError as exc:
        raise UpdaterError(
            f"{purpose} needs torch, which is not installed: pip install 'fresco-bridge[torch]' "
            "(torch==2.13.0; `make test` installs it)"
        ) from exc
    return torch


def state_dict_names(layers: tuple[int, ...]) -> list[tuple[str, str]]:
    """(weight name, bias name) per Linear of ``nn.Sequential(Linear, Tanh, …, Linear)``."""
    return [(f"{2 * k}.weight", f"{2 * k}.bias") for k in range(len(layers) - 1)]


def _plain(value: Any) -> Any:
    """Training metadata reduced to what ``torch.load(weights_only=True)`` accepts."""
    if isinstance(value, dict):
        return {str(k): _plain(v) for k, v in value.items()}
    if isinstance(value, list | tuple):
        return [_plain(v) for v in value]
    if isinstance(value, np.generic):
        return value.item()
    if value is None or isinstance(value, str | int | float | bool):
        return value
    return str(value)


def save_model(model: AnnModel, path: Path) -> None:
    """Write ``model`` to ``path`` atomically (a temporary file renamed into place)."""
    torch = import_torch("writing a model file")
    state = {}
    for (w_name, b_name), (w, b) in zip(state_dict_names(model.net.layers),
                                        model.net.unpack(model.theta), strict=True):
        state[w_name] = torch.from_numpy(w.copy())
        state[b_name] = torch.from_numpy(b.copy())
    payload = {
        "format": FORMAT,
        "version": VERSION,
        "feature_spec": model.spec.as_dict(),
        "layers": list(model.net.layers),
        "activation": "tanh",
        "state_dict": state,
        "normalisation": {
            "x_min": torch.from_numpy(model.scaler.x_min.copy()),
            "x_max": torch.from_numpy(model.scaler.x_max.copy()),
            "y_min": model.scaler.y_min,
            "y_max": model.scaler.y_max,
        },
        "offline": {"disp": torch.from_numpy(model.offline_d.copy()),
                    "force": torch.from_numpy(model.offline_force.copy())},
        "units": {"disp": "mm", "force": "kN"},
        "training": _plain(model.training),
    }
    tmp = path.with_name(f".{path.name}.tmp")
    try:
        torch.save(payload, tmp)
        os.replace(tmp, path)
    finally:
        tmp.unlink(missing_ok=True)


def _field(data: dict[str, Any], key: str, kind: type | tuple[type, ...], where: str) -> Any:
    if key not in data:
        raise UpdaterError(f"{where}: the model file has no {key!r}")
    value = data[key]
    if not isinstance(value, kind):
        raise UpdaterError(f"{where}: {key!r} has the wrong type ({type(value).__name__})")
    return value


def _array(torch: Any, value: Any, where: str, what: str) -> np.ndarray:
    if not isinstance(value, torch.Tensor):
        raise UpdaterError(f"{where}: {what} must be a tensor, got {type(value).__name__}")
    arr: np.ndarray = value.detach().cpu().to(torch.float64).numpy().copy()
    if not np.all(np.isfinite(arr)):
        raise UpdaterError(f"{where}: {what} holds NaN or inf")
    return arr


def load_model(path: Path) -> AnnModel:
    """Read a model file; UpdaterError names the file and what is wrong with it."""
    where = str(path)
    if not path.is_file():
        raise UpdaterError(f"{where}: no such model file")
    torch = import_torch("reading a model file")
    try:
        data = torch.load(path, map_location="cpu", weights_only=True)
    except (zipfile.BadZipFile, EOFError, RuntimeError, OSError) as exc:
        raise UpdaterError(f"{where}: not a readable fresco-bridge model file ({exc})") from exc
    except Exception as exc:  # torch's unpickler refuses anything but plain data and tensors
        raise UpdaterError(f"{where}: not a fresco-bridge model file "
                           f"({type(exc).__name__}: {str(exc).splitlines()[0]})") from exc
    if not isinstance(data, dict) or data.get("format") != FORMAT:
        raise UpdaterError(f"{where}: not a fresco-bridge model file (format "
                           f"{data.get('format') if isinstance(data, dict) else None!r}, "
                           f"expected {FORMAT!r})")
    version = _field(data, "version", int, where)
    if version > VERSION:
        raise UpdaterError(f"{where}: model file version {version} is newer than this "
                           f"fresco-bridge reads (<= {VERSION}); upgrade fresco-bridge")
    spec = FeatureSpec.from_dict(data.get("feature_spec"), where=where)
    if data.get("activation") != "tanh":
        raise UpdaterError(f"{where}: activation {data.get('activation')!r} is not supported "
                           "(tanh hidden layers, linear output)")
    layers = tuple(int(n) for n in _field(data, "layers", list, where))
    try:
        net = Mlp(layers)
    except UpdaterError as exc:
        raise UpdaterError(f"{where}: {exc}") from exc
    state = _field(data, "state_dict", dict, where)
    theta = np.empty(net.n_params)
    for (w_name, b_name), (w, b) in zip(state_dict_names(layers), net.unpack(theta), strict=True):
        w_arr = _array(torch, state.get(w_name), where, f"state_dict[{w_name!r}]")
        b_arr = _array(torch, state.get(b_name), where, f"state_dict[{b_name!r}]")
        if w_arr.shape != w.shape or b_arr.shape != b.shape:
            raise UpdaterError(f"{where}: {w_name}/{b_name} have shapes {w_arr.shape}/"
                               f"{b_arr.shape}, layers {list(layers)} need {w.shape}/{b.shape}")
        w[...] = w_arr
        b[...] = b_arr
    norm = _field(data, "normalisation", dict, where)
    y_min, y_max = norm.get("y_min"), norm.get("y_max")
    if not all(isinstance(v, float | int) and math.isfinite(v) for v in (y_min, y_max)):
        raise UpdaterError(f"{where}: normalisation y_min/y_max must be finite numbers")
    scaler = MinMaxScaler.from_bounds(_array(torch, norm.get("x_min"), where, "x_min"),
                                      _array(torch, norm.get("x_max"), where, "x_max"),
                                      float(y_min), float(y_max), where=where)
    offline = _field(data, "offline", dict, where)
    disp = _array(torch, offline.get("disp"), where, "offline disp")
    force = _array(torch, offline.get("force"), where, "offline force")
    if disp.ndim != 1 or disp.shape != force.shape or disp.size < 2:
        raise UpdaterError(f"{where}: offline disp/force must be equal-length histories")
    training = data.get("training", {})
    return AnnModel(net, theta, scaler, disp, force, spec,
                    dict(training) if isinstance(training, dict) else {})
