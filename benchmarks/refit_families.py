"""Law families for ``updating.refit`` tried on the design records (issue 9, BENCHMARKS.md
"updating part 8a"), as ``benchmarks.updater_design --factory`` functions.

``chaboche`` (``sim_actuator.models.chaboche``): 14 free parameters, the Voce and excursion
changes of the elastic range as fractions of fy (``qr``, ``qe`` in [-0.999, 1], their sum kept
above -0.98 and the softening rates below the law's limit, so every point of the box is a
valid law), bounds and scales from the data (first-loading stiffness k, peak force, k/peak).
Why it is outside both specimens: the law's docstring. Factories:

* ``chaboche_online``: ``RefitUpdater`` on the law alone (options: ``every``, ``stride``,
  ``max_nfev``, ``offline_weight``, ``warmup``);
* ``chaboche_mixture``: the default ``online_improved`` (design E) with the refitted law as a
  fifth expert, scored like the others (same options, for the law);
* ``chaboche_residual``: the refitted law plus E's memory basis on its residual (the
  ``bouc-wen+memory`` expert with the law refitted online), ``chaboche_residual_mixture``: that
  as E's fifth expert.

``baber_wen_residual_mixture``: design H with its law expert replaced by the law plus the memory
basis on its residual (BENCHMARKS.md "updating part 16", negative).

``excursion_bw`` (``sim_actuator.models.excursion_bw``, BENCHMARKS.md "updating part 8c"): Bouc-Wen
with the exponent scheduled on the previous plastic excursion, isotropic hardening on the range
and the transition origin ``c`` (0: beta = gamma); 9 free parameters, ``n_min`` clipped to
``n0``; fitted through the JIT drive. Capacity only (it failed there).

``python -m benchmarks.refit_families <specimen> <seed> [chaboche|excursion-bw|baber-wen]
[kt|soft|pulse|softpulse]``: step-1 capacity (``capacity``; ``baber-wen`` is
``online_improved``'s law expert, BENCHMARKS.md "updating part 16").
``taskset -c 0 python -m benchmarks.updater_design --workers 1 --factory
benchmarks.refit_families:chaboche_online [--only menegotto-pinto]``.
"""

from __future__ import annotations

import math
import time
from collections.abc import Mapping
from typing import Any

import numpy as np
import numpy.typing as npt

from fresco_bridge.updating.base import OwnsTwin
from fresco_bridge.updating.branch import BranchRls, initial_stiffness
from fresco_bridge.updating.degrading import BABER_WEN, REFIT_SCHEDULE, baber_wen_refit
from fresco_bridge.updating.improved import EXPERTS, OnlineImproved, _MixtureTwin
from fresco_bridge.updating.physics import _PhysicsTwin, data_scales
from fresco_bridge.updating.refit import FitSpace, LawFamily, RefitUpdater, law_forces
from fresco_bridge.updating.shadow import stepper
from sim_actuator.models.base import HysteresisModel
from sim_actuator.models.chaboche import Chaboche
from sim_actuator.models.excursion_bw import ExcursionBoucWen, drive

FloatArray = npt.NDArray[np.float64]

CHABOCHE_FREE = ("k0", "fy", "C1", "gamma1", "C2", "gamma2", "C3", "gamma3", "kh", "qr", "b",
                 "hm", "qe", "be")  # fmt: skip


def chaboche_space(disp: FloatArray, force: FloatArray,
                   free: tuple[str, ...] = CHABOCHE_FREE) -> FitSpace:  # fmt: skip
    """Start, bounds, scales (see the module docstring)."""
    k = initial_stiffness(disp, force)
    fp = float(np.max(np.abs(force)))
    dref = fp / k
    table = {  # start, lower, upper, scale
        "k0": (k, 0.3 * k, 3 * k, k),
        "fy": (0.7 * fp, 0.05 * fp, 2 * fp, fp),
        "C1": (0.3 * k, 0.0, 5 * k, k),
        "gamma1": (1.0 / dref, 0.05 / dref, 50 / dref, 1 / dref),
        "C2": (0.02 * k, 0.0, 1 * k, 0.1 * k),
        "gamma2": (0.1 / dref, 0.001 / dref, 5 / dref, 0.1 / dref),
        "C3": (0.005 * k, 0.0, 0.5 * k, 0.01 * k),
        "gamma3": (0.01 / dref, 0.0001 / dref, 1 / dref, 0.01 / dref),
        "kh": (0.02 * k, 0.0, 0.5 * k, 0.01 * k),
        "qr": (-0.3, -0.999, 1.0, 0.1),
        "b": (0.2 / dref, 0.005 / dref, 10 / dref, 0.1 / dref),
        "hm": (0.01 * k, 0.0, 0.5 * k, 0.01 * k),
        "qe": (-0.3, -0.999, 1.0, 0.1),
        "be": (1.0 / dref, 0.01 / dref, 50 / dref, 0.1 / dref),
    }
    rows = [table[name] for name in free]
    return FitSpace(*(tuple(row[i] for row in rows) for i in range(4)))


def chaboche_law(free: Mapping[str, float]) -> Chaboche:
    """The law from the fit's parameters (``qr``, ``qe``: fractions of fy, kept valid)."""
    p = dict(free)
    qr, qe = p.pop("qr", 0.0), p.pop("qe", 0.0)
    negative = min(qr, 0.0) + min(qe, 0.0)
    if negative < -0.98:
        qr, qe = (x * -0.98 / negative if x < 0.0 else x for x in (qr, qe))
    p["Q"], p["Qe"] = qr * p["fy"], qe * p["fy"]
    limit = 0.95 * p["k0"]  # |Q| b + |Qe| be below k0, split evenly
    if p["Q"] < 0.0:
        p["b"] = min(p.get("b", 1.0), 0.5 * limit / -p["Q"])
    if p["Qe"] < 0.0:
        p["be"] = min(p.get("be", 1.0), 0.5 * limit / -p["Qe"])
    return Chaboche(**p)


CHABOCHE = LawFamily("chaboche", CHABOCHE_FREE, chaboche_law, chaboche_space)


EXCURSION_FREE = ("k0", "fy", "alpha", "n0", "n_min", "xi0", "a", "p", "c")


def excursion_space(disp: FloatArray, force: FloatArray) -> FitSpace:
    """Start, bounds, scales from the first-loading stiffness and the peak force."""
    k, fp = data_scales(disp, force, "excursion Bouc-Wen")
    return FitSpace(start=(k, fp, 0.03, 10.0, 1.5, 0.5, 0.03, 0.8, 0.8),
                    lower=(0.25 * k, 0.15 * fp, 0.0, 1.0, 0.5, 0.01, 0.0, 0.1, 0.0),
                    upper=(4.0 * k, 3.0 * fp, 0.5, 60.0, 60.0, 100.0, 1.0, 2.0, 1.0),
                    scale=(k, fp, 0.01, 1.0, 0.3, 0.1, 0.01, 0.1, 0.1))  # fmt: skip


def _excursion_params(free: Mapping[str, float]) -> dict[str, float]:
    return {**free, "n_min": min(free["n_min"], free["n0"])}


def excursion_law(free: Mapping[str, float]) -> ExcursionBoucWen:
    """The law from the fit's parameters (``n_min`` clipped to ``n0``)."""
    return ExcursionBoucWen(**_excursion_params(free))


def _excursion_forces(free: Mapping[str, float], disp: FloatArray) -> FloatArray:
    p = _excursion_params(free)
    return drive(np.array([p[name] for name in EXCURSION_FREE]), disp)


EXCURSION_BW = LawFamily("excursion-bouc-wen", EXCURSION_FREE, excursion_law, excursion_space,
                         forces=_excursion_forces)  # fmt: skip


def chaboche_online(disp: FloatArray, force: FloatArray, **options: Any) -> RefitUpdater:
    """The refitted Chaboche law alone."""
    return RefitUpdater(CHABOCHE, offline=(disp, force), name="chaboche_refit", **options)


def chaboche_mixture(disp: FloatArray, force: FloatArray, **options: Any) -> OnlineImproved:
    """Design E with the refitted Chaboche law as a fifth expert."""
    return _with_expert(OnlineImproved(offline=(disp, force)), "chaboche-refit",
                        chaboche_online(disp, force, **options))


def _with_expert(mixture: OnlineImproved, name: str, expert: Any) -> OnlineImproved:
    """``mixture`` with one more expert, scored like the others from its first step."""
    mixture.experts.append(expert)
    mixture.expert_names = (*mixture.expert_names, name)
    mixture.scores = np.append(mixture.scores, mixture.scores[0])
    mixture._shadows.append(stepper(expert.twin.clone()))
    mixture._twin = _MixtureTwin(mixture, [e.twin for e in mixture.experts])
    return mixture


class RefitResidual(OwnsTwin):
    """The refitted law plus design E's memory basis learning its residual online (the
    ``bouc-wen+memory`` expert of ``physics`` with the law refitted instead of fixed)."""

    name = "chaboche+memory"

    def __init__(self, family: LawFamily, *, offline: tuple[FloatArray, FloatArray],
                 name: str = "chaboche+memory", **options: Any) -> None:  # fmt: skip
        disp, force = offline
        self.name = name
        self.law = RefitUpdater(family, offline=offline, name=self.name, **options)
        law_force = law_forces(family.build(self.law.parameters), disp)
        self.residual = BranchRls(offline=(disp, force - law_force), memory_terms=True,
                                  force_scale=float(np.max(np.abs(force))),
                                  stiffness=initial_stiffness(disp, force), shrink=True)
        self._twin = _PhysicsTwin(self.law.twin, self.residual.twin)
        self._last_update = 0.0

    @property
    def misfit(self) -> float:
        """The law's whole-history misfit (``online_improved``'s law trust reads it)."""
        return self.law.misfit

    @property
    def force_peak(self) -> float:
        return self.law.force_peak

    def source_twin(self) -> HysteresisModel:
        return _PhysicsTwin(self.law.source_twin(), self.residual.source_twin())

    def predict(self, d: float) -> float:
        return self.law.predict(d) + self.residual.predict(d)

    def observe(self, d: float, force: float) -> None:
        start = time.perf_counter()
        f_law = self.law.predict(d)
        self.law.observe(d, force)
        self.residual.observe(d, force - f_law)
        self._last_update = time.perf_counter() - start


def chaboche_residual(disp: FloatArray, force: FloatArray, **options: Any) -> RefitResidual:
    """The refitted Chaboche law plus the memory basis on its residual."""
    return RefitResidual(CHABOCHE, offline=(disp, force), **options)


def chaboche_residual_mixture(disp: FloatArray, force: FloatArray,
                              **options: Any) -> OnlineImproved:  # fmt: skip
    """Design E with ``chaboche_residual`` as a fifth expert."""
    return _with_expert(OnlineImproved(offline=(disp, force)), "chaboche+memory",
                        chaboche_residual(disp, force, **options))


def _with_law_expert(disp: FloatArray, force: FloatArray, name: str, expert: Any,
                     options: dict[str, Any]) -> OnlineImproved:  # fmt: skip
    """Design H (``options`` to ``OnlineImproved``) with ``expert`` in place of its ``baber-wen``
    law expert, law trust applying to it (its ``misfit`` and ``force_peak``)."""
    others = tuple(e for e in EXPERTS if e != "baber-wen")
    mixture = _with_expert(OnlineImproved(offline=(disp, force), experts=others, **options),
                           name, expert)  # fmt: skip
    mixture._laws = [len(mixture.experts) - 1]
    mixture._update_trust()
    return mixture


def baber_wen_residual_mixture(disp: FloatArray, force: FloatArray,
                               **options: Any) -> OnlineImproved:  # fmt: skip
    """Design H with its ``baber-wen`` expert replaced by that law plus the memory basis learning
    its residual every step, law trust applying to the pair (BENCHMARKS.md "updating part 16":
    the residual adapts within the first strong pulse, where the law refits too rarely)."""
    expert = RefitResidual(BABER_WEN, offline=(disp, force), name="baber-wen+memory",
                           **REFIT_SCHEDULE)
    return _with_law_expert(disp, force, expert.name, expert, options)


def baber_wen_schedule_mixture(disp: FloatArray, force: FloatArray,
                               **options: Any) -> OnlineImproved:  # fmt: skip
    """Design H with its ``baber-wen`` expert on another refit schedule: ``every``, ``max_nfev``,
    ``offline_weight``, ``warmup``, ``stride`` go to the law (``degrading.REFIT_SCHEDULE``
    otherwise), the rest to ``OnlineImproved`` (BENCHMARKS.md "updating part 16")."""
    keys = ("every", "max_nfev", "offline_weight", "warmup", "stride", "offline_nfev")
    schedule = {k: options.pop(k) for k in keys if k in options}
    return _with_law_expert(disp, force, "baber-wen", baber_wen_refit((disp, force), **schedule),
                            options)


def capacity(specimen: str, seed: int, starts: int = 6, family: str = "chaboche",
             record: str = "kt") -> dict[str, dict[str, float]]:  # fmt: skip
    """Step 1 of the spike: the family fitted in hindsight (best of ``starts``; Chaboche on every
    3rd sample plus reversals, the others on every sample) to (a) the tested element's whole
    history of the reference case (a ``updater_design`` record of family ``record``, 3 m/s²,
    20 s, ``seed``, 0 % noise), (b) that and the offline database together (the design runs'
    first 2500 steps of a conventional run: everything an online fit could ever see), (c) the
    twin's own whole history (the family's bound: not available online); then the twin
    free-runs in closed loop with those parameters; MAETH against the twin's true force. Also
    (d) the offline database alone: what an online fit has before the test starts."""
    from benchmarks.updater_design import _conventional, design_motion
    from fresco_bridge import indicators
    from fresco_bridge.study.constants import OFFLINE_SAMPLES
    from fresco_bridge.study.simulate import simulate_case, specimen_model
    from fresco_bridge.updating.refit import compress, fit_law
    from fresco_bridge.updating.updaters import FixedModelUpdater

    families = {"chaboche": CHABOCHE, "excursion-bw": EXCURSION_BW, "baber-wen": BABER_WEN}
    law_family = families[family]
    motion = design_motion(record, seed)
    ref = simulate_case("generalisation", specimen,
                        FixedModelUpdater("reference", specimen_model(specimen)), motion)
    conv = _conventional(specimen, motion, 0.0)
    offline = (conv.tested_drift[:OFFLINE_SAMPLES], conv.tested_force[:OFFLINE_SAMPLES])
    tested = (ref.tested_drift, ref.tested_force)
    out = {}
    for label, data in (("offline", [offline]), ("tested", [tested]),
                        ("tested+offline", [tested, offline]),
                        ("twin", [(ref.twin_drift, ref.twin_true_force)])):  # fmt: skip
        d, f = data[0]
        space = law_family.space(d, f)
        histories = []
        for hd, hf in data:
            keep = compress(hd, 3 if family == "chaboche" else 1)
            histories.append((hd[keep], hf[keep], 1.0))
        rng = np.random.default_rng(0)
        lower, upper = np.array(space.lower), np.array(space.upper)
        best: tuple[float, FloatArray] | None = None
        for i in range(starts):
            x0 = np.array(space.start)
            if i and family == "chaboche":
                x0 = np.clip(x0 * np.exp(rng.normal(0.0, 1.0, x0.size)), lower, upper)
                x0[CHABOCHE_FREE.index("qr")] = -rng.uniform(0.3, 0.9)
                x0[CHABOCHE_FREE.index("qe")] = -rng.uniform(0.1, 0.6)
            elif i:
                x0 = np.clip(x0 * np.exp(rng.normal(0.0, 0.5, x0.size)), lower, upper)
                if family == "excursion-bw":
                    x0[EXCURSION_FREE.index("c")] = rng.uniform(0.0, 1.0)
            x = fit_law(law_family, histories, space, start=x0, max_nfev=200)
            model = law_family.build(law_family.params(x))
            sq = sum(float(np.sum((law_forces(model.clone(), hd) - hf) ** 2)) for hd, hf in data)
            rms = math.sqrt(sq / sum(hd.size for hd, _ in data))
            if best is None or rms < best[0]:
                best = (rms, x)
        assert best is not None
        law = law_family.build(law_family.params(best[1]))
        fit_max = max(float(np.max(np.abs(law_forces(law.clone(), hd) - hf))) for hd, hf in data)
        run = simulate_case("generalisation", specimen, FixedModelUpdater(family, law), motion)
        err = np.abs(run.twin_true_force - run.twin_force)
        out[label] = {"fit_rms": best[0], "fit_max": fit_max,
                      "maeth": indicators.maeth(run.twin_true_force, run.twin_force),
                      "worst_step": float(np.argmax(err))}
    return out


if __name__ == "__main__":
    import sys

    kind = sys.argv[3] if len(sys.argv) > 3 else "chaboche"
    record = sys.argv[4] if len(sys.argv) > 4 else "kt"
    rows = capacity(sys.argv[1], int(sys.argv[2]), family=kind, record=record)
    for name, row in rows.items():
        print(sys.argv[1], record, sys.argv[2], kind, name,
              {k: round(v, 3) for k, v in row.items()})
