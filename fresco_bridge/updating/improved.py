"""``online_improved``: experts weighted by how well each reproduces the tested element.

Why a mixture: no single structure measured wins on both study specimens (BENCHMARKS.md, issue 9
candidates). A reversal-coordinate basis (``branch``) is best where the law is far from any
smooth state-variable form; a fitted Bouc-Wen law plus a residual basis (``physics``)
generalises a degrading element's history to the twin through its own state. Which one is
better is visible online without the twin's truth, on the tested element itself, two ways:

* *free run*: a shadow copy of each expert's twin is driven by the tested element's
  displacement and never sees its force (exactly the twin's situation: its own predicted
  forces are its memory), and is compared with the measured force;
* *one step*: each expert's prediction of the tested force from the tested element's measured
  memory, before it learns from the step.

``score="both"`` (default) adds the two squared errors; ``S_k`` is their exponentially weighted
mean (factor ``mixing`` per step, each step's value clipped at ``gate**2 * S_k`` so one
load-cell spike cannot flip the choice), and expert k weighs ``1 / S_k**2`` (normalised) —
or, with ``shadow=True`` once the shadow scores exist, ``1 / (S_k * H_k)``, ``H_k``
the expert's error on a stored stretch of the tested element's history whose state matches the
twin's (``shadow``: the score on the recent past ranks experts as their twins would not when
the twin is in another state; BENCHMARKS.md, issue 9 part 7). Why
both: the one-step error alone is flattered by the measured reversal force (a Bouc-Wen
residual expert that scored best by it was the worst twin on a replay pair), the free-run
error alone lets an expert's old drift linger (worse on Menegotto-Pinto); BENCHMARKS.md has the
numbers. The twin's force is the weighted sum of the experts' twins, each on its own memory of
the twin's history.

*Law trust* (``law_trust``, default ``LAW_TRUST`` = 0.02): a law expert (``baber-wen``) whose rms
force misfit over the *whole* history it was fitted to (the offline database and everything the
tested element did so far, ``refit.RefitUpdater.misfit``) is at most ``law_trust`` × that
history's peak |force| takes all the weight; otherwise the mixture weighs as above. Why: the
scores rank experts by the tested element's *recent* past, where a forgetting basis fits as well
as the law or better, yet it transfers worse to a twin in another state; one parameter set that
explains two whole histories (offline and online) in different states is evidence that the law
generalises to a third, which no forgetting basis can claim. On the design records
(BENCHMARKS.md, updating part 9b) the law's relative misfit is 0.6–1.4 % on the BWBN specimen
(its family is right; the 1 % noise included) and 6–9 % on Menegotto-Pinto (it is not), but
2.6–2.75 % on the test suite's 200-step Menegotto-Pinto study (a 201-step offline database: a
short history is weak evidence), where 3 % trusted the law and lost to the calibrated Bilinear;
hence 2 %, between the two. The switch can change only at a refit. ``law_trust=0``
is design G's plain mixture. No twin truth enters: only the tested element's measurements.

Experts (``experts=``): ``reversal`` (the basis alone: design B of BENCHMARKS.md),
``reversal+memory`` (plus the previous-branch and envelope terms), ``bouc-wen+memory`` (the
fitted law plus the memory basis on its residual, shrunk towards zero), ``reversal+stops`` (the
basis plus stop operators scheduled on the element's own plastic deformation, ``play``: a twin
that is still virgin keeps what the tested element taught while it was virgin), ``baber-wen``
(a degrading Bouc-Wen law without pinching, refitted online on the tested element's whole
history, the twin running it on its own history: ``degrading``; BENCHMARKS.md, updating part
8b). The default is these five (design G, BENCHMARKS.md updating part 9: on the design records
0.786 of design E's MAETH in geometric mean, worst +1.1 %, a 3000-step replay 6.3 s against
4.1 s). Optional, not in the default mixture: ``reversal+memory+stops``,
``reversal+memory+hinges`` (``reversal+memory`` plus force hinges: the knee where the elastic
trial force reaches a force level, ``branch``). Design F of BENCHMARKS.md (issue 9 part 7) is
design E plus ``reversal+memory+hinges`` with ``shadow=True``: better on the design records,
~1.4× the cost of a replay, so not the default. The basis experts learn by their own
exponentially weighted, ridge-regularised least squares with Huber gating (``forgetting``,
``ridge``, ``gate``; ``branch.WeightedRls``); ``baber-wen`` by periodic refits (``refit``).
Cost per step: the experts' updates and shadows, tenths of a millisecond (with ``shadow``,
plus free runs every 20 steps), and a ``baber-wen`` refit every 300 steps: a spike of ~80 ms
that grows with the history (the fit is over all of it). Served live, it belongs beside the
event loop, not in it.
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
docstring; BENCHMARKS.md, updating part 9b)."""

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
        if self.shadow is not None:
            self.shadow.before_step([expert.source_twin() for expert in self.experts])
        for k, expert in enumerate(self.experts):
            squared = 0.0
            if self.score != "one-step":
                free = force - self._shadows[k](d)
                squared += free * free
            if self.score != "free-run":
                one = force - expert.predict(d)
                squared += one * one
            score = float(self.scores[k])
            self.scores[k] = lam * score + (1.0 - lam) * min(squared, cap * score)
            expert.observe(d, force)
        if self._laws:
            self._update_trust()
        if self.shadow is not None:
            self.shadow.after_step(d, force)
        self._last_update = time.perf_counter() - start
