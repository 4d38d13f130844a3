"""A hysteresis law identified online: periodic warm-started bounded least squares on the tested
element's *recent* measured history (a window of bounded length), the twin running the same
law with the latest parameters on its own history. Why: a law with a real internal state
generalises across histories where its family is right, which weights of a basis on the recent
past do not.

The law is a ``lawfit.LawFamily`` (any law of ``sim_actuator.models`` with named free
parameters and an explicit state, ``ParametricModel``) and the fit is ``lawfit``'s bounded
least squares; this module adds what an online refit needs:

* :func:`compress`: the samples a rate-independent law needs to reproduce a history's states —
  every ``stride``-th sample plus every reversal (local extremum of d) and the last sample. A
  law whose step is exact along a monotonic segment (closed-form return mapping) gives the same
  state from the compressed history as from the whole; one integrated in sub-steps of bounded
  size (Bouc-Wen's RK4) nearly so;
* :class:`LawWindow`: an element's last ``window`` samples and the law's state *before* them
  (a copy of the law that steps each sample as it leaves the window). Why: a refit or a new
  parameter set replays the window from that state, never the whole history, so a step's cost
  and the memory are bounded whatever the run's length. The state at the window's start is the
  one the law reached with the parameters of each step's time (incremental, as a filter's):
  before the first sample leaves the window it is the virgin state, so a run shorter than the
  window is fitted exactly as on its whole history;
* :class:`RefitUpdater`: the Updater. ``observe`` steps the tested element's law (for
  ``predict``) and its window; every ``every`` steps it refits, warm-started from the current
  parameters, ``max_nfev`` evaluations, on the compressed window (from its start state) plus
  the offline history (from the virgin state, weight ``offline_weight``); the law's state on the
  tested element and the twin's are then recomputed by replaying each element's own
  (compressed) window with the new parameters. The twin and every clone of it see a new
  parameter set at their next ``set_trial``: parameters are shared, states are each element's.

After every fit (the offline one included) :attr:`RefitUpdater.misfit` is the rms force error of
the new parameters over the samples fitted (the compressed window and the offline history, each
weighted as in the fit) and :attr:`RefitUpdater.force_peak` the peak |force| seen: how well one
parameter set explains the element's history (``improved``'s ``law_trust`` reads it).

Cost: a refit is ``max_nfev × (free + 1)`` law runs over the compressed window and the offline
history (finite differences), a spike every ``every`` steps, bounded by ``window``; an ordinary
step is two law steps per element (the front and the window's start).
"""

from __future__ import annotations

import math
import time
from collections import deque
from collections.abc import Callable, Mapping, Sequence
from typing import cast

import numpy as np
import numpy.typing as npt

from fresco_bridge.lawfit import LawFamily, bounded_least_squares, fit_law, law_forces
from fresco_bridge.updating.base import OwnsTwin, UpdaterError, check_measurement
from fresco_bridge.updating.branch import offline_data
from sim_actuator.models.base import (
    HysteresisModel,
    ModelInputError,
    ModelParameterError,
    ModelState,
    ParametricModel,
    trial_input_error,
)

__all__ = ["WINDOW", "LawWindow", "RefitUpdater", "compress"]

FloatArray = npt.NDArray[np.float64]
IntArray = npt.NDArray[np.intp]

WINDOW = 1500
"""Default window of a refit (steps of the element's history replayed from the law's state at
its start): five refits of the default schedule. A longer run costs no more per refit; a longer
window costs in proportion (BENCHMARKS.md, "Online updating")."""

ForcesFrom = Callable[[Mapping[str, float], FloatArray, ModelState], FloatArray]
"""``forces_from(params, disp, state)``: a fast form of ``law_forces`` of the law with
``params`` started from the committed ``state`` (e.g. ``sim_actuator.models.paths.drive_from``,
the same algorithm); NaN where the law refuses."""



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


class LawWindow:
    """An element's last ``size`` samples (d, and F for the tested element) and the law's
    committed state before them (module docstring)."""

    def __init__(self, start: ParametricModel, size: int) -> None:
        self.size = size
        self._start = start
        self._disp: deque[float] = deque()
        self._force: deque[float] = deque()

    def append(self, d: float, force: float = math.nan) -> None:
        """Keep one committed sample; the oldest beyond ``size`` steps the start state."""
        self._disp.append(d)
        self._force.append(force)
        if len(self._disp) > self.size:
            self._start.set_trial(self._disp.popleft())
            self._start.commit()
            self._force.popleft()

    def clear(self, start: ParametricModel) -> None:
        """Forget every sample; ``start`` (a virgin law) is the state before the next."""
        self._start = start
        self._disp.clear()
        self._force.clear()

    def arrays(self) -> tuple[FloatArray, FloatArray]:
        """(displacements, forces) of the window."""
        return (np.fromiter(self._disp, np.float64, len(self._disp)),
                np.fromiter(self._force, np.float64, len(self._force)))

    def start(self, law: _Law) -> ParametricModel:
        """A law with ``law``'s parameters from the window's start state (a new object); the
        window's start itself moves to those parameters."""
        if self._start.parameters != law.parameters():
            self._start = law.build().with_params({}, self._start.state())
        return self._start.with_params({}, self._start.state())

    def replayed(self, law: _Law, stride: int) -> tuple[ParametricModel, FloatArray]:
        """``law`` moved from the window's start along its compressed displacements: the model
        (at the window's last sample) and its forces at the compressed samples."""
        model = self.start(law)
        disp = self.arrays()[0]
        return model, law_forces(model, disp[compress(disp, stride)])

    def copy(self) -> LawWindow:
        """An independent copy (its start state and samples)."""
        window = LawWindow(self._start.with_params({}, self._start.state()), self.size)
        window._disp.extend(self._disp)
        window._force.extend(self._force)
        return window

    def __len__(self) -> int:
        return len(self._disp)


class _Law:
    """The latest parameters, shared by the tested element's law, the twin and its clones."""

    def __init__(self, family: LawFamily, x: FloatArray) -> None:
        self.family = family
        self.x = x
        self.version = 0

    def update(self, x: FloatArray) -> None:
        self.x = x
        self.version += 1

    def build(self) -> ParametricModel:
        return _parametric(self.family, self.family.build(self.family.params(self.x)))

    def parameters(self) -> dict[str, float]:
        """Every parameter of the law now (the free and the fixed ones)."""
        return self.build().parameters


def _parametric(family: LawFamily, model: HysteresisModel) -> ParametricModel:
    """``model`` as a law with an explicit state (a windowed refit needs one)."""
    if not (callable(getattr(model, "state", None))
            and callable(getattr(model, "with_params", None))):  # fmt: skip
        raise UpdaterError(f"law family {family.name!r}: its model {type(model).__name__} has "
                           "no explicit state (state(), with_params()); a windowed refit "
                           "needs one")
    return cast(ParametricModel, model)


class _RefitTwin:
    """The law on the twin's own history (material semantics); at a new parameter set it
    replays its own window (compressed) from the window's start before its next trial."""

    def __init__(self, law: _Law, name: str, stride: int, window: int) -> None:
        self._law = law
        self.name = name
        self._stride = stride
        self._model: HysteresisModel = law.build()
        self._version = law.version
        self._window = LawWindow(law.build(), window)

    def _current(self) -> HysteresisModel:
        if self._version != self._law.version:
            self._model = self._window.replayed(self._law, self._stride)[0]
            self._version = self._law.version
        return self._model

    def set_trial(self, d: float) -> tuple[float, float]:
        if not np.isfinite(d):
            raise trial_input_error(self.name, d)
        return self._current().set_trial(d)

    def commit(self) -> None:
        model = self._current()
        model.commit()
        self._window.append(model.committed[0])

    def advance(self, d: float) -> float:
        """``set_trial(d)`` and ``commit()`` in one, the force only (the free runs that score
        the experts)."""
        force = self.set_trial(d)[0]
        self.commit()
        return force

    def revert_to_last_commit(self) -> None:
        self._current().revert_to_last_commit()

    def revert_to_start(self) -> None:
        self._window.clear(self._law.build())
        self._model = self._law.build()
        self._version = self._law.version

    @property
    def initial_tangent(self) -> float:
        return self._current().initial_tangent

    @property
    def committed(self) -> tuple[float, float]:
        return self._current().committed

    def clone(self) -> HysteresisModel:
        twin = _RefitTwin.__new__(_RefitTwin)
        twin._law, twin.name, twin._stride = self._law, self.name, self._stride
        twin._model, twin._version = self._model.clone(), self._version
        twin._window = self._window.copy()
        return twin


class RefitUpdater(OwnsTwin):
    """A law refitted online to the tested element's whole history (module docstring)."""

    def __init__(self, family: LawFamily, *, offline: tuple[npt.ArrayLike, npt.ArrayLike],
                 every: int = 200, stride: int = 5, max_nfev: int = 8,
                 offline_weight: float = 1.0, offline_nfev: int = 40, warmup: int = 50,
                 window: int = WINDOW, forces_from: ForcesFrom | None = None,
                 name: str = "online_refit") -> None:  # fmt: skip
        """``offline``: (d, F) from the virgin state, fitted first (``offline_nfev``) and kept
        in every refit with weight ``offline_weight`` (0 drops it); ``every``: steps between
        refits, the first after ``warmup`` steps; ``stride``: compression of the histories;
        ``window``: the steps of each element's history a refit replays (>= ``every``);
        ``forces_from``: the fit's fast form of the law from a state (default: the objects)."""
        disp, force = offline_data(offline, name)
        if every < 1 or stride < 1 or max_nfev < 1 or offline_nfev < 1 or warmup < 1:
            raise UpdaterError(f"{name}: every, stride, max_nfev, offline_nfev, warmup must be "
                               f">= 1 (got {every}, {stride}, {max_nfev}, {offline_nfev}, "
                               f"{warmup})")  # fmt: skip
        if window < every:
            raise UpdaterError(f"{name}: window must be >= every (got window {window}, every "
                               f"{every}): every step must be in at least one refit")
        if not offline_weight >= 0.0:
            raise UpdaterError(f"{name}: offline_weight must be >= 0 (got {offline_weight})")
        self.name = name
        self.family = family
        self.every, self.stride, self.max_nfev, self.warmup = every, stride, max_nfev, warmup
        self.window = window
        self._forces_from = forces_from
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
        self._source: HysteresisModel = self._law.build()
        self._history = LawWindow(self._law.build(), window)
        self._seen = 0
        self._twin = _RefitTwin(self._law, name, stride, window)
        self._last_update = 0.0
        self.refits = 0
        if forces_from is not None:  # its compiled kernel is built (or loaded) now, not in
            # the step of the first refit: a cold JIT compile takes seconds (BENCHMARKS.md)
            forces_from(self.parameters, np.zeros(1), self._law.build().state())

    @property
    def parameters(self) -> dict[str, float]:
        """The latest free parameters by name."""
        return self.family.params(self._law.x)

    def source_twin(self) -> HysteresisModel:
        """A copy of the law on the tested element's history now."""
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
        self._history.append(d, force)
        self._seen += 1
        if self._seen >= self.warmup and (self._seen - self.warmup) % self.every == 0:
            self.refit()
        self._last_update = time.perf_counter() - start

    def refit(self) -> None:
        """Refit now on the window (warm start) and move the law to the new state."""
        disp, force = self._history.arrays()
        keep = compress(disp, self.stride)
        window = (disp[keep], force[keep], 1.0)
        histories = [window, *([self._offline] if self._offline[2] > 0.0 else [])]
        start = self._history.start(self._law)
        x = self._fit(start, histories)
        self._law.update(x)
        self._source, fitted = self._history.replayed(self._law, self.stride)
        self._measure(histories, fitted)
        self.refits += 1

    def _fit(self, start: ParametricModel,
             histories: Sequence[tuple[FloatArray, FloatArray, float]]) -> FloatArray:
        """Free parameters minimising the weighted squared force error over ``histories``: the
        first (the window) run from ``start``'s state, the others from the virgin state."""
        family = self.family
        roots = [math.sqrt(w) for _, _, w in histories]
        size = sum(d.size for d, _, _ in histories)
        peak = max((float(np.max(np.abs(f))) for _, f, _ in histories if f.size), default=1.0)
        bad = np.full(size, 10.0 * peak)
        state = start.state()

        def residual(x: FloatArray) -> FloatArray:
            try:
                params = family.params(x)
                parts = []
                for i, ((d, f, _), r) in enumerate(zip(histories, roots, strict=True)):
                    if i == 0 and self._forces_from is not None:
                        pred = self._forces_from(params, d, state)
                    elif i == 0:
                        pred = law_forces(_parametric(family, family.build(params))
                                          .with_params({}, state), d)  # fmt: skip
                    elif family.forces is not None:
                        pred = family.forces(params, d)
                    else:
                        pred = law_forces(family.build(params), d)
                    parts.append(r * (pred - f))
            except (ModelInputError, ModelParameterError):
                return bad
            out = np.concatenate(parts)
            return out if np.all(np.isfinite(out)) else bad

        return bounded_least_squares(residual, self._law.x, np.array(self.space.lower),
                                     np.array(self.space.upper),
                                     scale=np.array(self.space.scale),
                                     max_nfev=self.max_nfev).x  # fmt: skip

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
