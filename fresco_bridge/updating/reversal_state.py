"""A learned reversal-state law: the secant stiffness from the last reversal as a small tanh
network of generic memory variables of a rate-independent element (issue 9, the
Menegotto-Pinto gap; BENCHMARKS.md, updating part 10).

Why: parametric laws outside the specimen's family (Chaboche, an excursion-scheduled Bouc-Wen,
a bounding surface) could not reproduce Menegotto-Pinto even in hindsight — they lack
reversal-point memory — and the basis experts of ``online_improved`` forget. Here the law is
learned, stationary given its state (no forgetting), from whole histories, and the twin runs it
on its *own* memory: its reversal forces are its own predicted forces (a recurrence).

The force of an element moving in direction ``s`` (+1/-1) is::

    F = F_r + (d - d_r) * k_init * g(z)

with ``(d_r, F_r)`` its last reversal point (the committed point where the direction of motion
last changed; (0, 0) while virgin) and ``z`` the memory variables, mirrored by ``s`` (a law that
is odd under d -> -d, F -> -F sees one loading direction):

* ``s (d - d_r)``: how far the current branch has gone;
* ``s d_r``, ``s F_r``: where it started;
* ``s d_rp``, ``s F_rp``: the reversal before (so the previous branch's excursion is known);
* ``s d_ahead``, ``s d_behind``: the element's extreme displacement so far in the direction of
  motion and the opposite one (its envelope);
* ``energy``: the work done on the element so far (cumulative ``F dd``; degrading elements
  degrade with it).

Displacements are scaled by the training data's peak |d|, forces by its peak |F|, the energy by
a data energy scale, the secant by ``k_init`` (first-loading stiffness). Nothing here is a
specimen's formula: the memory variables apply to any one-degree-of-freedom element, the form
is continuous at every reversal by construction, and a bounded ``g`` (tanh layers, linear
output) keeps every branch's force within ``|F_r| + |d - d_r| k_init max|g|``. That bounds one
branch, not the recurrence: ``F_r`` is the previous branch's end, so a ``g`` that extrapolates
badly can pump the force up reversal after reversal. Measured (BENCHMARKS.md, updating part
10): with every variable the twins stayed within 16.3 kN; without the envelope and energy
variables a twin reached 1347 kN.

Material semantics: ``set_trial(d)`` starts from the last committed state and never advances
it; a reversal is taken at the committed point when a trial moves against ``s``.

Fitting (:func:`fit_law`): weighted Levenberg-Marquardt (``lm``) of ``g`` on the secant targets
``(F - F_r) / (d - d_r)`` with weights ``(d - d_r)**2`` — exactly the squared force error —
with the memory variables computed along a measured history with the *measured* forces
(teacher forcing). Several networks fitted from different starts can be averaged (an
ensemble: the law's ``g`` is their mean).

Verdict (BENCHMARKS.md, updating part 10): the learned law *can* represent Menegotto-Pinto
(fitted to the twin's own history, its twin free-runs within 0.23/0.30 kN), but fitted to the
tested element (and the offline database) it transfers to the twin no better than 1.10–2.92 kN
(targets 0.45/0.58); the errors sit in the twin's early, barely-yielded states, and other
records' histories do not close seed 1's gap. :class:`ReversalStateUpdater` learns it online;
as a sixth expert of ``online_improved`` (design H) it lowered the Menegotto-Pinto MAETH by
1.5–18 % on design seeds 1–2 and by nothing on seeds 3–6, so it is not in the default mixture
(``benchmarks.reversal_state:mixture`` builds that candidate).
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass
from typing import NamedTuple

import numpy as np
import numpy.typing as npt

from fresco_bridge.updating.base import OwnsTwin, UpdaterError, check_measurement
from fresco_bridge.updating.branch import initial_stiffness, offline_data
from fresco_bridge.updating.lm import LmOptions, levenberg_marquardt
from fresco_bridge.updating.mlp import Mlp
from fresco_bridge.updating.refit import MeasuredHistory
from sim_actuator.models.base import trial_input_error

__all__ = ["FEATURES", "RELATIVE_FEATURES", "VARIABLES", "Memory", "ReversalStateLaw",
           "ReversalStateUpdater", "Scales", "features", "fit_law", "scales"]

FloatArray = npt.NDArray[np.float64]

FEATURES = ("s(d-d_r)", "s d_r", "s F_r", "s d_rp", "s F_rp", "s d_ahead", "s d_behind",
            "energy")  # fmt: skip
"""The memory variables, in input order (module docstring)."""

RELATIVE_FEATURES = ("s(d-d_r)", "s(d_ahead-d_r)", "range", "|d_r-d_rp|", "s F_r", "s F_rp",
                     "energy")  # fmt: skip
"""A variant measured in BENCHMARKS.md (updating part 10, worse): positions only relative to
the last reversal (distance to the envelope ahead, the envelope's span d_max - d_min, the
previous branch's length), so two elements at different absolute positions look alike."""

VARIABLES = {"absolute": FEATURES, "relative": RELATIVE_FEATURES}


@dataclass(frozen=True)
class Scales:
    """Data scales of the inputs and the output (module docstring) and the memory variables
    used: ``variables`` (a key of ``VARIABLES``) less the names in ``drop``."""

    disp: float
    force: float
    energy: float
    stiffness: float
    variables: str = "absolute"
    drop: tuple[str, ...] = ()

    def __post_init__(self) -> None:
        names = VARIABLES.get(self.variables)
        if names is None or any(name not in names for name in self.drop):
            raise UpdaterError(f"reversal-state: unknown variables {self.variables!r} or drop "
                               f"{self.drop!r} (known: {VARIABLES})")
        if len(self.drop) >= len(names):
            raise UpdaterError("reversal-state: every memory variable dropped")

    @property
    def names(self) -> tuple[str, ...]:
        """The memory variables in input order."""
        return tuple(n for n in VARIABLES[self.variables] if n not in self.drop)

    @property
    def keep(self) -> list[int]:
        """Their indices in the variable set."""
        return [i for i, n in enumerate(VARIABLES[self.variables]) if n not in self.drop]


def scales(disp: FloatArray, force: FloatArray, variables: str = "absolute",
           drop: tuple[str, ...] = ()) -> Scales:
    """Scales from a measured history: peak |d|, peak |F|, the work done along it (at least
    peak |d| × peak |F|), the first-loading stiffness."""
    d_peak = float(np.max(np.abs(disp)))
    f_peak = float(np.max(np.abs(force)))
    k = initial_stiffness(disp, force)
    if not (d_peak > 0.0 and f_peak > 0.0 and k > 0.0):
        raise UpdaterError(f"reversal-state: the data never load (peak |d| {d_peak!r}, peak |F| "
                           f"{f_peak!r}, first-loading stiffness {k!r})")
    work = float(np.sum(0.5 * (force[1:] + force[:-1]) * np.diff(disp)))
    return Scales(d_peak, f_peak, max(work, d_peak * f_peak), k, variables, drop)


class Memory(NamedTuple):
    """Committed memory of an element (module docstring); ``s`` = 0 while it has not moved."""

    d: float = 0.0
    f: float = 0.0
    s: float = 0.0
    d_r: float = 0.0
    f_r: float = 0.0
    d_rp: float = 0.0
    f_rp: float = 0.0
    d_max: float = 0.0
    d_min: float = 0.0
    energy: float = 0.0

    def branch(self, d: float) -> Memory:
        """The memory a trial at ``d`` moves on: a reversal at the committed point if ``d``
        goes against ``s`` (the committed fields otherwise unchanged)."""
        step = d - self.d
        if step == 0.0:
            return self
        s = 1.0 if step > 0.0 else -1.0
        if self.s == 0.0:
            return self._replace(s=s)
        if s != self.s:
            return self._replace(s=s, d_r=self.d, f_r=self.f, d_rp=self.d_r, f_rp=self.f_r)
        return self

    def committed_at(self, d: float, f: float) -> Memory:
        """The memory after committing (d, f) on this branch."""
        return self._replace(d=d, f=f, d_max=max(self.d_max, d), d_min=min(self.d_min, d),
                             energy=self.energy + 0.5 * (self.f + f) * (d - self.d))

    def inputs(self, d: float, sc: Scales) -> FloatArray:
        """The scaled, mirrored memory variables at ``d`` on this branch (``sc.names``; the
        first is always s (d - d_r))."""
        s = self.s if self.s != 0.0 else 1.0
        ahead, behind = (self.d_max, self.d_min) if s > 0.0 else (self.d_min, self.d_max)
        u, v = s / sc.disp, s / sc.force
        if sc.variables == "absolute":
            z = np.array([u * (d - self.d_r), u * self.d_r, v * self.f_r, u * self.d_rp,
                          v * self.f_rp, u * ahead, u * behind, self.energy / sc.energy])
        else:
            z = np.array([u * (d - self.d_r), u * (ahead - self.d_r),
                          (self.d_max - self.d_min) / sc.disp, abs(self.d_r - self.d_rp) / sc.disp,
                          v * self.f_r, v * self.f_rp, self.energy / sc.energy])
        return z if not sc.drop else z[sc.keep]


def features(disp: FloatArray, force: FloatArray, sc: Scales
             ) -> tuple[FloatArray, FloatArray, FloatArray]:
    """(inputs n × len(sc.names), secant targets, weights) along a measured history from the
    virgin state, the memory driven by the measured forces (teacher forcing); secant = (F - F_r) /
    ((d - d_r) k_init), weight = ((d - d_r) k_init / F_peak)**2 (0 where d = d_r)."""
    n = disp.size
    x = np.empty((n, len(sc.names)))
    y = np.zeros(n)
    w = np.zeros(n)
    mem = Memory()
    for i, (d, f) in enumerate(zip(disp.tolist(), force.tolist(), strict=True)):
        mem = mem.branch(d)
        x[i] = mem.inputs(d, sc)
        run = (d - mem.d_r) * sc.stiffness
        if run != 0.0:
            y[i] = (f - mem.f_r) / run
            w[i] = (run / sc.force) ** 2
        mem = mem.committed_at(d, f)
    return x, y, w


def fit_law(net: Mlp, theta0: FloatArray,
            histories: list[tuple[FloatArray, FloatArray, float]], sc: Scales,
            options: LmOptions) -> tuple[FloatArray, float]:
    """(theta, rms force error) of ``g`` fitted by weighted LM to the histories (d, F, weight),
    each from the virgin state, teacher-forced (:func:`features`)."""
    parts = [(*features(d, f, sc), weight) for d, f, weight in histories]
    x = np.concatenate([p[0] for p in parts])
    y = np.concatenate([p[1] for p in parts])
    w = np.concatenate([p[2] * p[3] for p in parts])
    keep = w > 0.0
    if not np.any(keep):
        raise UpdaterError("reversal-state: no sample away from a reversal point to fit")
    result = levenberg_marquardt(net, theta0, x[keep], y[keep], w[keep], options)
    theta = np.asarray(result.theta, dtype=np.float64)
    r = net.forward(theta, x[keep]) - y[keep]
    rms = math.sqrt(float(w[keep] @ (r * r)) / float(np.sum(keep))) * sc.force
    return theta, rms


class _Parameters:
    """The latest parameters of the ensemble's networks (one row each), shared by an
    element's law and its clones."""

    def __init__(self, thetas: FloatArray) -> None:
        self.thetas = np.atleast_2d(thetas)

    def g(self, net: Mlp, z: FloatArray) -> tuple[float, FloatArray]:
        """The ensemble's mean g at ``z`` and its input gradient."""
        total, grad = 0.0, np.zeros(z.size)
        for theta in self.thetas:
            y, dy = net.input_gradient(theta, z)
            total += y
            grad += dy
        k = self.thetas.shape[0]
        return total / k, grad / k


class ReversalStateLaw:
    """The learned law as a ``HysteresisModel`` (module docstring); ``params`` may be shared
    with other elements (the tested element's law, the twin, shadow copies): a new ``theta``
    applies at their next trial."""

    name = "reversal-state"

    def __init__(self, net: Mlp, params: _Parameters | FloatArray, sc: Scales) -> None:
        self.net = net
        self.params = params if isinstance(params, _Parameters) else _Parameters(params)
        self.scales = sc
        self._committed = Memory()
        self._trial = self._committed

    def set_trial(self, d: float) -> tuple[float, float]:
        if not math.isfinite(d):
            raise trial_input_error(self.name, d)
        mem = self._committed.branch(d)
        sc = self.scales
        g, grad = self.params.g(self.net, mem.inputs(d, sc))
        run = d - mem.d_r
        force = mem.f_r + run * sc.stiffness * g
        s = mem.s if mem.s != 0.0 else 1.0
        tangent = sc.stiffness * (g + run * float(grad[0]) * s / sc.disp)
        self._trial = mem.committed_at(d, force)
        return force, tangent

    def commit(self) -> None:
        self._committed = self._trial

    def revert_to_last_commit(self) -> None:
        self._trial = self._committed

    def revert_to_start(self) -> None:
        self._committed = self._trial = Memory()

    @property
    def initial_tangent(self) -> float:
        g, _ = self.params.g(self.net, Memory(s=1.0).inputs(0.0, self.scales))
        return self.scales.stiffness * g

    @property
    def committed(self) -> tuple[float, float]:
        return self._committed.d, self._committed.f

    def clone(self) -> ReversalStateLaw:
        law = ReversalStateLaw(self.net, self.params, self.scales)
        law._committed, law._trial = self._committed, self._trial
        return law


class ReversalStateUpdater(OwnsTwin):
    """The law learned online: an ensemble fitted to the offline database, refitted every
    ``every`` steps after ``warmup`` (warm-started, ``refit_iterations`` LM iterations per
    member) on the offline database plus the tested element's whole measured history, no
    forgetting. The twin (and any clone) runs the latest parameters on its own memory; its
    memory is not replayed after a refit (its reversal points stay those it passed through).
    ``predict`` is the one-step force from the tested element's *measured* memory."""

    name = "reversal-state"

    def __init__(self, *, offline: tuple[npt.ArrayLike, npt.ArrayLike],
                 hidden: tuple[int, ...] = (8, 8), members: int = 3, iterations: int = 60,
                 every: int = 500, refit_iterations: int = 15, warmup: int = 500) -> None:
        disp, force = offline_data(offline, self.name)
        if (members < 1 or iterations < 1 or every < 1 or refit_iterations < 1 or warmup < 1
                or not hidden or min(hidden) < 1):
            raise UpdaterError(f"{self.name}: members, iterations, every, refit_iterations, "
                               f"warmup and the hidden sizes must be >= 1 (got {members}, "
                               f"{iterations}, {every}, {refit_iterations}, {warmup}, {hidden})")
        self.scales = scales(disp, force)
        self.net = Mlp((len(self.scales.names), *hidden, 1))
        self._offline = (disp, force, 1.0)
        options = LmOptions(max_iterations=iterations, mu=1e-3)
        thetas = [fit_law(self.net, self.net.init_params(np.random.default_rng(seed)),
                          [self._offline], self.scales, options)[0] for seed in range(members)]
        self._twin = ReversalStateLaw(self.net, np.array(thetas), self.scales)
        self.params = self._twin.params
        self.refit_iterations = refit_iterations
        self.refits = 0
        self._memory = Memory()
        self._history = MeasuredHistory(every, warmup)
        self._last_update = 0.0

    def source_twin(self) -> ReversalStateLaw:
        """The law on the tested element's measured memory now (shadow scoring)."""
        law = ReversalStateLaw(self.net, self.params, self.scales)
        law._committed = law._trial = self._memory
        return law

    def predict(self, d: float) -> float:
        """One-step-ahead force of the tested element at ``d`` (nothing changes)."""
        mem = self._memory.branch(d)
        g, _ = self.params.g(self.net, mem.inputs(d, self.scales))
        return mem.f_r + (d - mem.d_r) * self.scales.stiffness * g

    def observe(self, d: float, force: float) -> None:
        d, force = check_measurement(self.name, d, force)
        start = time.perf_counter()
        self._memory = self._memory.branch(d).committed_at(d, force)
        if self._history.append(d, force):
            self.refit()
        self._last_update = time.perf_counter() - start

    def refit(self) -> None:
        """Refit every member now, warm-started, on the offline database and the history."""
        histories = [self._offline, (*self._history.arrays(), 1.0)]
        options = LmOptions(max_iterations=self.refit_iterations, mu=1e-3)
        self.params.thetas = np.array([fit_law(self.net, theta, histories, self.scales,
                                               options)[0] for theta in self.params.thetas])
        self.refits += 1
