"""A hysteresis law identified online: periodic warm-started bounded least squares on the tested
element's whole measured history, the twin running the same law with the latest parameters on
its own history. Why: a law with a real internal state generalises across histories where its
family is right, which weights of a basis on the recent past do not.

The law is a ``lawfit.LawFamily`` (any law of ``sim_actuator.models`` with named free
parameters) and the fit is ``lawfit.fit_law``; this module adds what an online refit needs:

* :func:`compress`: the samples a rate-independent law needs to reproduce a history's states —
  every ``stride``-th sample plus every reversal (local extremum of d) and the last sample. A
  law whose step is exact along a monotonic segment (closed-form return mapping) gives the same
  state from the compressed history as from the whole; one integrated in sub-steps of bounded
  size (Bouc-Wen's RK4) nearly so;
* :class:`RefitUpdater`: the Updater. ``observe`` steps the tested element's law (for
  ``predict``) and keeps the history; every ``every`` steps it refits, warm-started from the
  current parameters, ``max_nfev`` evaluations, on the compressed history so far (plus the
  offline history with weight ``offline_weight``); the law's state on the tested element and
  the twin's are then recomputed by replaying each element's own (compressed) displacement
  history with the new parameters. The twin and every clone of it (shadow copies) see a new
  parameter set at their next ``set_trial``: parameters are shared, states are each element's.

After every fit (the offline one included) :attr:`RefitUpdater.misfit` is the rms force error of
the new parameters over the samples fitted (the compressed histories, each weighted as in the
fit) and :attr:`RefitUpdater.force_peak` their peak |force|: how well one parameter set explains
the element's *whole* history (``improved``'s ``law_trust`` reads it).

Cost: a refit is ``max_nfev × (free + 1)`` law evaluations over the compressed history (finite
differences), a spike every ``every`` steps; an ordinary step is one law step per element.
"""

from __future__ import annotations

import math
import time
from collections.abc import Sequence

import numpy as np
import numpy.typing as npt

from fresco_bridge.lawfit import LawFamily, fit_law, law_forces
from fresco_bridge.updating.base import OwnsTwin, UpdaterError, check_measurement
from fresco_bridge.updating.branch import offline_data
from sim_actuator.models.base import HysteresisModel, trial_input_error

__all__ = ["MeasuredHistory", "RefitUpdater", "compress"]

FloatArray = npt.NDArray[np.float64]
IntArray = npt.NDArray[np.intp]


def compress(disp: FloatArray, stride: int) -> IntArray:
    """Indices of every ``stride``-th sample, every reversal and the last sample (sorted)."""
    n = disp.size
    if n == 0:
        return np.zeros(0, dtype=np.intp)
    keep = np.zeros(n, dtype=bool)
    keep[::max(stride, 1)] = True
    keep[-1] = True
    if n > 2:
        step = np.diff(disp)
        # a reversal: the increment changes sign (zero increments carry the previous sign)
        sign = np.sign(step)
        nz = np.flatnonzero(sign)
        if nz.size:
            filled = sign[nz][np.maximum(np.searchsorted(nz, np.arange(sign.size), "right") - 1,
                                         0)]  # fmt: skip
            keep[1:-1] |= filled[1:] != filled[:-1]
    return np.flatnonzero(keep)


class MeasuredHistory:
    """The tested element's whole measured history and when an online refit is due: after
    ``warmup`` measurements, then every ``every`` (shared by the refitting updaters)."""

    def __init__(self, every: int, warmup: int) -> None:
        self.every, self.warmup = every, warmup
        self._disp: list[float] = []
        self._force: list[float] = []

    def append(self, d: float, force: float) -> bool:
        """Keep one measurement; True when a refit is due now."""
        self._disp.append(d)
        self._force.append(force)
        n = len(self._disp)
        return n >= self.warmup and (n - self.warmup) % self.every == 0

    def arrays(self) -> tuple[FloatArray, FloatArray]:
        """(displacements, forces) so far."""
        return (np.array(self._disp, dtype=np.float64), np.array(self._force, dtype=np.float64))


class _Law:
    """The latest parameters, shared by the tested element's law, the twin and its clones."""

    def __init__(self, family: LawFamily, x: FloatArray) -> None:
        self.family = family
        self.x = x
        self.version = 0

    def update(self, x: FloatArray) -> None:
        self.x = x
        self.version += 1

    def build(self) -> HysteresisModel:
        return self.family.build(self.family.params(self.x))


class _RefitTwin:
    """The law on the twin's own history (material semantics); at a new parameter set it
    replays its own committed displacements (compressed) before its next trial."""

    def __init__(self, law: _Law, name: str, stride: int) -> None:
        self._law = law
        self.name = name
        self._stride = stride
        self._model = law.build()
        self._version = law.version
        self._history: list[float] = []

    def _current(self) -> HysteresisModel:
        if self._version != self._law.version:
            model = self._law.build()
            disp = np.array(self._history, dtype=np.float64)
            law_forces(model, disp[compress(disp, self._stride)])
            self._model, self._version = model, self._law.version
        return self._model

    def set_trial(self, d: float) -> tuple[float, float]:
        if not np.isfinite(d):
            raise trial_input_error(self.name, d)
        return self._current().set_trial(d)

    def commit(self) -> None:
        model = self._current()
        model.commit()
        self._history.append(model.committed[0])

    def advance(self, d: float) -> float:
        """``set_trial(d)`` and ``commit()`` in one, the force only (shadow scoring)."""
        force = self.set_trial(d)[0]
        self.commit()
        return force

    def revert_to_last_commit(self) -> None:
        self._current().revert_to_last_commit()

    def revert_to_start(self) -> None:
        self._history.clear()
        self._model = self._law.build()
        self._version = self._law.version

    @property
    def initial_tangent(self) -> float:
        return self._current().initial_tangent

    @property
    def committed(self) -> tuple[float, float]:
        return self._current().committed

    def clone(self) -> HysteresisModel:
        twin = _RefitTwin(self._law, self.name, self._stride)
        twin._model, twin._version = self._model.clone(), self._version
        twin._history = list(self._history)
        return twin


class RefitUpdater(OwnsTwin):
    """A law refitted online to the tested element's whole history (module docstring)."""

    def __init__(self, family: LawFamily, *, offline: tuple[npt.ArrayLike, npt.ArrayLike],
                 every: int = 200, stride: int = 5, max_nfev: int = 8,
                 offline_weight: float = 1.0, offline_nfev: int = 40, warmup: int = 50,
                 name: str = "online_refit") -> None:  # fmt: skip
        """``offline``: (d, F) from the virgin state, fitted first (``offline_nfev``) and kept
        in every refit with weight ``offline_weight`` (0 drops it); ``every``: steps between
        refits, the first after ``warmup`` steps; ``stride``: compression of the histories."""
        disp, force = offline_data(offline, name)
        if every < 1 or stride < 1 or max_nfev < 1 or offline_nfev < 1 or warmup < 1:
            raise UpdaterError(f"{name}: every, stride, max_nfev, offline_nfev, warmup must be "
                               f">= 1 (got {every}, {stride}, {max_nfev}, {offline_nfev}, "
                               f"{warmup})")  # fmt: skip
        if not offline_weight >= 0.0:
            raise UpdaterError(f"{name}: offline_weight must be >= 0 (got {offline_weight})")
        self.name = name
        self.family = family
        self.every, self.stride, self.max_nfev, self.warmup = every, stride, max_nfev, warmup
        self.space = family.space(disp, force)
        keep = compress(disp, stride)
        self._offline = (disp[keep], force[keep], float(offline_weight))
        x = fit_law(family, [(disp[keep], force[keep], 1.0)], self.space, max_nfev=offline_nfev)
        self._law = _Law(family, x)
        self.force_peak = float(np.max(np.abs(force))) if force.size else 0.0
        """Peak |force| of the histories fitted (offline and online so far)."""
        self.misfit = 0.0
        """Rms force error of the latest parameters over the samples fitted (module docstring)."""
        self._measure([(disp[keep], force[keep], 1.0)], None)
        self._source = self._law.build()
        self._history = MeasuredHistory(every, warmup)
        self._twin = _RefitTwin(self._law, name, stride)
        self._last_update = 0.0
        self.refits = 0

    @property
    def parameters(self) -> dict[str, float]:
        """The latest free parameters by name."""
        return self.family.params(self._law.x)

    def source_twin(self) -> HysteresisModel:
        """The law on the tested element's history now (shadow scoring)."""
        return self._source.clone()

    def predict(self, d: float) -> float:
        """One-step-ahead force of the tested element at ``d`` (nothing committed)."""
        force = self._source.set_trial(d)[0]
        self._source.revert_to_last_commit()
        return force

    def observe(self, d: float, force: float) -> None:
        d, force = check_measurement(self.name, d, force)
        start = time.perf_counter()
        self._source.set_trial(d)
        self._source.commit()
        if self._history.append(d, force):
            self.refit()
        self._last_update = time.perf_counter() - start

    def refit(self) -> None:
        """Refit now on the history so far (warm start) and move the law to the new state."""
        disp, force = self._history.arrays()
        keep = compress(disp, self.stride)
        histories = [(disp[keep], force[keep], 1.0)]
        if self._offline[2] > 0.0:
            histories.append(self._offline)
        x = fit_law(self.family, histories, self.space, start=self._law.x,
                    max_nfev=self.max_nfev)  # fmt: skip
        self._law.update(x)
        self._source = self._law.build()
        self._measure(histories, law_forces(self._source, disp[keep]))
        self.refits += 1

    def _measure(self, histories: Sequence[tuple[FloatArray, FloatArray, float]],
                 first: FloatArray | None) -> None:
        """``misfit`` and ``force_peak`` of the latest parameters over ``histories`` (``first``:
        the law's forces along the first one, when already computed)."""
        params = self._law.family.params(self._law.x)
        total = weight = 0.0
        for i, (d, f, w) in enumerate(histories):
            if i == 0 and first is not None:
                pred = first
            elif self.family.forces is not None:
                pred = self.family.forces(params, d)
            else:
                pred = law_forces(self._law.build(), d)
            total += w * float(np.sum((pred - f) ** 2))
            weight += w * d.size
            self.force_peak = max(self.force_peak, float(np.max(np.abs(f))) if f.size else 0.0)
        self.misfit = math.sqrt(total / weight) if weight > 0.0 else 0.0
        if not math.isfinite(self.misfit):
            self.misfit = math.inf
