"""``online_improved``: experts weighted by how well each reproduces the tested element.

Why a mixture: no single structure serves both kinds of specimen. A reversal-coordinate basis
(``branch``) is best where the law is far from any smooth state-variable form; a fitted law with
its own state (``physics``, ``degrading``) carries a degrading element's history over to the
twin. Which one is better can be seen online, on the tested element alone (no twin truth):

* *free run*: a shadow copy of each expert's twin is driven by the tested element's
  displacement and never sees its force (the twin's own situation), compared with the measured
  force;
* *one step*: each expert's prediction of the tested force from the tested element's measured
  memory, before it learns from the step.

``score="both"`` (default) adds the two squared errors, because each alone misleads: the
one-step error is flattered by the measured reversal force, the free-run error lets an old
drift linger. ``S_k`` is their exponentially weighted mean (factor ``mixing``, each step clipped
at ``gate**2 * S_k`` so one load-cell spike cannot flip the choice); expert k weighs
``1 / S_k**2`` (normalised). The mixture's force is the weighted sum of the experts' twins, each
on its own memory.

*Law trust* (``law_trust``): a law expert whose rms misfit over the whole history it was fitted
to is at most ``law_trust`` × that history's peak |force| takes all the weight. Why: the scores
rank experts on the *recent* past, where a forgetting basis fits as well as a law yet transfers
worse to a twin in another state; one parameter set explaining two whole histories is evidence
the law generalises. ``law_trust=0`` is the plain mixture. The switch changes only at a refit.

*Do no harm* (the offline start kept as a candidate): the twin serves either the mixture or the
*offline start*, the Bilinear calibrated to the offline database (``none --offline``, what the
lab would run without updating), whichever has the smaller **prequential free-run error** on
the tested element so far: the mean over every observed step of the squared error of a free-run
copy of each (driven by the tested element's displacement alone, never its force, the twin's
own situation) against the measured force, each made *before* the step is learned. Why this
and no threshold: the offline start learns nothing, so its error is out of sample by
construction, and the mixture's is too (it predicts before it learns), so neither is
flattered; on the tested element the served law is never the worse of the two over the run.
Both keep their own state on the twin at every commit, so a switch is to a model that has
followed the twin's whole history. Where the specimen is in the Bilinear family the updater
ends where its start was; where it is not, the mixture takes over as soon as its accumulated
error is the smaller.

*Divergence*: an expert's law can run away on its own history (a reversal basis extrapolated
past its data feeds its reversal force back with a gain above 1). A prediction that is not
finite, or whose squared error overflows a float, scores the largest float (it loses every
comparison) and a free-run copy that is not finite restarts from the virgin state; the served
twin leaves out a part whose answer is not finite (the offline start answers if none is left).

Experts (``experts=``; :data:`EXPERTS` by default, :data:`OPTIONAL_EXPERTS` on request):
``reversal`` (the basis alone), ``reversal+memory`` (plus previous-branch and envelope terms),
``bouc-wen+memory`` (a fitted Bouc-Wen law plus the memory basis on its residual, ``physics``),
``reversal+stops`` (plus stop operators scheduled on the element's own plastic deformation,
``play``), ``baber-wen`` (a degrading law refitted on the tested element's recent history,
``degrading``, from the law's state at the window's start), ``bilinear`` (the offline
start's family refitted the same way, ``bilinear``: the law the lab calibrates offline, which
the mixture must be able to represent exactly). The bases learn by
exponentially weighted ridge least squares with Huber gating (``forgetting``, ``ridge``,
``gate``); the laws by periodic refits on a window of bounded length, which cost far more
than an ordinary step but do not grow with the run: served live, the updater belongs beside the
event loop. Figures, the choice
of the defaults and what fails: ``BENCHMARKS.md``, "Online updating".
"""

from __future__ import annotations

import math
import sys
import time
from typing import Any, Protocol

import numpy as np
import numpy.typing as npt

from fresco_bridge.lawfit import calibrate_bilinear
from fresco_bridge.updating.base import OwnsTwin, UpdaterError, check_measurement
from fresco_bridge.updating.branch import BranchMemory, BranchRls, ReversalBasis
from sim_actuator.models import make_model
from sim_actuator.models.base import HysteresisModel, trial_input_error

__all__ = ["EXPERTS", "LAW_TRUST", "SCORES", "BranchMemory", "OnlineImproved", "ReversalBasis"]

FloatArray = npt.NDArray[np.float64]

EXPERTS = ("reversal", "reversal+memory", "bouc-wen+memory", "reversal+stops", "baber-wen",
           "bilinear")
"""The experts ``online_improved`` combines by default."""

OPTIONAL_EXPERTS = ("reversal+memory+stops",)
"""Experts that can be asked for by name but are not in the default mixture."""

LAW_EXPERTS = ("baber-wen", "bilinear")
"""Experts that are a law refitted on the tested element's history (``refit.RefitUpdater``):
``law_trust`` applies to them."""

LAW_TRUST = 0.02
"""Default ``law_trust``: a law expert whose rms misfit over the whole history it was fitted to
is at most this fraction of that history's peak |force| takes all the weight (module
docstring). Chosen between the misfits of a right and a wrong law family: ``BENCHMARKS.md``,
"Online updating"."""

SCORES = ("both", "free-run", "one-step")
"""How an expert is scored on the tested element (module docstring)."""


class _Expert(Protocol):
    def predict(self, d: float) -> float: ...
    def observe(self, d: float, force: float) -> None: ...
    @property
    def twin(self) -> HysteresisModel: ...


class _MixtureTwin:
    """The served twin: the weighted sum of the experts' twins and the offline start's twin
    (weight 1 on the start while it is served, ``OnlineImproved.served_weights``). Material
    semantics: each part keeps its own state, every part commits at every commit."""

    name = "online_improved"

    def __init__(self, owner: OnlineImproved, parts: list[HysteresisModel]) -> None:
        self._owner = owner
        self._parts = parts
        self._committed = (0.0, 0.0)
        self._trial = self._committed

    def set_trial(self, d: float) -> tuple[float, float]:
        if not math.isfinite(d):
            raise trial_input_error(self.name, d)
        w = self._owner.served_weights()
        answers = [(weight, *part.set_trial(d))
                   for weight, part in zip(w.tolist(), self._parts, strict=True) if weight > 0.0]
        finite = [(weight, f, k) for weight, f, k in answers
                  if math.isfinite(f) and math.isfinite(k)]  # a diverged part has no say
        total = sum(weight for weight, _, _ in finite)
        if total <= 0.0:  # every weighted part diverged: the offline start (a Bilinear) answers
            finite, total = [(1.0, *self._parts[-1].set_trial(d))], 1.0
        force = sum(weight * f for weight, f, _ in finite) / total
        tangent = sum(weight * k for weight, _, k in finite) / total
        self._trial = (d, force)
        return force, tangent

    def commit(self) -> None:
        for part in self._parts:
            part.commit()
        self._committed = self._trial

    def revert_to_last_commit(self) -> None:
        for part in self._parts:
            part.revert_to_last_commit()
        self._trial = self._committed

    def revert_to_start(self) -> None:
        for part in self._parts:
            part.revert_to_start()
        self._committed = self._trial = (0.0, 0.0)

    @property
    def initial_tangent(self) -> float:
        w = self._owner.served_weights()
        return float(sum(weight * part.initial_tangent
                         for weight, part in zip(w.tolist(), self._parts, strict=True)))

    @property
    def committed(self) -> tuple[float, float]:
        return self._committed

    def clone(self) -> HysteresisModel:
        twin = _MixtureTwin(self._owner, [part.clone() for part in self._parts])
        twin._committed, twin._trial = self._committed, self._trial
        return twin


_WORST = sys.float_info.max
"""The squared error of a prediction that is not finite or whose error squared overflows: the
largest a float holds, so such a copy loses every comparison and nothing summed overflows."""


def _squared_error(measured: float, predicted: float) -> float:
    """``(measured - predicted)**2``, never raising: :data:`_WORST` when not finite."""
    squared = (measured - predicted) * (measured - predicted)
    return squared if squared <= _WORST else _WORST  # inf and NaN both fail ``<=``


def _free_run(model: HysteresisModel, d: float) -> float:
    """Move ``model`` to ``d`` and commit: its force (a free-run copy on the tested element)."""
    advance = getattr(model, "advance", None)
    if advance is not None:
        return float(advance(d))
    force = model.set_trial(d)[0]
    model.commit()
    return force


class OnlineImproved(OwnsTwin):
    """Our updater (see the module docstring); ``offline`` = (displacement, force) arrays.

    Keyword options only, so the class itself is the registry's factory."""

    name = "online_improved"

    def __init__(
        self,
        *,
        offline: tuple[npt.ArrayLike, npt.ArrayLike],
        experts: str | tuple[str, ...] = EXPERTS,
        forgetting: float = 0.998,
        ridge: float = 1e-3,
        gate: float = 4.0,
        mixing: float = 0.99,
        score: str = "both",
        law_trust: float = LAW_TRUST,
    ) -> None:
        names = tuple(e.strip() for e in experts.split(",")) if isinstance(experts, str) else (
            tuple(experts))  # fmt: skip
        unknown = [e for e in names if e not in EXPERTS + OPTIONAL_EXPERTS]
        if not names or unknown or len(set(names)) != len(names):
            known = ", ".join(EXPERTS + OPTIONAL_EXPERTS)
            raise UpdaterError(f"online_improved: experts must be distinct names from {known} "
                               f"(got {', '.join(names) or 'none'})")
        if score not in SCORES:
            raise UpdaterError(f"online_improved: score must be one of {', '.join(SCORES)} "
                               f"(got {score!r})")
        if not 0.0 <= law_trust < 1.0:
            raise UpdaterError(f"online_improved: need 0 <= law_trust < 1 (got {law_trust})")
        if not 0.5 <= mixing < 1.0:
            raise UpdaterError(f"online_improved: need 0.5 <= mixing < 1 (got {mixing})")
        rls: dict[str, Any] = {"forgetting": forgetting, "ridge": ridge, "gate": gate}
        built: list[_Expert] = []
        for name in names:
            if name == "bouc-wen+memory":
                from fresco_bridge.updating.physics import PhysicsResidual

                built.append(PhysicsResidual(offline=offline, **rls))
            elif name == "baber-wen":
                from fresco_bridge.updating.degrading import baber_wen_refit

                built.append(baber_wen_refit(offline))
            elif name == "bilinear":
                from fresco_bridge.updating.bilinear import bilinear_refit

                built.append(bilinear_refit(offline))
            elif name in ("reversal+stops", "reversal+memory+stops"):
                from fresco_bridge.updating.play import BranchStopRls

                built.append(BranchStopRls(offline=offline, memory_terms="memory" in name,
                                           **rls))
            else:
                built.append(BranchRls(offline=offline, memory_terms=name != "reversal", **rls))
        self.expert_names = names
        self.experts: list[_Expert] = built
        self.mixing = mixing
        self.gate = gate
        force_scale = float(np.max(np.abs(np.asarray(offline[1], dtype=np.float64))))
        self.scores: FloatArray = np.full(len(built), 1e-4 * force_scale**2)
        """Exponentially weighted mean squared error of each expert on the tested element."""
        self.score = score
        self._free = [e.twin.clone() for e in built]
        """Each expert's free-run copy on the tested element (the free-run score)."""
        self.start_params = calibrate_bilinear(offline[0], offline[1])
        """The offline start: the Bilinear calibrated to the offline database."""
        start = make_model("bilinear", **self.start_params)
        self._start_free = start.clone()
        self.harm = np.zeros(2)
        """Prequential free-run squared error on the tested element so far, per observed step:
        [mixture, offline start] (module docstring, *do no harm*). A running mean, not the sum:
        the same choice at every step (one count divides both), bounded over any run length."""
        self._harm_steps = 0
        self.law_trust = law_trust
        self.trusted: int | None = None
        """Index of the law expert the mixture trusts alone now (``law_trust``), or None."""
        self._laws = [k for k, name in enumerate(names) if name in LAW_EXPERTS]
        self._update_trust()
        self._twin = _MixtureTwin(self, [*(e.twin for e in built), start])
        self._last_update = 0.0

    def _update_trust(self) -> None:
        """Trust the law expert whose whole-history rms misfit is the smallest relative to its
        force scale, if at most ``law_trust`` (module docstring); else none."""
        best, self.trusted = self.law_trust, None
        for k in self._laws:
            law = self.experts[k]
            misfit, peak = getattr(law, "misfit", math.inf), getattr(law, "force_peak", 0.0)
            if peak > 0.0 and misfit <= best * peak:
                best, self.trusted = misfit / peak, k

    def mixture_weights(self) -> FloatArray:
        """Current weight of each expert in the mixture (sums to 1)."""
        if self.trusted is not None:
            w = np.zeros(len(self.experts))
            w[self.trusted] = 1.0
            return w
        scores = np.maximum(self.scores, 1e-300)
        w = (scores.min() / scores) ** 2  # 1 / S_k**2 scaled by the best: no 0/0, no overflow
        return np.asarray(w / w.sum(), dtype=np.float64)

    @property
    def serving_start(self) -> bool:
        """Whether the twin serves the offline start now: its prequential free-run error on the
        tested element is not larger than the mixture's (module docstring)."""
        return bool(self.harm[1] <= self.harm[0])

    def served_weights(self) -> FloatArray:
        """Weights of the twin's parts: the experts', then the offline start's."""
        if self.serving_start:
            w = np.zeros(len(self.experts) + 1)
            w[-1] = 1.0
            return w
        return np.append(self.mixture_weights(), 0.0)

    def observe(self, d: float, force: float) -> None:
        d, force = check_measurement(self.name, d, force)
        start = time.perf_counter()
        lam, cap = self.mixing, self.gate**2
        weights = self.mixture_weights()
        mixture_free = mixture_ahead = free_weight = 0.0
        for k, expert in enumerate(self.experts):
            free_force = _free_run(self._free[k], d)
            if not math.isfinite(free_force):  # a diverged copy: it loses, then starts anew
                self._free[k].revert_to_start()
            elif weights[k] > 0.0:
                mixture_free += float(weights[k]) * free_force
                free_weight += float(weights[k])
            squared = 0.0
            if self.score != "one-step":
                squared += _squared_error(force, free_force)
            one_step = expert.predict(d)
            if weights[k] > 0.0:
                mixture_ahead += float(weights[k]) * one_step
            if self.score != "free-run":
                squared += _squared_error(force, one_step)
            score = float(self.scores[k])
            self.scores[k] = min(lam * score + (1.0 - lam) * min(squared, cap * score), _WORST)
            expert.observe(d, force)
        mixture_free = mixture_free / free_weight if free_weight > 0.0 else math.inf
        start_free = _free_run(self._start_free, d)
        serving_start = self.serving_start
        self._harm_steps += 1
        step = np.array((_squared_error(force, mixture_free), _squared_error(force, start_free)))
        self.harm += (step - self.harm) / self._harm_steps
        if self._laws:
            self._update_trust()
        self._last_one_step = abs(force - (start_free if serving_start else mixture_ahead))
        self._last_update = time.perf_counter() - start
