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
  fifth expert, scored like the others (same options, for the law).

``taskset -c 0 python -m benchmarks.updater_design --workers 1 --factory
benchmarks.refit_families:chaboche_online [--only menegotto-pinto]``.
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

import numpy as np
import numpy.typing as npt

from fresco_bridge.updating.branch import initial_stiffness
from fresco_bridge.updating.improved import OnlineImproved, _MixtureTwin
from fresco_bridge.updating.refit import FitSpace, LawFamily, RefitUpdater
from fresco_bridge.updating.shadow import stepper
from sim_actuator.models.chaboche import Chaboche

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


def chaboche_online(disp: FloatArray, force: FloatArray, **options: Any) -> RefitUpdater:
    """The refitted Chaboche law alone."""
    return RefitUpdater(CHABOCHE, offline=(disp, force), name="chaboche_refit", **options)


def chaboche_mixture(disp: FloatArray, force: FloatArray, **options: Any) -> OnlineImproved:
    """Design E with the refitted Chaboche law as a fifth expert."""
    mixture = OnlineImproved(offline=(disp, force))
    expert = chaboche_online(disp, force, **options)
    mixture.experts.append(expert)
    mixture.expert_names = (*mixture.expert_names, "chaboche-refit")
    mixture.scores = np.append(mixture.scores, mixture.scores[0])
    mixture._shadows.append(stepper(expert.twin.clone()))
    mixture._twin = _MixtureTwin(mixture, [e.twin for e in mixture.experts])
    return mixture
