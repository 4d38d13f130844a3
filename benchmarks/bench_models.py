"""Per-step cost of the hysteresis models (``set_trial`` twice + ``commit``, as a Newton step
of the bridge's step loop does), this tree against another source tree, alternating.

``python -m benchmarks.bench_models --baseline DIR`` runs each variant in its own process
(``PYTHONPATH`` = the tree), pinned with ``taskset -c 1`` when available, variants alternating,
``--rounds`` rounds, and prints min/median ns per step and the ratio. Without ``--baseline`` it
only times this tree. ``DIR`` is e.g. ``git archive main | tar -x -C /tmp/base``.

Feeds BENCHMARKS.md, "Step cost and scaling" (the specimen's share of a step). ``--quick``: one
round of 20 000 steps, a smoke run.
"""

from __future__ import annotations

import argparse
import json
import math
import os
import shutil
import statistics
import subprocess
import sys
import time
from pathlib import Path

KINDS: dict[str, dict[str, float]] = {
    "elastic": {"k": 10.0},
    "bilinear": {"k0": 8.0, "fy": 12.0, "alpha": 0.05},
    "bouc-wen": {"k0": 8.0, "fy": 12.0, "alpha": 0.05, "n": 2.0, "beta": 0.5, "gamma": 0.5},
    "bwbn": {"k0": 8.0, "fy": 12.0, "alpha": 0.05, "n": 2.0, "beta": 0.5, "gamma": 0.5,
             "zeta_s": 0.6, "p": 1.0, "q": 0.1, "psi0": 0.3, "delta_psi": 0.01, "lam": 0.5,
             "delta_nu": 0.01, "delta_eta": 0.01},
    "menegotto-pinto": {"k0": 8.0, "fy": 12.0, "alpha": 0.05, "a1": 0.02, "a3": 0.02},
}
ROOT = Path(__file__).resolve().parent.parent


def time_kind(kind: str, steps: int) -> float:
    """ns per step of a 4 mm, growing sine (yields the bilinear damper every cycle)."""
    from sim_actuator.models import make_model

    model = make_model(kind, **KINDS[kind])
    path = [4.0 * (1 + i / steps) * math.sin(0.05 * i) for i in range(1, steps + 1)]
    set_trial, commit = model.set_trial, model.commit
    t0 = time.perf_counter()
    for d in path:
        set_trial(d * 0.99)
        set_trial(d)
        commit()
    return (time.perf_counter() - t0) / steps * 1e9


def _child(steps: int) -> None:
    from sim_actuator.models import MODEL_PARAMETERS

    counts = {"elastic": steps, "bilinear": steps, "bouc-wen": steps // 10, "bwbn": steps // 20,
              "menegotto-pinto": steps}
    print(json.dumps({k: time_kind(k, n) for k, n in counts.items() if k in MODEL_PARAMETERS}))


def _run_tree(tree: Path, steps: int) -> dict[str, float]:
    cmd = [sys.executable, "-m", "benchmarks.bench_models", "--child", "--steps", str(steps)]
    if shutil.which("taskset"):
        cmd = ["taskset", "-c", "1", *cmd]
    env = {**os.environ, "PYTHONPATH": f"{tree}{os.pathsep}{ROOT}"}
    out = subprocess.run(cmd, env=env, cwd=tree, capture_output=True, text=True, check=True,
                         timeout=600)
    result: dict[str, float] = json.loads(out.stdout)
    return result


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("--baseline", type=Path, help="another source tree to compare against")
    parser.add_argument("--rounds", type=int, default=5)
    parser.add_argument("--steps", type=int, default=200_000)
    parser.add_argument("--child", action="store_true", help=argparse.SUPPRESS)
    parser.add_argument("--quick", action="store_true", help="one round of 20 000 steps")
    args = parser.parse_args(argv)
    if args.quick:
        args.rounds, args.steps = 1, min(args.steps, 20_000)
    if args.child:
        _child(args.steps)
        return
    trees = {"this": ROOT}
    if args.baseline is not None:
        trees = {"baseline": args.baseline.resolve(), "this": ROOT}
    samples: dict[str, list[dict[str, float]]] = {name: [] for name in trees}
    for _ in range(args.rounds):
        for name, tree in trees.items():
            samples[name].append(_run_tree(tree, args.steps))
    print(f"ns per step (2 trials + commit), {args.rounds} rounds alternating, taskset -c 1")
    print(f"{'kind':10s} " + " ".join(f"{n + ' min':>14s} {n + ' med':>14s}" for n in trees)
          + ("  ratio (median)" if len(trees) == 2 else ""))
    for kind in KINDS:
        cells, medians = [], []
        if any(kind not in s for runs in samples.values() for s in runs):
            continue  # a kind one of the trees does not have
        for name in trees:
            values = [s[kind] for s in samples[name]]
            medians.append(statistics.median(values))
            cells.append(f"{min(values):14.1f} {medians[-1]:14.1f}")
        ratio = f"  {medians[1] / medians[0]:.3f}" if len(trees) == 2 else ""
        print(f"{kind:10s} " + " ".join(cells) + ratio)


if __name__ == "__main__":
    main()
