"""Shadow scoring for ``online_improved``: each expert's *current* model tested on a stretch of
the tested element's own history whose state matches the twin's now.

Why: the mixture's usual score is each expert's error on the tested element's *recent* past,
which can rank experts as their twins would not when the twin is in another state (an expert
weighted highest can be the worst twin alone). Old errors binned by state are stale, and old
weights are worse; here the stretch is old but the model is current: every ``every`` steps, the
stored step of the tested element whose state is nearest the twin's — span so far (max d −
min d) and recent amplitude (max |d| over the last ``window`` steps), compared in log ratio —
starts a free run of each expert's twin over the next ``length`` measured steps, from the
expert's memory of the tested element at that step (measured forces), with the expert's
weights of *now*; span and amplitude get 2 % of the tested element's peak |d| so far added
before the log ratio, so an element at rest does not divide by zero. The mean squared error of
that free run is the expert's shadow score ``H_k``; the mixture weighs experts by
``1 / (S_k · H_k)`` (``S_k`` the usual score). Only displacements, the tested element's
measured forces and the experts' own models enter; never the twin's truth.

Cost: one free run of ``length`` steps per expert every ``every`` steps (the median step does
none of it); memory: one stored twin per expert per step, the oldest dropped past ``keep``
steps. Figures and what it changes: ``BENCHMARKS.md``, "Online updating".
"""

from __future__ import annotations

from collections import deque
from collections.abc import Callable, Sequence
from typing import Protocol, runtime_checkable

import numpy as np
import numpy.typing as npt

from fresco_bridge.updating.base import UpdaterError
from sim_actuator.models.base import HysteresisModel

__all__ = ["FreeRun", "ShadowScorer", "element_state", "matched_start", "stepper"]

FloatArray = npt.NDArray[np.float64]


@runtime_checkable
class FreeRun(Protocol):
    """A twin that can take a step and commit it without computing its tangent."""

    def advance(self, d: float) -> float: ...


def stepper(model: HysteresisModel) -> Callable[[float], float]:
    """A function that moves ``model`` to d, commits and returns the force: ``advance`` where
    the model has it (no tangent probe), else ``set_trial`` then ``commit``."""
    if isinstance(model, FreeRun):
        return model.advance

    def step(d: float) -> float:
        force = model.set_trial(d)[0]
        model.commit()
        return force

    return step


def element_state(d: FloatArray, window: int) -> tuple[FloatArray, FloatArray]:
    """(span so far, recent amplitude) at every index of the displacement history ``d``: span =
    max − min of ``d[:i + 1]``, amplitude = max |d| over ``d[i - window + 1:i + 1]``."""
    if d.ndim != 1 or d.size == 0 or window < 1:
        raise UpdaterError(f"element_state: need a non-empty 1-D history and window >= 1 (got "
                           f"shape {d.shape}, window {window})")
    span = np.maximum.accumulate(d) - np.minimum.accumulate(d)
    a = np.abs(d)
    amp = np.empty(d.size)
    head = min(window - 1, d.size)
    amp[:head] = np.maximum.accumulate(a[:head])
    if d.size >= window:
        amp[window - 1:] = np.lib.stride_tricks.sliding_window_view(a, window).max(axis=1)
    return span, amp


def matched_start(tested: FloatArray, twin: FloatArray, *, length: int, window: int,
                  floor: float) -> int:
    """Index ``t`` of the tested history (``t + length < tested.size``) whose state is nearest
    the twin's last state: the smallest sum of |log| ratios of span and amplitude, each plus
    ``floor`` (so an element at rest does not divide by zero); the earliest on a tie."""
    if tested.size <= length or twin.size == 0 or not floor > 0.0:
        raise UpdaterError(f"matched_start: need more than {length} tested steps, a twin step "
                           f"and floor > 0 (got {tested.size}, {twin.size}, {floor})")
    span_t, amp_t = element_state(tested, window)
    span_w, amp_w = element_state(twin, window)
    n = tested.size - length
    distance = (np.abs(np.log((span_t[:n] + floor) / (span_w[-1] + floor)))
                + np.abs(np.log((amp_t[:n] + floor) / (amp_w[-1] + floor))))  # fmt: skip
    return int(np.argmin(distance))


class ShadowScorer:
    """The stored history and the shadow scores (module docstring)."""

    FLOOR = 0.02
    """Added to span and amplitude before their log ratio, times the tested peak |d| so far."""

    def __init__(self, experts: int, *, length: int = 100, window: int = 100,
                 every: int = 20, keep: int = 20000) -> None:
        if not (experts >= 1 and length >= 1 and window >= 1 and every >= 1
                and keep > length + window):  # fmt: skip
            raise UpdaterError(f"online_improved: bad shadow settings (experts {experts}, length "
                               f"{length}, window {window}, every {every}, keep {keep})")
        self.experts = experts
        self.length, self.window, self.every = length, window, every
        self._d: deque[float] = deque(maxlen=keep)
        self._f: deque[float] = deque(maxlen=keep)
        self._starts: deque[tuple[HysteresisModel, ...]] = deque(maxlen=keep)
        self._twin: deque[float] = deque(maxlen=keep)
        self._steps = 0
        self.scores: FloatArray | None = None
        """Each expert's shadow score (mean squared error), None until the first scoring."""

    def before_step(self, twins: Sequence[HysteresisModel]) -> None:
        """Store each expert's twin on its memory of the tested element *before* the step is
        observed (``source_twin``; cloned when used, so the stored one never moves)."""
        if len(twins) != self.experts:
            raise UpdaterError(f"online_improved: {len(twins)} shadow twins for "
                               f"{self.experts} experts")
        self._starts.append(tuple(twins))

    def after_step(self, d: float, force: float) -> None:
        """Store the observed tested step; re-score every ``every`` steps once enough is stored."""
        self._d.append(d)
        self._f.append(force)
        self._steps += 1
        if (self._steps % self.every == 0 and len(self._d) >= self.length + self.window
                and len(self._twin) >= self.window):  # fmt: skip
            self.scores = self._score()

    def twin_committed(self, d: float) -> None:
        """Store the twin's committed displacement (its state is what is matched)."""
        self._twin.append(d)

    def twin_reset(self) -> None:
        self._twin.clear()

    def _score(self) -> FloatArray:
        d = np.fromiter(self._d, dtype=np.float64, count=len(self._d))
        f = np.fromiter(self._f, dtype=np.float64, count=len(self._f))
        twin = np.fromiter(self._twin, dtype=np.float64, count=len(self._twin))
        floor = self.FLOOR * (float(np.max(np.abs(d))) + 1e-9)
        t = matched_start(d, twin, length=self.length, window=self.window, floor=floor)
        # the twins of step t + 1 were stored before it was observed: memory through step t
        stored = self._starts[t + 1]
        out = np.empty(len(stored))
        for k, twin_k in enumerate(stored):
            step = stepper(twin_k.clone())
            total = 0.0
            for i in range(t + 1, t + 1 + self.length):
                error = f[i] - step(float(d[i]))
                total += error * error
            out[k] = total / self.length
        return out
