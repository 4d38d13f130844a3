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
``1 / S_k**2`` (normalised), or ``1 / (S_k * H_k)`` with ``shadow=True``, ``H_k`` its error on a
stretch of the tested element's history whose state matches the twin's (``shadow``). The twin's
force is the weighted sum of the experts' twins, each on its own memory.

*Law trust* (``law_trust``): a law expert whose rms misfit over the whole history it was fitted
to is at most ``law_trust`` × that history's peak |force| takes all the weight. Why: the scores
rank experts on the *recent* past, where a forgetting basis fits as well as a law yet transfers
worse to a twin in another state; one parameter set explaining two whole histories is evidence
the law generalises. ``law_trust=0`` is the plain mixture. The switch changes only at a refit.

Experts (``experts=``; :data:`EXPERTS` by default, :data:`OPTIONAL_EXPERTS` on request):
``reversal`` (the basis alone), ``reversal+memory`` (plus previous-branch and envelope terms),
``bouc-wen+memory`` (a fitted Bouc-Wen law plus the memory basis on its residual, ``physics``),
``reversal+stops`` (plus stop operators scheduled on the element's own plastic deformation,
``play``), ``baber-wen`` (a degrading law refitted on the tested element's whole history,
``degrading``), ``reversal+memory+hinges`` (force hinges, ``branch``). The bases learn by
exponentially weighted ridge least squares with Huber gating (``forgetting``, ``ridge``,
``gate``); ``baber-wen`` by periodic refits, which cost far more than an ordinary step and grow
with the history: served live, the updater belongs beside the event loop. Figures, the choice
of the defaults and what fails: ``BENCHMARKS.md``, "Online updating".
"""

from __future__ import annotations

import math
import time
from typing import Any, Protocol

import numpy as np
import numpy.typing as npt

from fresco_bridge.updating.base import OwnsTwin, UpdaterError, check_measurement
from fresco_bridge.updating.branch import BranchMemory, BranchRls, ReversalBasis
from fresco_bridge.updating.shadow import ShadowScorer, stepper
from sim_actuator.models.base import HysteresisModel, trial_input_error

__all__ = ["EXPERTS", "LAW_TRUST", "SCORES", "BranchMemory", "OnlineImproved", "ReversalBasis"]

FloatArray = npt.NDArray[np.float64]

EXPERTS = ("reversal", "reversal+memory", "bouc-wen+memory", "reversal+stops", "baber-wen")
"""The experts ``online_improved`` combines by default."""

OPTIONAL_EXPERTS = ("reversal+memory+stops", "reversal+memory+hinges")
"""Experts that can be asked for by name but are not in the default mixture."""

LAW_EXPERTS = ("baber-wen",)
"""Experts that are a law refitted on the whole history (``refit.RefitUpdater``): ``law_trust``
applies to them."""

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
    def source_twin(self) -> HysteresisModel: ...
    @property
    def twin(self) -> HysteresisModel: ...


class _MixtureTwin:
    """The weighted sum of the experts' twins (material semantics: each keeps its own)."""

    name = "online_improved"

    def __init__(self, owner: OnlineImproved, parts: list[HysteresisModel],
                 record: bool = True) -> None:
        """``record``: tell the owner each commit (the twin's history for shadow scoring);
        clones do not."""
        self._owner = owner
        self._parts = parts
        self._record = record
        self._committed = (0.0, 0.0)
        self._trial = self._committed

    def set_trial(self, d: float) -> tuple[float, float]:
        if not math.isfinite(d):
            raise trial_input_error(self.name, d)
        w = self._owner.mixture_weights()
        force = tangent = 0.0
        for weight, part in zip(w.tolist(), self._parts, strict=True):
            f, k = part.set_trial(d)
            force += weight * f
            tangent += weight * k
        self._trial = (d, force)
        return force, tangent

    def commit(self) -> None:
        for part in self._parts:
            part.commit()
        self._committed = self._trial
        if self._record and self._owner.shadow is not None:
            self._owner.shadow.twin_committed(self._committed[0])

    def revert_to_last_commit(self) -> None:
        for part in self._parts:
            part.revert_to_last_commit()
        self._trial = self._committed

    def revert_to_start(self) -> None:
        for part in self._parts:
            part.revert_to_start()
        self._committed = self._trial = (0.0, 0.0)
        if self._record and self._owner.shadow is not None:
            self._owner.shadow.twin_reset()

    @property
    def initial_tangent(self) -> float:
        w = self._owner.mixture_weights()
        return float(sum(weight * part.initial_tangent
                         for weight, part in zip(w.tolist(), self._parts, strict=True)))

    @property
    def committed(self) -> tuple[float, float]:
        return self._committed

    def clone(self) -> HysteresisModel:
        twin = _MixtureTwin(self._owner, [part.clone() for part in self._parts], record=False)
        twin._committed, twin._trial = self._committed, self._trial
        return twin


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
        shadow: bool = False,
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
            elif name in ("reversal+stops", "reversal+memory+stops"):
                from fresco_bridge.updating.play import BranchStopRls

                built.append(BranchStopRls(offline=offline, memory_terms="memory" in name,
                                           **rls))
            else:
                built.append(BranchRls(offline=offline, memory_terms=name != "reversal",
                                       hinges=name.endswith("hinges"), **rls))
        self.expert_names = names
        self.experts: list[_Expert] = built
        self.mixing = mixing
        self.gate = gate
        force_scale = float(np.max(np.abs(np.asarray(offline[1], dtype=np.float64))))
        self.scores: FloatArray = np.full(len(built), 1e-4 * force_scale**2)
        """Exponentially weighted mean squared error of each expert on the tested element."""
        self.score = score
        self._shadows = [stepper(e.twin.clone()) for e in built]
        self.shadow = ShadowScorer(len(built)) if shadow else None
        """Shadow scoring (``shadow.py``), or None."""
        self.law_trust = law_trust
        self.trusted: int | None = None
        """Index of the law expert the mixture trusts alone now (``law_trust``), or None."""
        self._laws = [k for k, name in enumerate(names) if name in LAW_EXPERTS]
        self._update_trust()
        self._twin = _MixtureTwin(self, [e.twin for e in built])
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
        """Current weight of each expert (sums to 1)."""
        if self.trusted is not None:
            w = np.zeros(len(self.experts))
            w[self.trusted] = 1.0
            return w
        scores = np.maximum(self.scores, 1e-300)
        shadow = None if self.shadow is None else self.shadow.scores
        w = 1.0 / scores**2 if shadow is None else 1.0 / (scores * np.maximum(shadow, 1e-300))
        return np.asarray(w / w.sum(), dtype=np.float64)

    def observe(self, d: float, force: float) -> None:
        d, force = check_measurement(self.name, d, force)
        start = time.perf_counter()
        lam, cap = self.mixing, self.gate**2
        weights = self.mixture_weights() if self.score != "free-run" else None
        predicted = 0.0
        if self.shadow is not None:
            self.shadow.before_step([expert.source_twin() for expert in self.experts])
        for k, expert in enumerate(self.experts):
            squared = 0.0
            if self.score != "one-step":
                free = force - self._shadows[k](d)
                squared += free * free
            if weights is not None:
                one_step = expert.predict(d)
                predicted += float(weights[k]) * one_step
                one = force - one_step
                squared += one * one
            score = float(self.scores[k])
            self.scores[k] = lam * score + (1.0 - lam) * min(squared, cap * score)
            expert.observe(d, force)
        if self._laws:
            self._update_trust()
        if self.shadow is not None:
            self.shadow.after_step(d, force)
        self._last_one_step = None if weights is None else abs(force - predicted)
        self._last_update = time.perf_counter() - start
