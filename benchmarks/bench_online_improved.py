"""``online_improved``'s cost per step: against the simulated tested damper (short run), and
over a long run (is the learning cost bounded whatever the run's length?).

* ``step`` (default): observe + the twin's trial/commit against one step of the simulated
  tested damper (BWBN, the baseline), same process, same histories (a study run: demo frame,
  synthetic record, generalisation layout, the reference twin). Rounds alternate the variants;
  per round the median and p99 of the per-step wall time; the table gives min / median over
  rounds.
* ``--long N``: one N-step source (Northridge LOS270 from ``examples/data``, scaled to 3 m/s²,
  repeated with 5 s of rest between repeats, driving the BWBN damper in the demo frame), then
  ``online_improved`` (offline database: the first 2500 steps) observes every step and its
  twin follows the twin story. Per tenth of the run: median, p99 and max of the per-step time,
  and the process's RSS at its end. Targets: p99 of the last tenth ≤ 1.5× the first tenth's,
  RSS growth ≤ 20 MB.

    taskset -c 1 python -m benchmarks.bench_online_improved [--quick] [--rounds 3]
    taskset -c 1 python -m benchmarks.bench_online_improved --long 100000 [--rounds 3]

Feeds BENCHMARKS.md, "Online updating" (cost per step, bounded learning).
"""

from __future__ import annotations

import argparse
import statistics
import time
from pathlib import Path

import numpy as np
import numpy.typing as npt

from fresco_bridge.integrator import GroundMotion, kanai_tajimi, read_peer_at2
from fresco_bridge.study.simulate import simulate_case, specimen_model
from fresco_bridge.updating.improved import OnlineImproved
from fresco_bridge.updating.updaters import FixedModelUpdater

FloatArray = npt.NDArray[np.float64]
RECORD = Path(__file__).resolve().parents[1] / "examples" / "data" / "RSN960_NORTHR_LOS270.AT2"


def _improved(tested: FloatArray, force: FloatArray, twin: FloatArray,
              offline: int = 1000) -> list[float]:
    updater = OnlineImproved(offline=(tested[:offline], force[:offline]))
    model = updater.twin
    times = []
    for d, f, dw in zip(tested.tolist(), force.tolist(), twin.tolist(), strict=True):
        start = time.perf_counter()
        updater.observe(d, f)
        model.set_trial(dw)
        model.commit()
        times.append(time.perf_counter() - start)
    return times


def _specimen(tested: FloatArray) -> list[float]:
    model = specimen_model("bwbn")
    times = []
    for d in tested.tolist():
        start = time.perf_counter()
        model.set_trial(d)
        model.commit()
        times.append(time.perf_counter() - start)
    return times


def _rss_mb() -> float:
    """Resident set size of this process now (MB), from /proc."""
    with open("/proc/self/statm", encoding="ascii") as fh:
        pages = int(fh.read().split()[1])
    return pages * 4096 / 1e6


def _short(rounds: int, quick: bool) -> None:
    motion = kanai_tajimi(3.0, duration=5.0 if quick else 20.0, dt=0.01, seed=1)
    run = simulate_case("generalisation", "bwbn",
                        FixedModelUpdater("reference", specimen_model("bwbn")), motion)
    tested, force, twin = run.tested_drift, run.tested_force, run.twin_drift
    rows: dict[str, list[tuple[float, float]]] = {"online_improved": [], "bwbn step": []}
    for _ in range(rounds):
        for name in rows:
            times = _specimen(tested) if name == "bwbn step" else _improved(tested, force, twin)
            ms = np.asarray(times, dtype=np.float64) * 1e3
            rows[name].append((float(np.median(ms)), float(np.percentile(ms, 99))))
    print(f"{tested.size} steps, {rounds} rounds (min / median over rounds), ms per step")
    print("| variant | median | p99 |\n|---|---|---|")
    for name, values in rows.items():
        med = [v[0] for v in values]
        p99 = [v[1] for v in values]
        print(f"| {name} | {min(med):.4f} / {statistics.median(med):.4f} | "
              f"{min(p99):.4f} / {statistics.median(p99):.4f} |")
    ratio = [a[0] / b[0] for a, b in zip(rows["online_improved"], rows["bwbn step"], strict=True)]
    print(f"ratio of medians online_improved / bwbn step: min {min(ratio):.2f}, "
          f"median {statistics.median(ratio):.2f}")


def long_motion(steps: int) -> GroundMotion:
    """Northridge LOS270 at 3 m/s², repeated with 5 s of rest between repeats, ``steps`` long."""
    once = read_peer_at2(RECORD).scaled_to_pga(3.0)
    rest = np.zeros(round(5.0 / once.dt))
    block = np.concatenate((once.accel, rest))
    accel = np.tile(block, steps // block.size + 1)[:steps]
    return GroundMotion(once.dt, accel, f"{once.name} repeated", once.source)


def _long(steps: int, rounds: int) -> None:
    motion = long_motion(steps + 1)
    run = simulate_case("generalisation", "bwbn",
                        FixedModelUpdater("reference", specimen_model("bwbn")), motion,
                        steps=steps)  # fmt: skip
    tested, force, twin = run.tested_drift, run.tested_force, run.twin_drift
    print(f"{tested.size} steps (LOS270 repeated), {rounds} round(s); per tenth of the run: "
          "median / p99 / max ms per step (observe + twin trial/commit), RSS MB at its end")
    tenth = tested.size // 10
    for r in range(rounds):
        rss = [_rss_mb()]
        updater = OnlineImproved(offline=(tested[:2500], force[:2500]))
        model = updater.twin
        times = np.empty(tested.size)
        for i, (d, f, dw) in enumerate(zip(tested.tolist(), force.tolist(), twin.tolist(),
                                           strict=True)):  # fmt: skip
            start = time.perf_counter()
            updater.observe(d, f)
            model.set_trial(dw)
            model.commit()
            times[i] = time.perf_counter() - start
            if (i + 1) % tenth == 0:
                rss.append(_rss_mb())
        law = updater.experts[updater.expert_names.index("baber-wen")]
        ms = times * 1e3
        parts = [ms[k * tenth:(k + 1) * tenth] for k in range(10)]
        p99 = [float(np.percentile(p, 99)) for p in parts]
        print(f"round {r + 1}: " + "; ".join(
            f"{float(np.median(p)):.3f}/{q:.2f}/{float(np.max(p)):.0f}"
            for p, q in zip(parts, p99, strict=True)))  # fmt: skip
        print(f"  p99 last tenth / first tenth: {p99[-1] / p99[0]:.2f} (target <= 1.5); "
              f"RSS {rss[0]:.1f} -> {rss[1]:.1f} (after the first tenth) -> {rss[-1]:.1f} MB: "
              f"growth after the first tenth {rss[-1] - rss[1]:+.1f} MB (target <= 20); "
              f"refits of the law {getattr(law, 'refits', '-')}; "
              f"serving the offline start at the end: {updater.serving_start}")


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("--rounds", type=int, default=3)
    parser.add_argument("--quick", action="store_true", help="one round on a 5 s record")
    parser.add_argument("--long", type=int, default=None, metavar="N",
                        help="the long run: N steps (e.g. 100000)")
    args = parser.parse_args(argv)
    if args.quick:
        args.rounds = 1
    if args.long is not None:
        _long(args.long, args.rounds)
    else:
        _short(args.rounds, args.quick)


if __name__ == "__main__":
    main()
