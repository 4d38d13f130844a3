"""The design records of ``online_improved``: where its candidates are chosen, never on the
evaluation records (the Northridge records of ``study paper``).

Ten numbers per candidate, MAETH of the twin in kN (generalisation layout: against the twin's
*true* force):

* eight closed-loop runs: ``kanai_tajimi(3 m/s², 20 s)`` seeds 1 and 2 x both specimens x
  load-cell noise 0 / 1 % (noise seed 1), with the study's own phase 1 (conventional run ->
  offline database of its first 2500 measured steps, calibrated Bilinear) and ``simulate_case``;
  the calibrated Bilinear's MAETH and the target (10 % of it at 0 %, 20 % at 1 % noise) beside;
* two replay pairs (bwbn, Menegotto-Pinto): ``kanai_tajimi`` seed 7, 30 s, reference run in the
  generalisation layout, first 3000 steps (source = tested d and F, twin = twin d and true F);
  offline database = the first 2500 steps of a conventional run (paper layout, the paper's
  Bilinear) on seed 8, 30 s; ``updating.replay.replay``.

A candidate is the registry's ``online_improved`` with ``--option KEY=VALUE`` pairs, or any
``--factory module:function`` called as ``function(offline_disp, offline_force, **options)``
returning an ``Updater``. ``--baseline`` also runs the default ``online_improved``
(``--baseline-option KEY=VALUE``: with these options) and prints the geometric mean and the
worst of the ratios. ``--seeds 3,4,5,6`` runs the closed-loop set on other record seeds (no
replay pairs); ``--family`` draws them from other synthetic families (``DESIGN_FAMILIES``: soft
soil, an impulsive envelope, both; the default set gave nothing to design against where some
evaluation records were hard). ``--noise 0`` and ``--only bwbn`` restrict the runs.

    taskset -c 0 python -m benchmarks.updater_design [--quick] --workers 1 [--option ...]

Feeds BENCHMARKS.md, "Online updating" (the design figures). ``--quick``: one closed-loop run
(seed 1, bwbn, no noise), a smoke run.
"""

from __future__ import annotations

import argparse
import importlib
import json
import math
import time
from collections.abc import Callable
from concurrent.futures import ProcessPoolExecutor
from typing import Any

import numpy as np

from fresco_bridge import indicators
from fresco_bridge.integrator import GroundMotion, JenningsEnvelope, kanai_tajimi
from fresco_bridge.lawfit import calibrate_bilinear
from fresco_bridge.study.constants import OFFLINE_SAMPLES
from fresco_bridge.study.simulate import simulate_case, specimen_model
from fresco_bridge.updating.base import Updater
from fresco_bridge.updating.cli import parse_option
from fresco_bridge.updating.registry import PAPER_BILINEAR, make_updater
from fresco_bridge.updating.replay import replay
from fresco_bridge.updating.updaters import FixedModelUpdater
from sim_actuator.models import make_model

SPECIMENS = ("bwbn", "menegotto-pinto")
CLOSED_LOOP = tuple((seed, spec, noise) for seed in (1, 2) for spec in SPECIMENS
                    for noise in (0.0, 1.0))  # fmt: skip
REPLAY = tuple(("replay", spec, 0.0) for spec in SPECIMENS)
NOISE_SEED = 1
REPLAY_STEPS = 3000

Factory = Callable[..., Updater]

DESIGN_FAMILIES: dict[str, dict[str, Any]] = {
    "kt": {},
    "soft": {"omega_g": 8.0, "zeta_g": 0.4},
    "pulse": {"envelope": JenningsEnvelope(1.0, 4.0, 0.5)},
    "softpulse": {"omega_g": 8.0, "zeta_g": 0.4, "envelope": JenningsEnvelope(1.0, 4.0, 0.5)},
}
"""Synthetic design record families (module docstring): ``kanai_tajimi`` keyword arguments."""


def design_motion(family: str, seed: int, duration: float = 20.0) -> GroundMotion:
    """A design record: ``family`` of ``DESIGN_FAMILIES``, 3 m/s², ``seed``."""
    return kanai_tajimi(3.0, duration, seed=seed, **DESIGN_FAMILIES[family])


def _label(family: str, seed: int) -> str:
    return f"seed {seed}" if family == "kt" else f"{family} seed {seed}"


def _factory(spec: str | None) -> Factory:
    if spec is None:
        return lambda d, f, **opts: make_updater("online_improved", offline=(d, f), **opts)
    module, _, name = spec.partition(":")
    func: Factory = getattr(importlib.import_module(module), name)
    return func


def _conventional(specimen: str, motion: Any, noise_std: float, layout: str = "paper") -> Any:
    return simulate_case(layout, specimen,
                         FixedModelUpdater("conventional_paper",
                                           make_model("bilinear", **PAPER_BILINEAR)),
                         motion, noise_std=noise_std, noise_seed=NOISE_SEED)  # fmt: skip


def _closed_loop(seed: int, specimen: str, noise_pct: float, factory: Factory,
                 options: dict[str, Any], family: str = "kt") -> dict[str, Any]:
    motion = design_motion(family, seed)
    clean = simulate_case("paper", specimen,
                          FixedModelUpdater("reference", specimen_model(specimen)), motion)
    noise_std = noise_pct / 100.0 * float(np.max(np.abs(clean.tested_force)))
    conv = _conventional(specimen, motion, noise_std)
    disp = conv.tested_drift[:OFFLINE_SAMPLES].copy()
    force = conv.tested_force[:OFFLINE_SAMPLES].copy()
    calibrated = FixedModelUpdater("conventional_calibrated",
                                   make_model("bilinear", **calibrate_bilinear(disp, force)))
    base = simulate_case("generalisation", specimen, calibrated, motion, noise_std=noise_std,
                         noise_seed=NOISE_SEED)  # fmt: skip
    start = time.process_time()
    run = simulate_case("generalisation", specimen, factory(disp, force, **options), motion,
                        noise_std=noise_std, noise_seed=NOISE_SEED)  # fmt: skip
    seconds = time.process_time() - start
    conv_cal = indicators.maeth(base.twin_true_force, base.twin_force)
    maeth = indicators.maeth(run.twin_true_force, run.twin_force)
    err = np.abs(run.twin_true_force - run.twin_force)
    return {"record": _label(family, seed), "specimen": specimen, "noise_pct": noise_pct,
            "conv_cal": conv_cal, "target": (0.1 if noise_pct == 0 else 0.2) * conv_cal,
            "maeth": maeth, "reduction_pct": 100.0 * (1.0 - maeth / conv_cal),
            "worst_step": int(np.argmax(err)), "cpu_s": seconds}  # fmt: skip


def _replay_pair(specimen: str, factory: Factory, options: dict[str, Any]) -> dict[str, Any]:
    ref = simulate_case("generalisation", specimen,
                        FixedModelUpdater("reference", specimen_model(specimen)),
                        kanai_tajimi(3.0, 30.0, seed=7))  # fmt: skip
    conv = _conventional(specimen, kanai_tajimi(3.0, 30.0, seed=8), 0.0)
    disp = conv.tested_drift[:OFFLINE_SAMPLES].copy()
    force = conv.tested_force[:OFFLINE_SAMPLES].copy()
    n = REPLAY_STEPS
    start = time.process_time()
    result = replay(factory(disp, force, **options), ref.tested_drift[:n],
                    ref.tested_force[:n], ref.twin_drift[:n])  # fmt: skip
    seconds = time.process_time() - start
    truth = ref.twin_true_force[:n]
    err = np.abs(truth - result.force_pred)
    return {"record": "replay", "specimen": specimen, "noise_pct": 0.0, "conv_cal": math.nan,
            "target": math.nan, "maeth": indicators.maeth(truth, result.force_pred),
            "reduction_pct": math.nan, "worst_step": int(np.argmax(err)), "cpu_s": seconds}


Job = tuple[tuple[Any, str, float], str | None, dict[str, Any], str]


def _one(job: Job) -> dict[str, Any]:
    (record, specimen, noise), factory_spec, options, family = job
    factory = _factory(factory_spec)
    if record == "replay":
        return _replay_pair(specimen, factory, options)
    return _closed_loop(int(record), specimen, noise, factory, options, family)


def design_runs(only: str | None = None, seeds: tuple[int, ...] | None = None,
                families: tuple[str, ...] = ("kt",), noise: float | None = None
                ) -> list[tuple[tuple[Any, str, float], str]]:
    """The runs ``evaluate`` makes: ((record seed or "replay", specimen, noise %), family)."""
    unknown = [f for f in families if f not in DESIGN_FAMILIES]
    if unknown or not families or (seeds is None and families != ("kt",)):
        raise ValueError(f"updater_design: families must be of {', '.join(DESIGN_FAMILIES)}, "
                         f"and families other than kt need --seeds (got "
                         f"{', '.join(families) or 'none'} with seeds {seeds})")  # fmt: skip
    design = (*CLOSED_LOOP, *REPLAY) if seeds is None else tuple(
        (seed, spec, level) for seed in seeds for spec in SPECIMENS for level in (0.0, 1.0))
    items = [it for it in design if (only is None or it[1] == only)
             and (noise is None or it[0] == "replay" or it[2] == noise)]
    return [(it, fam) for fam in families for it in items]


def evaluate(factory_spec: str | None, options: dict[str, Any], workers: int,
             only: str | None = None, seeds: tuple[int, ...] | None = None,
             families: tuple[str, ...] = ("kt",), noise: float | None = None
             ) -> list[dict[str, Any]]:
    """The ten design numbers of one candidate (``only``: a specimen name to run half;
    ``seeds``: closed-loop runs on these record seeds of each of ``families`` instead, no
    replay pairs; ``noise``: that load-cell noise level only)."""
    jobs: list[Job] = [(it, factory_spec, options, fam)
                       for it, fam in design_runs(only, seeds, families, noise)]
    if workers <= 1:
        return [_one(j) for j in jobs]
    with ProcessPoolExecutor(workers) as pool:
        return list(pool.map(_one, jobs))


def _print(rows: list[dict[str, Any]], base: list[dict[str, Any]] | None) -> None:
    print("| record | specimen | noise % | conv_cal | target | MAETH | reduction % | worst step "
          "| CPU s |" + (" vs baseline |" if base else ""))
    print("|---|---|---|---|---|---|---|---|---|" + ("---|" if base else ""))
    ratios = []
    for i, r in enumerate(rows):
        line = (f"| {r['record']} | {r['specimen']} | {r['noise_pct']:g} | {r['conv_cal']:.3f} | "
                f"{r['target']:.3f} | {r['maeth']:.3f} | {r['reduction_pct']:.1f} | "
                f"{r['worst_step']} | {r['cpu_s']:.1f} |")
        if base:
            ratio = r["maeth"] / base[i]["maeth"]
            ratios.append(ratio)
            line += f" {ratio:.3f} ({base[i]['maeth']:.3f}) |"
        print(line)
    if ratios:
        geo = math.exp(sum(math.log(x) for x in ratios) / len(ratios))
        print(f"\ngeometric mean vs baseline {geo:.3f}, worst {max(ratios):.3f}, better on "
              f"{sum(x < 1 for x in ratios)} of {len(ratios)}")


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(description=__doc__,
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--option", type=parse_option, action="append", default=[])
    parser.add_argument("--factory", help="module:function building the candidate updater")
    parser.add_argument("--baseline", action="store_true",
                        help="also run the default online_improved and compare")
    parser.add_argument("--baseline-option", type=parse_option, action="append", default=[],
                        help="an option of the baseline online_improved (implies --baseline)")
    parser.add_argument("--seeds", type=lambda t: tuple(int(x) for x in t.split(",")),
                        help="closed-loop record seeds instead of the design set (e.g. 3,4,5,6: "
                             "more design runs; no replay pairs)")
    parser.add_argument("--family", type=lambda t: tuple(t.split(",")), default=("kt",),
                        help="with --seeds: design record families, comma-separated, of "
                             f"{', '.join(DESIGN_FAMILIES)} (default kt)")
    parser.add_argument("--noise", type=float, choices=(0.0, 1.0),
                        help="one load-cell noise level only (%%)")
    parser.add_argument("--only", choices=SPECIMENS, help="one specimen only")
    parser.add_argument("--workers", type=int, default=1)
    parser.add_argument("--json", help="write the rows here")
    parser.add_argument("--quick", action="store_true", help="one closed-loop run")
    args = parser.parse_args(argv)
    if args.quick:
        args.only, args.seeds, args.noise = "bwbn", (1,), 0.0
    options = dict(args.option)
    try:
        design_runs(args.only, args.seeds, args.family, args.noise)
    except ValueError as exc:
        parser.error(str(exc))
    scope = (args.only, args.seeds, args.family, args.noise)
    rows = evaluate(args.factory, options, args.workers, *scope)
    base_options = dict(args.baseline_option)
    base = (evaluate(None, base_options, args.workers, *scope)
            if args.baseline or base_options else None)
    _print(rows, base)
    if args.json:
        with open(args.json, "w", encoding="utf-8") as fh:
            json.dump({"candidate": rows, "baseline": base}, fh, indent=1)


if __name__ == "__main__":
    main()
