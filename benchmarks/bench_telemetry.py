"""Demo steps/s with live telemetry (real Mosquitto) on vs off, alternating in one process run.

Why: telemetry must never slow the test (target: at most 10 % slower with telemetry on).
Each run is the demo's own loop: the explicit-Newmark two-story frame drives the bridge's
``damper`` site (``BridgeThread``, in-process bilinear damper, run record on) over loopback
TCP with ``GenericClientLink``, exactly as ``fresco-bridge demo`` does, minus the plotting.

Variants (each run gets a fresh bridge and a fresh run directory):

- ``off``: the demo's default config: no MQTT, no metrics; online monitors on and recorded.
- ``mqtt``: ``telemetry.mqtt_host = 127.0.0.1`` (real Mosquitto on 1883), every step published.
- ``mqtt+metrics``: plus the Prometheus endpoint (``metrics_port = 0``).
- ``bare``: ``monitors = false`` (no step taps at all), to price the monitors themselves.

Variants take turns within each round (rotating the order each round). The table gives the
median and [min - max] steps/s over the rounds, the ratio of medians, the median over rounds
of variant/off *in the same round* (the verdict: pairing cancels the load drift of a shared
machine), the ratio of the best runs, and the process CPU per step (client + bridge threads).

Then, in isolation (no bridge, no client thread, so no GIL sharing and far less noise): one
event loop feeds 20000 step samples (monitor included) to ``MqttTelemetry`` (real broker, every
message published) and to ``NullTelemetry``, alternating, 7 rounds; the CPU difference per
step is what telemetry itself costs the bridge's loop.

    python -m benchmarks.bench_telemetry [--quick] [--rounds 40] [--duration 10]

Feeds BENCHMARKS.md, "Telemetry". ``--quick``: one round of 2 s runs and one isolated round of
2000 samples, a smoke run. Without Mosquitto the MQTT variants are skipped (said on stdout).
"""

from __future__ import annotations

import argparse
import asyncio
import math
import os
import shutil
import socket
import statistics
import subprocess
import tempfile
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from benchmarks.bench_opensees_bridge import machine_info
from fresco_bridge.config import parse_config
from fresco_bridge.daemon import BridgeThread
from fresco_bridge.demo import demo_config_text
from fresco_bridge.indicators import OnlineMonitor
from fresco_bridge.integrator import (
    DEMO_DT,
    demo_frame_integrator,
    demo_site_coupling,
    kanai_tajimi,
    run_coupled,
)
from fresco_bridge.integrator.link import GenericClientLink
from fresco_bridge.telemetry import MqttTelemetry, NullTelemetry, StepSample, Telemetry

BROKER = ("127.0.0.1", 1883)
TARGET_SLOWDOWN = 0.10
PRIMARY = "mqtt"


@dataclass(frozen=True)
class Variant:
    name: str
    telemetry_toml: str
    needs_broker: bool = False


VARIANTS = (
    Variant("off", ""),
    Variant("mqtt", 'mqtt_host = "127.0.0.1"\nprefix = "{prefix}"', needs_broker=True),
    Variant("mqtt+metrics", 'mqtt_host = "127.0.0.1"\nprefix = "{prefix}"\nmetrics_port = 0',
            needs_broker=True),
    Variant("bare", "monitors = false"),
)


def broker_up() -> bool:
    """Mosquitto on 127.0.0.1:1883, started (daemonised) if it is installed but not running."""
    def reachable() -> bool:
        try:
            socket.create_connection(BROKER, timeout=1).close()
            return True
        except OSError:
            return False

    if reachable():
        return True
    if shutil.which("mosquitto") is None:
        return False
    subprocess.run(["mosquitto", "-d", "-c", "/etc/mosquitto/mosquitto.conf"], check=False)
    deadline = time.monotonic() + 5
    while time.monotonic() < deadline:
        if reachable():
            return True
        time.sleep(0.1)
    return False


def run_variant(v: Variant, duration: float, root: Path) -> dict[str, Any]:
    """One demo run; returns steps/s (timed around the integrator loop) and telemetry stats."""
    text = demo_config_text("tcp", run_name=f"bench-{v.name.replace('+', '-')}")
    if v.telemetry_toml:
        prefix = f"fb-bench-{os.getpid()}"
        text += "\n[telemetry]\n" + v.telemetry_toml.format(prefix=prefix) + "\n"
    cfg = parse_config(text, f"<bench {v.name}>")
    motion = kanai_tajimi(3.0, duration=duration, dt=DEMO_DT, seed=1)
    with BridgeThread(cfg, text, run_dir=root) as bridge:
        tel = bridge.bridge.telemetry
        if tel is not None:  # time the steady state, not the first connection
            deadline = time.monotonic() + 10
            while not bridge.call(lambda: tel.stats.connected):
                if time.monotonic() > deadline:
                    raise RuntimeError("telemetry never connected to the broker")
                time.sleep(0.02)
        link = GenericClientLink("127.0.0.1", bridge.ports["damper"], 2, timeout=10.0)
        coupling = demo_site_coupling(link)
        integ = demo_frame_integrator(coupling, motion)
        with link:
            b0, k0 = bridge.call(time.thread_time), broker_cpu()
            t0, c0 = time.perf_counter(), time.process_time()
            run_coupled(integ, coupling)
            wall, cpu = time.perf_counter() - t0, time.process_time() - c0
            bridge_cpu, broker = bridge.call(time.thread_time) - b0, broker_cpu() - k0
    stats = tel.stats if tel is not None else None  # final: the bridge has drained and stopped
    return {"steps": integ.n_steps, "steps_per_s": integ.n_steps / wall,
            "cpu_us_per_step": 1e6 * cpu / integ.n_steps,
            "bridge_us_per_step": 1e6 * bridge_cpu / integ.n_steps,
            "broker_us_per_step": 1e6 * broker / integ.n_steps, "stats": stats}


def broker_cpu() -> float:
    """CPU seconds used so far by every running ``mosquitto`` (from /proc; 0 if none)."""
    total = 0.0
    tick = os.sysconf("SC_CLK_TCK")
    for stat in Path("/proc").glob("[0-9]*/stat"):
        try:
            text = stat.read_text()
        except OSError:
            continue
        if "(mosquitto)" in text:
            fields = text.rsplit(")", 1)[1].split()
            total += (int(fields[11]) + int(fields[12])) / tick  # utime + stime
    return total


async def _tap_cost(tel: Telemetry, n: int) -> float:
    """Process CPU µs per step of a loop feeding ``tel`` like a site does (monitor included)."""
    task = asyncio.create_task(tel.run())
    deadline = time.monotonic() + 10
    while isinstance(tel, MqttTelemetry) and not tel.stats.connected:
        if time.monotonic() > deadline:
            raise RuntimeError("telemetry never connected to the broker")
        await asyncio.sleep(0.01)
    monitor = OnlineMonitor(DEMO_DT)
    c0 = time.process_time()
    for i in range(n):
        x = math.sin(0.01 * i)
        tel.publish_step(StepSample("damper", 1, i, DEMO_DT * i, (0.0, x), (x,), (x,), (8.0 * x,),
                                    "RUNNING", None, monitor.update(x, x)))
        if i % 4 == 0:
            await asyncio.sleep(0)  # the loop turns between steps, as between client requests
    tel.stop()
    await task
    cpu = time.process_time() - c0
    if isinstance(tel, MqttTelemetry) and tel.stats.published != n:
        raise RuntimeError(f"not every step was published: {tel.stats}")
    return 1e6 * cpu / n


def isolated_cost(rounds: int, n: int = 20000) -> str:
    """The telemetry's own CPU per step: MQTT vs NullTelemetry, same loop, alternating."""
    async def all_rounds() -> tuple[list[float], list[float]]:
        null, mqtt = [], []
        for _ in range(rounds):
            null.append(await _tap_cost(NullTelemetry(), n))
            mqtt.append(await _tap_cost(MqttTelemetry(  # a queue for all: the cost, not drops
                host=BROKER[0], port=BROKER[1], prefix=f"fb-bench-{os.getpid()}",
                queue_size=n), n))
        return null, mqtt

    null, mqtt = asyncio.run(all_rounds())
    a, b = statistics.median(null), statistics.median(mqtt)
    rounds_txt = ", ".join(f"{y - x:.1f}" for x, y in zip(null, mqtt, strict=True))
    return (f"\nisolated, {n} steps x {rounds} rounds (one event loop, no bridge): NullTelemetry "
            f"{a:.2f} CPU µs/step, MqttTelemetry {b:.2f} -> telemetry costs {b - a:.2f} CPU µs "
            f"per step [per round: {rounds_txt}]")


Samples = dict[str, list[tuple[float, float, float, float]]]
"""variant -> per round (steps/s, process CPU, bridge-thread CPU, broker CPU; µs/step)"""


def run_benchmark(rounds: int, duration: float) -> Samples:
    variants = list(VARIANTS)
    have_broker = broker_up()
    if not have_broker:
        print("no Mosquitto on 127.0.0.1:1883 and none could be started: MQTT variants skipped",
              flush=True)
        variants = [v for v in variants if not v.needs_broker]
    samples: Samples = {v.name: [] for v in variants}
    with tempfile.TemporaryDirectory(prefix="fb-bench-telemetry-") as tmp:
        for r in range(rounds):
            order = variants[r % len(variants):] + variants[: r % len(variants)]
            for v in order:
                res = run_variant(v, duration, Path(tmp) / f"{r}-{v.name}")
                samples[v.name].append((res["steps_per_s"], res["cpu_us_per_step"],
                                        res["bridge_us_per_step"], res["broker_us_per_step"]))
                st = res["stats"]
                extra = "" if st is None else (
                    f"  published {st.published}, dropped {st.dropped}, queued {st.queued}")
                print(f"round {r + 1} {v.name:<13} {res['steps']} steps  "
                      f"{res['steps_per_s']:8.0f} steps/s  "
                      f"CPU µs/step: process {res['cpu_us_per_step']:6.1f}, bridge "
                      f"{res['bridge_us_per_step']:6.1f}, broker {res['broker_us_per_step']:5.1f}"
                      f"{extra}", flush=True)
    return samples


def summarize(samples: Samples) -> str:
    def med(name: str, i: int) -> float:
        return statistics.median(x[i] for x in samples[name])

    def paired(name: str) -> float:
        """Median over rounds of (variant / off) in the same round: load drifts cancel."""
        return statistics.median(
            x[0] / o[0] for x, o in zip(samples[name], samples["off"], strict=True))

    base, base_cpu = med("off", 0), med("off", 1)
    best = max(x[0] for x in samples["off"])
    lines = ["", "| variant | steps/s median | [min - max] | ratio of medians | median of "
             "per-round ratios | ratio of bests | process CPU µs/step | − off | bridge thread "
             "CPU µs/step | − off | broker CPU µs/step (mean: 10 ms ticks) |",
             "|---|---|---|---|---|---|---|---|---|---|---|"]
    for name, xs in samples.items():
        rates = [x[0] for x in xs]
        lines.append(f"| {name} | {med(name, 0):.0f} | [{min(rates):.0f} - {max(rates):.0f}] | "
                     f"{med(name, 0) / base:.3f} | {paired(name):.3f} | {max(rates) / best:.3f} | "
                     f"{med(name, 1):.1f} | {med(name, 1) - base_cpu:+.1f} | {med(name, 2):.1f} | "
                     f"{med(name, 2) - med('off', 2):+.1f} | "
                     f"{statistics.fmean(x[3] for x in xs):.1f} |")
    if PRIMARY in samples:
        slowdown = 1.0 - paired(PRIMARY)
        verdict = "MET" if slowdown <= TARGET_SLOWDOWN else "NOT met"
        lines.append(f"\ntelemetry on ({PRIMARY}) is {100 * slowdown:.1f} % slower than off "
                     f"(median of per-round ratios; target <= {100 * TARGET_SLOWDOWN:.0f} %): "
                     f"{verdict}")
    return "\n".join(lines)


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(prog="benchmarks.bench_telemetry", description=__doc__,
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--rounds", type=int, default=40)
    parser.add_argument("--duration", type=float, default=10.0,
                        help="seconds of synthetic ground motion per run (dt 0.01 s)")
    parser.add_argument("--quick", action="store_true", help="one round of 2 s runs")
    args = parser.parse_args(argv)
    if args.quick:
        args.rounds, args.duration = 1, min(args.duration, 2.0)
    info = machine_info()
    print(f"demo loop, {args.duration:g} s record ({round(args.duration / DEMO_DT) + 1} steps), "
          f"{args.rounds} rounds; " + "; ".join(f"{k}: {v}" for k, v in info.items()), flush=True)
    print(summarize(run_benchmark(args.rounds, args.duration)), flush=True)
    if broker_up():
        print(isolated_cost(1, 2000) if args.quick else isolated_cost(7), flush=True)


if __name__ == "__main__":
    main()
