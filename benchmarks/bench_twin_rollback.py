"""The cost of a same-step twin's rollback point (``twins/worker.py``): one snapshot of the
updater (``updating.base.snapshot``) per session's first same-step trial and per ``REBASE``
steps, and a restore when a tentative step is unlearned, against the updater's own learning
time per step. The shipped BRFD pair: offline the 0.25 Hz sine, the source the Imperial
Valley DBE record, each updater after 1,000 learned steps.

    .venv/bin/python -m benchmarks.bench_twin_rollback [--steps N] [--repeat R]
"""

from __future__ import annotations

import argparse
import statistics
import time
from pathlib import Path

from fresco_bridge.twins.worker import REBASE
from fresco_bridge.updating.base import restore, snapshot
from fresco_bridge.updating.histories import read_history
from fresco_bridge.updating.registry import make_updater

DATA = Path(__file__).resolve().parent.parent / "examples" / "data"


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--steps", type=int, default=1000)
    parser.add_argument("--repeat", type=int, default=20)
    args = parser.parse_args()
    offline = read_history(DATA / "brfd_sine_0.25hz.csv")
    source = read_history(DATA / "brfd_imperial_valley_dbe.csv")
    assert source.force is not None and offline.force is not None
    for name in ("online_ukf", "online_ann", "online_improved"):
        updater = make_updater(name, offline=(offline.disp, offline.force))
        learn = []
        for d, f in zip(source.disp[: args.steps], source.force[: args.steps], strict=True):
            t0 = time.perf_counter()
            updater.observe(float(d), float(f))
            learn.append(time.perf_counter() - t0)
        snaps, restores = [], []
        for _ in range(args.repeat):
            t0 = time.perf_counter()
            blob = snapshot(updater)
            t1 = time.perf_counter()
            restore(blob)
            t2 = time.perf_counter()
            snaps.append(t1 - t0)
            restores.append(t2 - t1)
        step = statistics.median(learn)
        snap = statistics.median(snaps)
        print(f"{name:16s} learn/step median {1e3 * step:7.3f} ms | snapshot min/median "
              f"{1e3 * min(snaps):6.3f}/{1e3 * snap:6.3f} ms ({len(blob) / 1e3:.0f} kB) | "
              f"restore min/median {1e3 * min(restores):6.3f}/"
              f"{1e3 * statistics.median(restores):6.3f} ms | snapshot per step at REBASE "
              f"{REBASE}: {1e3 * snap / REBASE:.3f} ms ({100 * snap / REBASE / step:.1f} %)")


if __name__ == "__main__":
    main()
