"""Per-step cost of the safety layer: one site's step (trial → limits → controller → daq → commit)
without limits vs. with every limit configured, same process, same trajectory (all within limits).

The site is driven directly (no sockets, no record), with the in-process elastic specimen, so the
difference is the cost of the checks themselves.

    python -m benchmarks.bench_safety [--quick] [--steps 5000] [--repeats 7]

Feeds BENCHMARKS.md, "Safety layer". ``--quick``: 500 steps, one repeat, a smoke run.
"""

from __future__ import annotations

import argparse
import math
import platform
import statistics
import time
from typing import Any

from fresco_bridge.config import parse_config
from fresco_bridge.eager import Suspended, start_eager
from fresco_bridge.sites.experimental import ExperimentalSite
from fresco_bridge.sites.experimental_kind import site_controller as make_controller
from protocol import Signals, SignalSizes

SITE = """
[[sites]]
name = "s"
port = 0
[sites.controller]
model = "elastic"
params = { k = 10.0 }
"""
LIMITS = """
[[sites.limits]]
disp_min = -50.0
disp_max = 50.0
disp_increment = 5.0
velocity = 1000.0
force_min = -1000.0
force_max = 1000.0
"""
SIZES = SignalSizes(disp=0, vel=0, accel=0, force=1, time=0)
DT = 0.01


def _run(coro: Any) -> Any:
    r = start_eager(coro)
    assert not isinstance(r, Suspended), "the in-process path must not suspend"
    return r


def make_site(limits: bool) -> ExperimentalSite:
    cfg = parse_config(SITE + (LIMITS if limits else "")).sites[0]
    site = ExperimentalSite(cfg, make_controller(cfg), None, controller_timeout=5.0)
    site.open_session("bench")
    return site


def steps_per_run(site: ExperimentalSite, n: int) -> float:
    """Seconds per step over ``n`` steps of a 1 Hz, 20 mm sine (two trials per step)."""
    zeros = (0.0,)
    trials = []
    for i in range(1, n + 1):
        t = i * DT
        u = 20.0 * math.sin(2 * math.pi * t)
        trials.append((Signals(disp=(u * 0.99,), vel=zeros, accel=zeros, time=(t,)),
                       Signals(disp=(u,), vel=zeros, accel=zeros, time=(t,))))
    t0 = time.perf_counter()
    for first, second in trials:  # a Newton step: trial, force, corrected trial, force, commit
        _run(site.set_trial(first))
        _run(site.out_signals(SIZES))
        _run(site.set_trial(second))
        _run(site.out_signals(SIZES))
        _run(site.commit())
    elapsed = time.perf_counter() - t0
    assert str(site.state) == "RUNNING", f"the trajectory tripped a limit: {site.reason}"
    return elapsed / n


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("--steps", type=int, default=5000)
    parser.add_argument("--repeats", type=int, default=7)
    parser.add_argument("--quick", action="store_true", help="500 steps, one repeat")
    args = parser.parse_args(argv)
    if args.quick:
        args.steps, args.repeats = min(args.steps, 500), 1
    results: dict[str, list[float]] = {"no limits": [], "all limits": []}
    for _ in range(args.repeats):  # interleaved, so drift of a shared machine hits both
        for name, limits in (("no limits", False), ("all limits", True)):
            results[name].append(steps_per_run(make_site(limits), args.steps))
    print(f"machine: {platform.node()} {platform.processor() or platform.machine()}, "
          f"Python {platform.python_version()}; {args.repeats} interleaved runs of "
          f"{args.steps} steps (2 trials + 2 force requests + commit per step)")
    print("| variant | µs/step median | [min – max] |")
    print("|---|---|---|")
    for name, values in results.items():
        print(f"| {name} | {statistics.median(values) * 1e6:.2f} | "
              f"[{min(values) * 1e6:.2f} – {max(values) * 1e6:.2f}] |")
    ratio = statistics.median(results["all limits"]) / statistics.median(results["no limits"])
    extra = (statistics.median(results["all limits"])
             - statistics.median(results["no limits"])) * 1e6
    print(f"all limits / no limits = {ratio:.3f} (+{extra:.2f} µs/step)")


if __name__ == "__main__":
    main()
