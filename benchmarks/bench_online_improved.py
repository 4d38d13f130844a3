"""Per-step cost of ``online_improved`` (observe + the twin's trial/commit) against the cost of
one step of the simulated tested damper (BWBN, the baseline), same process, same histories.

The histories are those of a study run (demo frame, synthetic record, generalisation layout,
the reference twin). Rounds alternate the variants; per round the median and p99 of the
per-step wall time are taken; the table gives min / median over rounds. ``--design-f`` adds
``online_improved`` with a fifth expert and shadow scoring (options, not its default) as a third
variant.

    taskset -c 1 python -m benchmarks.bench_online_improved [--quick] [--rounds 3] [--design-f]

Feeds BENCHMARKS.md, "Online updating" (cost per step). ``--quick``: one round on a 5 s record,
a smoke run.
"""

from __future__ import annotations

import argparse
import statistics
import time
from typing import Any

import numpy as np

from fresco_bridge.integrator import kanai_tajimi
from fresco_bridge.study.simulate import simulate_case, specimen_model
from fresco_bridge.updating.improved import OnlineImproved
from fresco_bridge.updating.updaters import FixedModelUpdater

FIFTH_EXPERT_SHADOW: dict[str, Any] = {
    "experts": "reversal,reversal+memory,bouc-wen+memory,reversal+stops,reversal+memory+hinges",
    "shadow": True,
}
"""``online_improved`` with a fifth expert and shadow scoring (options, not the default)."""


def _improved(tested: np.ndarray, force: np.ndarray, twin: np.ndarray,
              options: dict[str, Any]) -> list[float]:
    updater = OnlineImproved(offline=(tested[:1000], force[:1000]), **options)
    model = updater.twin
    times = []
    for d, f, dw in zip(tested.tolist(), force.tolist(), twin.tolist(), strict=True):
        start = time.perf_counter()
        updater.observe(d, f)
        model.set_trial(dw)
        model.commit()
        times.append(time.perf_counter() - start)
    return times


def _specimen(tested: np.ndarray) -> list[float]:
    model = specimen_model("bwbn")
    times = []
    for d in tested.tolist():
        start = time.perf_counter()
        model.set_trial(d)
        model.commit()
        times.append(time.perf_counter() - start)
    return times


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("--rounds", type=int, default=3)
    parser.add_argument("--design-f", action="store_true",
                        help="also time a fifth expert with shadow scoring")
    parser.add_argument("--quick", action="store_true", help="one round on a 5 s record")
    args = parser.parse_args(argv)
    if args.quick:
        args.rounds = 1
    motion = kanai_tajimi(3.0, duration=5.0 if args.quick else 20.0, dt=0.01, seed=1)
    run = simulate_case("generalisation", "bwbn",
                        FixedModelUpdater("reference", specimen_model("bwbn")), motion)
    tested, force, twin = run.tested_drift, run.tested_force, run.twin_drift
    rows: dict[str, list[tuple[float, float]]] = {"online_improved": [], "bwbn step": []}
    if args.design_f:
        rows["online_improved, fifth expert + shadow"] = []
    for _ in range(args.rounds):
        for name in rows:
            options = FIFTH_EXPERT_SHADOW if name.endswith("shadow") else {}
            times = (_specimen(tested) if name == "bwbn step"
                     else _improved(tested, force, twin, options))
            ms = np.asarray(times, dtype=np.float64) * 1e3
            rows[name].append((float(np.median(ms)), float(np.percentile(ms, 99))))
    print(f"{tested.size} steps, {args.rounds} rounds (min / median over rounds), ms per step")
    print("| variant | median | p99 |\n|---|---|---|")
    for name, values in rows.items():
        med = [v[0] for v in values]
        p99 = [v[1] for v in values]
        print(f"| {name} | {min(med):.4f} / {statistics.median(med):.4f} | "
              f"{min(p99):.4f} / {statistics.median(p99):.4f} |")
    ratio = [a[0] / b[0] for a, b in zip(rows["online_improved"], rows["bwbn step"], strict=True)]
    print(f"ratio of medians online_improved / bwbn step: min {min(ratio):.2f}, "
          f"median {statistics.median(ratio):.2f}")


if __name__ == "__main__":
    main()
