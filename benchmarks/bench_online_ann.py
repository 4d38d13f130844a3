"""online_ann: update time per step and accuracy, the paper's 50 LM iterations vs early stopping.

    taskset -c 1 .venv/bin/python -m benchmarks.bench_online_ann [--quick] [--json FILE]

Feeds BENCHMARKS.md, "Online updating" (online_ann's cost and the variants behind its default).
``--quick``: one pair of 60 steps, the default variant (two in the timing), one round, a
smoke run.

Data (the study's simulation, in process): the offline database is the tested damper of a
conventional run (the paper's Bilinear twin) on synthetic record 1; evaluation pairs are
reference runs on other records, one per (specimen, record): SRC = the tested damper's (d, F),
TWIN = the twin's drift and true force, in the paper layout (twin beside the tested damper)
and the generalisation layout (twin in story 2). Each variant is replayed on every pair:

* accuracy: MAETH of the twin against its true force (the updater learns step i first) and
  the one-step-ahead RMSE (``--lag``: the twin only knows steps < i);
* time: wall and CPU (thread) time of every ``observe``; CPU time is what a quiet machine's
  wall time would be, so it is the number to read on a loaded machine.

A timing-only section alternates the variants over ``--rounds`` rounds on the same steps and
also times the pieces of one LM iteration (J^T W J as a general product over all 700 rows,
as a symmetric product over the rows that count, torch's float64 equivalent).
"""

from __future__ import annotations

import argparse
import json
import math
import os
import sys
import time
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from fresco_bridge import indicators
from fresco_bridge.integrator.demo import demo_ground_motion
from fresco_bridge.study.simulate import simulate_case, specimen_model
from fresco_bridge.updating import make_updater
from fresco_bridge.updating.ann import PRETRAIN_LM, AnnModel, pretrain
from fresco_bridge.updating.base import Updater
from fresco_bridge.updating.features import feature_rows
from fresco_bridge.updating.registry import PAPER_BILINEAR
from fresco_bridge.updating.updaters import FixedModelUpdater
from sim_actuator.models import Bilinear

_PAPER: dict[str, Any] = {"max_iterations": 50,
                          "single_precision_hessian": False}
"""The paper's exact fit (``PAPER_ONLINE_LM``); ``online_ann``'s default is "8 it f32"."""

VARIANTS: dict[str, dict[str, Any]] = {
    "faithful (50 it)": _PAPER,
    "faithful seed 2": {**_PAPER, "seed": 2},  # other random offline rows: the spread
    "50 it f32": {**_PAPER, "single_precision_hessian": True},
    "rtol 1e-2": {**_PAPER, "rtol": 0.01},
    "rtol 3e-2": {**_PAPER, "rtol": 0.03},
    "10 it": {**_PAPER, "max_iterations": 10},
    "8 it f32": {"max_iterations": 8, "single_precision_hessian": True},
    "default": {},  # whatever online_ann does without options (now "8 it f32")
    "5 it": {**_PAPER, "max_iterations": 5},
}


@dataclass
class Pair:
    label: str
    layout: str
    src_d: np.ndarray
    src_f: np.ndarray
    twin_d: np.ndarray
    twin_f: np.ndarray


def machine() -> dict[str, str]:
    blas = {k: v for k, v in os.environ.items() if "OPENBLAS" in k or k == "OMP_NUM_THREADS"}
    return {"nproc": str(os.cpu_count()), "affinity": str(sorted(os.sched_getaffinity(0))),
            "python": sys.version.split()[0],
            "loadavg": " ".join(f"{v:.2f}" for v in os.getloadavg()),
            "blas_env": ", ".join(f"{k}={v}" for k, v in sorted(blas.items())) or "(none)"}


def prepare(specimens: list[str], records: list[int], steps: int, pretrain_iterations: int,
            layouts: tuple[str, ...] = ("paper", "generalisation"),
            ) -> tuple[dict[str, AnnModel], list[Pair]]:
    models: dict[str, AnnModel] = {}
    pairs: list[Pair] = []
    for spec in specimens:
        conv = simulate_case("paper", spec,
                             FixedModelUpdater("conventional_paper", Bilinear(**PAPER_BILINEAR)),
                             demo_ground_motion(1))
        t = time.perf_counter()
        models[spec] = pretrain(conv.tested_drift, conv.tested_force, seed=1,
                                options=_lm(pretrain_iterations))
        print(f"  pretrained {spec}: {len(conv.tested_force)} samples, "
              f"{models[spec].training['iterations']} LM iterations, "
              f"{time.perf_counter() - t:.1f} s", flush=True)
        for rec in records:
            for layout in layouts:
                ref = simulate_case(layout, spec,
                                    FixedModelUpdater("reference", specimen_model(spec)),
                                    demo_ground_motion(rec), steps=steps)
                pairs.append(Pair(f"{spec}/record{rec}", layout, ref.tested_drift,
                                  ref.tested_force, ref.twin_drift, ref.twin_true_force))
    return models, pairs


def _lm(iterations: int) -> Any:
    from dataclasses import replace

    return replace(PRETRAIN_LM, max_iterations=iterations)


def run(updater: Updater, pair: Pair, lag: bool, iterations: list[int] | None = None,
        teacher: list[float] | None = None) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(predictions, wall s, cpu s) per step; the replay loop with CPU time around observe.

    ``iterations`` collects the LM iterations of every update (online_ann); ``teacher`` the
    network's force at each step from the twin's *true* previous state, after the update
    (teacher forcing: the fit's own error, free of the recurrence's chaos).
    """
    twin = updater.twin
    n = len(pair.twin_d)
    pred, wall, cpu = np.empty(n), np.empty(n), np.empty(n)
    model: AnnModel | None = getattr(updater, "model", None)
    x_true = None if teacher is None or model is None else \
        model.scaler.x(feature_rows(pair.twin_d, pair.twin_f)[0])
    for i in range(n):
        if lag:
            pred[i] = twin.set_trial(float(pair.twin_d[i]))[0]
            twin.commit()
        c0 = time.thread_time()
        updater.observe(float(pair.src_d[i]), float(pair.src_f[i]))
        cpu[i] = time.thread_time() - c0
        wall[i] = updater.last_update_seconds
        if iterations is not None:
            iterations.append(updater.last_fit.iterations)  # type: ignore[attr-defined]
        if x_true is not None and teacher is not None and model is not None:
            y = model.net.forward(updater.theta, x_true[i:i + 1])[0]  # type: ignore[attr-defined]
            teacher.append(float(y) * model.scaler.y_range + model.scaler.y_min)
        if not lag:
            pred[i] = twin.set_trial(float(pair.twin_d[i]))[0]
            twin.commit()
    return pred, wall, cpu


def scored_run(updater: Updater, pair: Pair) -> dict[str, float]:
    """One replay (the updater learns step i first) scored: MAETH, the teacher-forced RMSE,
    LM iterations and the update's wall and CPU time."""
    its: list[int] = []
    forced: list[float] = []
    pred, wall, cpu = run(updater, pair, lag=False, iterations=its, teacher=forced)
    return {"maeth": indicators.maeth(pair.twin_f, pred),
            "teacher_forced_rmse": indicators.one_step_rmse(pair.twin_f, np.array(forced)),
            "iterations_mean": float(np.mean(its)),
            "wall_ms_median": 1e3 * float(np.median(wall)),
            "wall_ms_p99": 1e3 * float(np.percentile(wall, 99)),
            "cpu_ms_median": 1e3 * float(np.median(cpu)),
            "cpu_ms_p99": 1e3 * float(np.percentile(cpu, 99))}


def accuracy(models: dict[str, AnnModel], pairs: list[Pair],
             variants: list[str], lag: bool = True) -> list[dict[str, Any]]:
    rows = []
    for pair in pairs:
        model = models[pair.label.split("/")[0]]
        offline = make_updater("offline_ann", model=model)
        base, _, _ = run(offline, pair, lag=False)
        print(f"  {pair.label} {pair.layout}: offline_ann MAETH "
              f"{indicators.maeth(pair.twin_f, base):.3f} kN", flush=True)
        rows.append({"pair": pair.label, "layout": pair.layout, "variant": "offline_ann",
                     "maeth": indicators.maeth(pair.twin_f, base),
                     "one_step_rmse": indicators.one_step_rmse(pair.twin_f, base)})
        for name in variants:
            opts = {"seed": 1, **VARIANTS[name]}
            scores = scored_run(make_updater("online_ann", model=model, **opts), pair)
            one_step = math.nan
            if lag:
                ahead, _, _ = run(make_updater("online_ann", model=model, **opts), pair,
                                  lag=True)
                one_step = indicators.one_step_rmse(pair.twin_f, ahead)
            row: dict[str, Any] = {"pair": pair.label, "layout": pair.layout, "variant": name,
                                   "one_step_rmse": one_step, **scores}
            rows.append(row)
            print(f"  {pair.label} {pair.layout}: {name:<17} MAETH {row['maeth']:7.3f} kN, "
                  f"one-step RMSE {row['one_step_rmse']:.4f} kN, teacher-forced RMSE "
                  f"{row['teacher_forced_rmse']:.4f} kN, LM iterations mean "
                  f"{row['iterations_mean']:.1f}; update wall median "
                  f"{row['wall_ms_median']:.1f} p99 {row['wall_ms_p99']:.1f} ms, cpu median "
                  f"{row['cpu_ms_median']:.1f} p99 {row['cpu_ms_p99']:.1f} ms", flush=True)
    return rows


def timing(model: AnnModel, pair: Pair, rounds: int, steps: int,
           variants: list[str]) -> dict[str, dict[str, list[float]]]:
    """Variants alternated round by round on the same steps: per-round median and p99."""
    out: dict[str, dict[str, list[float]]] = {}
    short = Pair(pair.label, pair.layout, pair.src_d[:steps], pair.src_f[:steps],
                 pair.twin_d[:steps], pair.twin_f[:steps])
    for rnd in range(rounds):
        for name in variants:
            its: list[int] = []
            opts = {"seed": 1, **VARIANTS[name]}
            _, wall, cpu = run(make_updater("online_ann", model=model, **opts), short,
                               lag=False, iterations=its)
            rec = out.setdefault(name, {"wall_median": [], "wall_p99": [], "cpu_median": [],
                                        "cpu_p99": [], "iterations_mean": [],
                                        "iterations_p99": []})
            rec["iterations_mean"].append(float(np.mean(its)))
            rec["iterations_p99"].append(float(np.percentile(its, 99)))
            rec["wall_median"].append(1e3 * float(np.median(wall)))
            rec["wall_p99"].append(1e3 * float(np.percentile(wall, 99)))
            rec["cpu_median"].append(1e3 * float(np.median(cpu)))
            rec["cpu_p99"].append(1e3 * float(np.percentile(cpu, 99)))
            print(f"  round {rnd + 1}/{rounds} {name:<16} wall median "
                  f"{rec['wall_median'][-1]:.2f} p99 {rec['wall_p99'][-1]:.2f} ms; cpu median "
                  f"{rec['cpu_median'][-1]:.2f} p99 {rec['cpu_p99'][-1]:.2f} ms; LM iterations "
                  f"mean {rec['iterations_mean'][-1]:.1f} p99 {rec['iterations_p99'][-1]:.0f}",
                  flush=True)
    return out


def _best(fn: Callable[[], object], repeat: int = 30) -> float:
    times = []
    for _ in range(repeat):
        t = time.thread_time()
        fn()
        times.append(time.thread_time() - t)
    return 1e3 * float(np.median(times))


def pieces(rounds: int) -> dict[str, list[float]]:
    """CPU ms of one LM iteration's pieces at the paper's sizes (700 x 301, 516 rows kept)."""
    import scipy.linalg  # type: ignore[import-untyped]
    from scipy.linalg.blas import dsyrk, ssyrk  # type: ignore[import-untyped]
    from scipy.linalg.lapack import dpotrf, dpotrs  # type: ignore[import-untyped]

    from fresco_bridge.updating.lm import one_blas_thread
    from fresco_bridge.updating.mlp import Mlp

    net = Mlp()
    rng = np.random.default_rng(0)
    theta = net.init_params(rng)
    x = rng.random((700, 6))
    w = rng.random(700)
    _, jac = net.jacobian(theta, x)
    wj = jac * w[:, None]
    js = (jac * np.sqrt(w)[:, None])[-516:].copy()
    hess = js.T @ js + 1e-5 * np.eye(301)
    jsf = np.asfortranarray(js)
    js32 = np.asfortranarray(js, dtype=np.float32)
    hess_f = np.asfortranarray(hess)
    out: dict[str, list[float]] = {}
    torch_mm: Callable[[], object] | None = None
    try:
        import torch

        torch.set_num_threads(1)
        tj = torch.from_numpy(js.copy())
        th = torch.from_numpy(hess.copy())
        tg = torch.from_numpy(js.T @ np.ones(516)).reshape(-1, 1)

        def torch_step() -> object:
            h = tj.T @ tj
            h.diagonal().add_(1e-5)
            return torch.cholesky_solve(tg, torch.linalg.cholesky(h))

        torch_mm = torch_step
        del th
    except ImportError:
        pass
    with one_blas_thread():
        for _ in range(rounds):
            for name, fn in (
                ("jacobian 700 x 301", lambda: net.jacobian(theta, x)),
                ("forward 700", lambda: net.forward(theta, x)),
                ("J^T W J gemm, 700 rows (naive)", lambda: wj.T @ jac),
                ("J^T W J syrk, 516 rows (numpy A.T @ A)", lambda: js.T @ js),
                ("J^T W J dsyrk in place, lower only (ours)",
                 lambda: dsyrk(1.0, jsf, lower=1, trans=1)),
                ("J^T W J ssyrk float32 (option)",
                 lambda: ssyrk(1.0, js32, lower=1, trans=1)),
                ("dpotrf + dpotrs 301, LAPACK direct (ours)",
                 lambda: dpotrs(dpotrf(hess_f, lower=1, clean=0)[0], js[0], lower=1)),
                ("cholesky + solve 301", lambda: scipy.linalg.cho_solve(
                    scipy.linalg.cho_factor(hess), js[0], check_finite=False)),
                ("numpy GN step (syrk + chol + solve)", lambda: scipy.linalg.cho_solve(
                    scipy.linalg.cho_factor(js.T @ js + 1e-5 * np.eye(301)), js[0])),
            ):
                out.setdefault(name, []).append(_best(fn))
            if torch_mm is not None:
                out.setdefault("torch f64 GN step (mm + cholesky + solve)", []).append(
                    _best(torch_mm))
    return out


def main(argv: list[str] | None = None) -> None:
    p = argparse.ArgumentParser(description=__doc__)
    p.add_argument("--specimens", default="bwbn,menegotto-pinto")
    p.add_argument("--records", default="2,3")
    p.add_argument("--steps", type=int, default=400)
    p.add_argument("--pretrain-iterations", type=int, default=300)
    p.add_argument("--rounds", type=int, default=3)
    p.add_argument("--timing-steps", type=int, default=150)
    p.add_argument("--layouts", default="paper,generalisation")
    p.add_argument("--variants", default=",".join(VARIANTS),
                   help=f"comma-separated subset of: {', '.join(VARIANTS)}")
    p.add_argument("--timing-variants", default="faithful (50 it),50 it f32,5 it",
                   help="comma-separated variants alternated in the timing section")
    p.add_argument("--skip-accuracy", action="store_true")
    p.add_argument("--skip-timing", action="store_true")
    p.add_argument("--no-lag", action="store_true",
                   help="accuracy without the one-step-ahead replay (half the time)")
    p.add_argument("--json", type=Path, default=None)
    p.add_argument("--quick", action="store_true", help="one short pair, two variants")
    args = p.parse_args(argv)
    if args.quick:
        args.specimens, args.records, args.layouts = "bwbn", "2", "generalisation"
        args.steps, args.pretrain_iterations, args.rounds = 60, 30, 1
        args.timing_steps, args.no_lag = 10, True
        args.variants, args.timing_variants = "default", "faithful (50 it),8 it f32"
    info = machine()
    print("machine:", info, flush=True)
    result: dict[str, Any] = {"machine": info}
    models, pairs = prepare(args.specimens.split(","), [int(r) for r in args.records.split(",")],
                            args.steps, args.pretrain_iterations,
                            tuple(args.layouts.split(",")))
    if not args.skip_timing:
        print("pieces of one LM iteration (cpu ms, median of 30 per round):", flush=True)
        result["pieces"] = pieces(args.rounds)
        for name, vals in result["pieces"].items():
            print(f"  {name:<42} min {min(vals):.3f}  median {float(np.median(vals)):.3f}")
        print("timing (alternating rounds):", flush=True)
        result["timing"] = timing(models[pairs[0].label.split("/")[0]], pairs[0], args.rounds,
                                  args.timing_steps, args.timing_variants.split(","))
    if not args.skip_accuracy:
        print("accuracy:", flush=True)
        result["accuracy"] = accuracy(models, pairs, args.variants.split(","), not args.no_lag)
    result["machine_end"] = machine()
    if args.json is not None:
        args.json.write_text(json.dumps(result, indent=2))


if __name__ == "__main__":
    main()
