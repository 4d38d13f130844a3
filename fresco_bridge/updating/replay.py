"""Replay an updater on recorded histories: the tested element's (d, F), the twin's d.

Pure: arrays in, arrays out (the CSV side is :mod:`.cli`). ``lag`` is the causality's
(``fresco_bridge.causality.lags``: ``previous-step`` lags, ``same-step`` does not). Step ``i``:

* ``lag=False`` (the paper's order): ``observe(source_d[i], source_f[i])``, then the twin is
  set to ``twin_d[i]`` and committed, so its step ``i`` uses what was learned through step ``i``;
* ``lag=True``: the twin's step ``i`` is predicted and committed first, then step ``i`` of the
  source is observed: the twin only knows the source through step ``i - 1`` (what a twin that
  must answer before the tested element is measured would know).
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np
import numpy.typing as npt

from .base import Updater, UpdaterError

FloatArray = npt.NDArray[np.float64]

__all__ = ["ReplayResult", "replay"]


@dataclass(frozen=True, slots=True)
class ReplayResult:
    """The twin's predicted force per step and the updater's time per step."""

    twin_disp: FloatArray
    force_pred: FloatArray
    update_seconds: FloatArray
    lag: bool


def replay(
    updater: Updater,
    source_d: npt.ArrayLike,
    source_f: npt.ArrayLike,
    twin_d: npt.ArrayLike,
    *,
    lag: bool = False,
    progress: Callable[[int, int], None] | None = None,
) -> ReplayResult:
    """Drive ``updater`` through the source and its twin through ``twin_d`` (see module doc)."""
    sd = np.asarray(source_d, dtype=np.float64)
    sf = np.asarray(source_f, dtype=np.float64)
    td = np.asarray(twin_d, dtype=np.float64)
    if sd.ndim != 1 or sd.shape != sf.shape:
        raise UpdaterError(f"replay: source d and F must be 1-D of equal length, got {sd.shape} "
                           f"and {sf.shape}")
    n = td.size
    if td.ndim != 1 or n == 0 or n > sd.size:
        raise UpdaterError(f"replay: the twin needs 1 to {sd.size} steps (the source's), got "
                           f"{td.shape}")
    twin = updater.twin
    pred = np.empty(n)
    seconds = np.empty(n)
    every = max(n // 100, 1)
    for i in range(n):
        if lag:
            pred[i] = twin.set_trial(float(td[i]))[0]
            twin.commit()
            updater.observe(float(sd[i]), float(sf[i]))
        else:
            updater.observe(float(sd[i]), float(sf[i]))
            pred[i] = twin.set_trial(float(td[i]))[0]
            twin.commit()
        seconds[i] = updater.last_update_seconds
        if progress is not None and (i % every == 0 or i == n - 1):
            progress(i + 1, n)
    return ReplayResult(td.copy(), pred, seconds, lag)
