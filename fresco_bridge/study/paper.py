"""``fresco-bridge study paper``: the source paper's case study, both layouts, every case.

A *run* is one (record, specimen, noise, seed). Each run has two phases, each a sweep through
``run_sweep`` (serial, local process pool or a Dask cluster):

1. *prepare*: a noise-free reference run fixes the noise scale (``--noise`` is a percentage of
   the tested damper's peak force in it); a conventional run (paper layout, the paper's
   Bilinear twin) is the offline database, as in the paper (first ``OFFLINE_SAMPLES`` measured
   steps); the calibrated Bilinear is fitted to it;
2. *cases*: every (layout, case) simulated independently, with the run's ``causality``
   (``same-step``, the paper's order, or ``previous-step``: see ``study.simulate``); the fixed
   models of phase 1 learn nothing, so it does not depend on it. With ``integrator =
   "opensees"`` each case runs from OpenSeesPy against a bridge (``study.opensees``); phase 1
   stays in process (noise-free: the same numbers OpenSees gives, to 1e-12).

Scores (``fresco_bridge.indicators``): paper layout against the tested damper's *measured*
force (the paper's Table 3); generalisation layout against the twin's *true* force. MAESD is
against the same layout's ``reference`` case, which shares the run's noise.
"""

from __future__ import annotations

import copy
from collections.abc import Callable, Sequence
from dataclasses import dataclass, replace
from typing import Any

import numpy as np

from fresco_bridge import indicators
from fresco_bridge.integrator import Causality, GroundMotion
from fresco_bridge.lawfit import calibrate_bilinear
from fresco_bridge.study.constants import CASES, INTEGRATORS, LAYOUTS, OFFLINE_SAMPLES
from fresco_bridge.study.opensees import TwinSite, simulate_case_opensees
from fresco_bridge.study.simulate import (
    CaseHistory,
    simulate_case,
    specimen_model,
    specimen_params,
)
from fresco_bridge.sweeps import run_sweep
from fresco_bridge.updating.base import Updater
from fresco_bridge.updating.registry import PAPER_BILINEAR, UPDATERS, make_updater
from fresco_bridge.updating.updaters import FixedModelUpdater, online_lm_options
from sim_actuator.models import make_model

__all__ = [
    "FIXED_CASES",
    "Prepared",
    "RunSpec",
    "StudyError",
    "available_cases",
    "case_metrics",
    "make_case_twin_site",
    "make_case_updater",
    "run_study",
]

FIXED_CASES = ("reference", "conventional_paper", "conventional_calibrated")
"""Cases whose twin never learns (a fixed model)."""


class StudyError(ValueError):
    """The study cannot run as asked (unknown case or specimen, unreadable record, …)."""


@dataclass(frozen=True, eq=False)
class RunSpec:
    """One run: a record, a specimen, a noise level and a seed."""

    record: str
    """Label: the record file's name, or ``synthetic-seed<N>``."""
    motion: GroundMotion
    specimen: str
    noise_pct: float
    seed: int
    steps: int | None = None
    ann_iterations: int | None = None
    """LM iteration cap of ``online_ann`` (None: its default, 8; the paper's is 50)."""
    pretrain_iterations: int = 1000
    """LM iterations of the offline pre-training (MATLAB ``trainlm``'s default epochs)."""
    ann_options: tuple[tuple[str, Any], ...] = ()
    """Further ``online_ann`` options (``rtol``, …); none: its defaults."""
    causality: Causality = "same-step"
    """What the twin's step i may learn from: the tested damper's step i (``same-step``, the
    paper's order) or only through step i - 1 (``previous-step``, a twin served live)."""
    integrator: str = "builtin"
    """``builtin`` (the in-process explicit Newmark) or ``opensees`` (OpenSeesPy, both dampers
    served by a bridge: ``study.opensees``)."""

    def online_ann_options(self) -> dict[str, Any]:
        """The options ``online_ann`` gets in this run (``--ann-option`` wins over the cap)."""
        options: dict[str, Any] = {}
        if self.ann_iterations is not None:
            options["max_iterations"] = self.ann_iterations
        options.update(self.ann_options)
        return options

    @property
    def label(self) -> str:
        noise = f"{self.noise_pct:g}".replace(".", "p")
        order = "" if self.causality == "same-step" else f"_{self.causality}"
        order += "" if self.integrator == "builtin" else f"_{self.integrator}"
        return (f"{self.record.removesuffix('.AT2')}_{self.specimen}_noise{noise}_seed{self.seed}"
                f"{order}")  # fmt: skip


@dataclass(frozen=True, eq=False)
class Prepared:
    """What phase 1 gives every case of a run."""

    run: RunSpec
    noise_std: float
    offline_disp: np.ndarray[Any, np.dtype[np.float64]]
    offline_force: np.ndarray[Any, np.dtype[np.float64]]
    calibrated: dict[str, float]
    ann: Any = None
    """The network pre-trained on the offline database (offline_ann, online_ann), if needed."""


def available_cases() -> tuple[str, ...]:
    """Every case: the fixed ones and one per learning updater of the registry."""
    return tuple(c for c in CASES if c in FIXED_CASES or c in UPDATERS)


def make_case_updater(case: str, prepared: Prepared) -> Updater:
    """The updater (and so the twin) of one case."""
    if case == "reference":
        return FixedModelUpdater("reference", specimen_model(prepared.run.specimen))
    if case == "conventional_paper":
        return FixedModelUpdater(case, make_model("bilinear", **PAPER_BILINEAR))
    if case == "conventional_calibrated":
        return FixedModelUpdater(case, make_model("bilinear", **prepared.calibrated))
    if case not in available_cases():
        raise StudyError(f"case {case!r} is not available; available: "
                         f"{', '.join(available_cases())}")  # fmt: skip
    if case == "online_improved":
        return make_updater(case, offline=(prepared.offline_disp, prepared.offline_force))
    if case == "online_ukf":
        return make_updater(case)  # the paper's start values and covariances
    # offline_ann, online_ann (the paper's method, the registry's defaults). Each
    # case gets its own copy: online_ann trains its network in place.
    options = prepared.run.online_ann_options() if case == "online_ann" else {}
    return make_updater(case, model=copy.deepcopy(prepared.ann), seed=prepared.run.seed,
                        **options)


def make_case_twin_site(case: str, prepared: Prepared) -> TwinSite:
    """The twin of one case as an updatable site (``make_case_updater``'s twin, configured)."""
    if case == "reference":
        kind, params = specimen_params(prepared.run.specimen)
        return TwinSite("none", {"model": kind, "params": params})
    if case == "conventional_paper":
        return TwinSite("none", {"model": "bilinear", "params": dict(PAPER_BILINEAR)})
    if case == "conventional_calibrated":
        return TwinSite("none", {"model": "bilinear", "params": dict(prepared.calibrated)})
    if case == "online_improved":
        return TwinSite(case, offline=(prepared.offline_disp, prepared.offline_force))
    if case == "online_ukf":
        return TwinSite(case)
    options = prepared.run.online_ann_options() if case == "online_ann" else {}
    return TwinSite(case, {"seed": prepared.run.seed, **options}, model=prepared.ann)


def _prepare(job: tuple[RunSpec, tuple[str, ...]]) -> Prepared:
    """Phase 1 of a run (a sweep task): noise scale, offline database, calibrated Bilinear and,
    when an ANN case is asked for, the network pre-trained on the offline database."""
    run, cases = job
    clean = simulate_case("paper", run.specimen,
                          FixedModelUpdater("reference", specimen_model(run.specimen)),
                          run.motion, steps=run.steps)  # fmt: skip
    noise_std = run.noise_pct / 100.0 * float(np.max(np.abs(clean.tested_force)))
    conventional = simulate_case(
        "paper", run.specimen,
        FixedModelUpdater("conventional_paper", make_model("bilinear", **PAPER_BILINEAR)),
        run.motion, noise_std=noise_std, noise_seed=run.seed, steps=run.steps,
    )  # fmt: skip
    disp = conventional.tested_drift[:OFFLINE_SAMPLES].copy()
    force = conventional.tested_force[:OFFLINE_SAMPLES].copy()
    ann = None
    if {"offline_ann", "online_ann"} & set(cases):
        from fresco_bridge.updating.ann import PRETRAIN_LM, pretrain

        ann = pretrain(disp, force, seed=run.seed, source=f"conventional run {run.label}",
                       options=replace(PRETRAIN_LM, max_iterations=run.pretrain_iterations))
    return Prepared(run, noise_std, disp, force, calibrate_bilinear(disp, force), ann)


@dataclass(frozen=True)
class _CaseTask:
    prepared: Prepared
    layout: str
    case: str


def _run_case(task: _CaseTask) -> CaseHistory:
    """Phase 2 (a sweep task): one (layout, case) of a run."""
    run = task.prepared.run
    updater = make_case_updater(task.case, task.prepared)
    if run.integrator == "opensees":
        return simulate_case_opensees(task.layout, run.specimen,
                                      make_case_twin_site(task.case, task.prepared), run.motion,
                                      steps=run.steps, causality=run.causality,
                                      ahead_updater=updater,
                                      noise_std=task.prepared.noise_std,
                                      noise_seed=run.seed)  # fmt: skip
    return simulate_case(task.layout, run.specimen, updater, run.motion,
                         noise_std=task.prepared.noise_std, noise_seed=run.seed,
                         steps=run.steps, causality=run.causality)  # fmt: skip


def case_metrics(layout: str, history: CaseHistory, reference: CaseHistory) -> dict[str, Any]:
    """The issue's keys for one case: Table 3 values, MAESD, one-step RMSE, update times; and
    RMSETH, the RMS error of the twin's force over the time history (beside MAETH)."""
    truth = history.tested_force if layout == "paper" else history.twin_true_force
    peaks = indicators.peak_values(truth, history.twin_force)
    update_ms = history.update_seconds * 1000.0
    update_time_ms = {  # none when not measured per step (an OpenSees-driven case)
        "median": float(np.median(update_ms)) if update_ms.size else None,
        "p99": float(np.percentile(update_ms, 99)) if update_ms.size else None,
    }
    return {
        "pv_es_pos": peaks.pv_es_pos,
        "pv_es_neg": peaks.pv_es_neg,
        "pv_ums_pos": peaks.pv_ums_pos,
        "pv_ums_neg": peaks.pv_ums_neg,
        "aepv_pos": peaks.aepv_pos,
        "aepv_neg": peaks.aepv_neg,
        "maeth": indicators.maeth(truth, history.twin_force),
        "rmseth": indicators.rmseth(truth, history.twin_force),
        "maesd": indicators.maesd(history.floor_displacement, reference.floor_displacement),
        "one_step_rmse": indicators.one_step_rmse(truth, history.twin_ahead_force),
        "update_time_ms": update_time_ms,
    }


def run_study(
    runs: Sequence[RunSpec],
    cases: Sequence[str],
    *,
    workers: int | None = None,
    scheduler: str | None = None,
    progress: Callable[[int, int], None] | None = None,
) -> list[tuple[dict[str, Any], dict[str, dict[str, CaseHistory]]]]:
    """Every run's result document and histories (``histories[layout][case]``)."""
    unknown = [c for c in cases if c not in available_cases()]
    if unknown:
        raise StudyError(f"unknown or unavailable case(s) {', '.join(unknown)}; available: "
                         f"{', '.join(available_cases())}")  # fmt: skip
    for run in runs:
        if run.integrator not in INTEGRATORS:
            raise StudyError(f"unknown integrator {run.integrator!r}; known: "
                             f"{', '.join(INTEGRATORS)}")  # fmt: skip
    wanted = ["reference", *[c for c in cases if c != "reference"]]
    jobs = [(run, tuple(wanted)) for run in runs]
    prepared = run_sweep(_prepare, jobs, workers=workers, scheduler=scheduler)
    tasks = [_CaseTask(p, layout, case) for p in prepared for layout in LAYOUTS for case in wanted]
    histories = run_sweep(_run_case, tasks, workers=workers, scheduler=scheduler,
                          progress=progress)  # fmt: skip
    results = []
    by_run: dict[int, dict[str, dict[str, CaseHistory]]] = {}
    for task, history in zip(tasks, histories, strict=True):
        by_run.setdefault(id(task.prepared), {}).setdefault(task.layout, {})[task.case] = history
    for p in prepared:
        per_layout = by_run[id(p)]
        ann = p.run.online_ann_options()
        ann_lm = online_lm_options(max_iterations=ann.get("max_iterations"),
                                   single_precision_hessian=ann.get("single_precision_hessian"))
        document: dict[str, Any] = {
            "study": "paper",
            "record": p.run.record,
            "record_pga_m_s2": p.run.motion.pga_m_s2,
            "specimen": p.run.specimen,
            "noise_pct": p.run.noise_pct,
            "noise_std_kN": p.noise_std,
            "seed": p.run.seed,
            "causality": p.run.causality,
            "integrator": p.run.integrator,
            "steps": int(per_layout["paper"]["reference"].tested_drift.size),
            "offline": {"samples": int(p.offline_disp.size), "calibrated_bilinear": p.calibrated,
                        "paper_bilinear": dict(PAPER_BILINEAR),
                        "pretrain_iterations": p.run.pretrain_iterations},
            "online_ann_max_iterations": ann_lm.max_iterations,
            "online_ann_single_precision_hessian": ann_lm.single_precision_hessian,
            "online_ann_options": dict(p.run.ann_options),
            "layouts": {
                layout: {
                    "scored_against": "tested damper's measured force" if layout == "paper"
                    else "twin's true force",
                    "cases": {
                        case: case_metrics(layout, per_layout[layout][case],
                                           per_layout[layout]["reference"])
                        for case in wanted
                    },
                }
                for layout in LAYOUTS
            },
        }
        results.append((document, per_layout))
    return results
