"""Soak: a real ``fresco-bridge serve`` with 32 sites, one paced client each, for minutes.

Question: does a long run leak? Targets: bridge RSS growth <= 10 % after warm-up,
file descriptors flat, p99 per-message latency stable (per-minute windows).

Method: the bridge is its own process (``python -m fresco_bridge.cli serve``), 32 TCP sites
with an in-process elastic specimen, recording on (fsync ``background``), online monitors on
(the defaults). One asyncio client per site in this process steps at ``--rate`` steps/s: trial
(code 3), getForce (10, timed from send to full reply), commit (5); every force is checked
against k·d. Every ``--sample`` s the bridge's VmRSS and open fds are read from ``/proc``.
``tests/e2e/test_soak.py`` runs it for 60 s (as a subprocess) and checks the summary.

    .venv/bin/python -m benchmarks.bench_soak [--quick] [--minutes 10] [--sites 32]
        [--warmup 60] [--sample 2] [--workdir DIR] [--json FILE]

Feeds BENCHMARKS.md, "Fuzz and soak". ``--quick``: 20 s, 8 sites, 5 s warm-up, a smoke run.
``--workdir`` keeps the bridge's run directory and log there (default: a temporary directory).
"""

from __future__ import annotations

import argparse
import asyncio
import contextlib
import json
import math
import os
import re
import statistics
import subprocess
import sys
import tempfile
import textwrap
import time
from collections.abc import Iterator
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from protocol import NEED_DATA, Action, ElementClientSession, Signals, SizeID

K = 10.0
READY = re.compile(r"fresco-bridge ready: (.*)")


def config(sites: int, run_dir: Path) -> str:
    head = textwrap.dedent(f"""
        [bridge]
        run_dir = "{run_dir}"
        run_name = "soak"
        """)
    return head + "".join(textwrap.dedent(f"""
        [[sites]]
        name = "s{i:02d}"
        port = 0
        [sites.controller]
        model = "elastic"
        params = {{ k = {K} }}
        """) for i in range(sites))


def proc_rss(pid: int) -> int:
    with open(f"/proc/{pid}/status") as fh:
        for line in fh:
            if line.startswith("VmRSS:"):
                return int(line.split()[1]) * 1024
    raise RuntimeError("no VmRSS")


def proc_fds(pid: int) -> int:
    return len(os.listdir(f"/proc/{pid}/fd"))


@dataclass
class SoakResult:
    duration: float
    warmup: float
    sites: int
    rate: float
    steps: int = 0
    wrong: int = 0
    errors: list[str] = field(default_factory=list)
    samples: list[tuple[float, int, int]] = field(default_factory=list)  # (t, rss, fds)
    latencies: list[tuple[float, float]] = field(default_factory=list)  # (t, seconds)
    loads: list[tuple[float, float]] = field(default_factory=list)  # (t, 1-min load average)

    def after_warmup(self) -> list[tuple[float, int, int]]:
        return [s for s in self.samples if s[0] >= self.warmup]

    @property
    def rss_growth(self) -> float:
        """RSS at the end over RSS just after warm-up, minus one."""
        w = self.after_warmup()
        return w[-1][1] / w[0][1] - 1.0

    @property
    def fds(self) -> tuple[int, int, int]:
        """fds just after warm-up, the minimum and maximum after warm-up."""
        w = self.after_warmup()
        return w[0][2], min(s[2] for s in w), max(s[2] for s in w)

    def windows(self, width: float = 60.0) -> list[dict[str, float]]:
        """Latency p50/p99/max (ms), bridge fds (max) and machine load (mean of the 1-minute
        load average) per window after warm-up."""
        out = []
        start = self.warmup
        while start < self.duration - 1e-9:
            xs = sorted(v for t, v in self.latencies if start <= t < start + width)
            if len(xs) >= 10:
                win = {"from_s": start, "n": len(xs),
                       "p50_ms": 1e3 * xs[len(xs) // 2],
                       "p99_ms": 1e3 * xs[min(len(xs) - 1, int(0.99 * len(xs)))],
                       "max_ms": 1e3 * xs[-1]}
                fds = [f for t, _, f in self.samples if start <= t < start + width]
                loads = [v for t, v in self.loads if start <= t < start + width]
                if fds:
                    win["fds_max"] = max(fds)
                if loads:
                    win["load_1min"] = statistics.fmean(loads)
                out.append(win)
            start += width
        return out

    def summary(self) -> dict[str, Any]:
        w = self.after_warmup()
        return {
            "duration_s": self.duration, "warmup_s": self.warmup, "sites": self.sites,
            "rate_per_client": self.rate, "steps": self.steps, "wrong_forces": self.wrong,
            "errors": self.errors[:5],
            "rss_after_warmup_mib": round(w[0][1] / 2**20, 1),
            "rss_end_mib": round(w[-1][1] / 2**20, 1),
            "rss_max_mib": round(max(s[1] for s in w) / 2**20, 1),
            "rss_growth_pct": round(100 * self.rss_growth, 2),
            "fds_after_warmup_min_max": self.fds,
            "latency_windows": [{k: round(v, 3) for k, v in win.items()}
                                for win in self.windows()],
        }


async def _client(port: int, result: SoakResult, stop: float, t0: float, index: int) -> None:
    session = ElementClientSession(SizeID.for_generic_client(1, 1))
    reader, writer = await asyncio.open_connection("127.0.0.1", port)
    writer.write(session.start())
    period = 1.0 / result.rate
    step = 0
    next_at = time.monotonic() + (index % 10) * period / 10  # spread the clients
    try:
        while time.monotonic() < stop:
            await asyncio.sleep(max(0.0, next_at - time.monotonic()))
            next_at += period
            step += 1
            d = 2.0 * math.sin(0.01 * step + index)
            writer.write(session.send_trial(Signals(disp=(d,), vel=(0.0,), accel=(0.0,),
                                                    time=(0.01 * step,))))
            sent = time.monotonic()
            writer.write(session.send_request(Action.GET_FORCE))
            while True:
                ev = session.next_event()
                if ev is not NEED_DATA:
                    break
                data = await asyncio.wait_for(reader.read(65536), 30.0)
                if not data:
                    raise ConnectionError("the bridge closed the connection")
                session.receive_data(data)
            now = time.monotonic()
            result.latencies.append((now - t0, now - sent))
            force = ev.values[0]  # type: ignore[union-attr]
            if abs(force - K * d) > 1e-9 * max(1.0, abs(K * d)):
                result.wrong += 1
            writer.write(session.send_commit())
            result.steps += 1
        writer.write(session.send_die())
        await writer.drain()
    finally:
        writer.close()


async def _drive(ports: list[int], pid: int, result: SoakResult, sample: float) -> None:
    t0 = time.monotonic()
    stop = t0 + result.duration

    async def sampler() -> None:  # the last sample is taken before the clients leave
        while time.monotonic() < stop - 0.5:
            now = time.monotonic() - t0
            result.samples.append((now, proc_rss(pid), proc_fds(pid)))
            result.loads.append((now, os.getloadavg()[0]))
            await asyncio.sleep(min(sample, max(0.0, stop - 0.5 - time.monotonic())))

    tasks = [asyncio.create_task(_client(p, result, stop, t0, i)) for i, p in enumerate(ports)]
    tasks.append(asyncio.create_task(sampler()))
    for outcome in await asyncio.gather(*tasks, return_exceptions=True):
        if isinstance(outcome, BaseException):
            result.errors.append(f"{type(outcome).__name__}: {outcome}")


def soak(duration: float, *, sites: int = 32, rate: float = 20.0, warmup: float | None = None,
         sample: float = 2.0, workdir: Path | None = None) -> tuple[SoakResult, Path]:
    """Run the soak; returns the result and the run directory of the bridge."""
    work = workdir or Path(tempfile.mkdtemp(prefix="fresco-soak-"))
    cfg = work / "soak.toml"
    cfg.write_text(config(sites, work / "runs"), encoding="utf-8")
    result = SoakResult(duration, warmup if warmup is not None else min(60.0, duration / 4),
                        sites, rate)
    with serving(cfg, work) as (pid, ports):
        asyncio.run(_drive(ports, pid, result, sample))
    (run_dir,) = [p for p in (work / "runs").iterdir() if p.is_dir()]
    return result, run_dir


@contextlib.contextmanager
def serving(cfg: Path, work: Path) -> Iterator[tuple[int, list[int]]]:
    """``fresco-bridge serve --config cfg`` as its own process: (its pid, the sites' ports).

    Its log goes to ``work/bridge.log``; it is terminated on exit.
    """
    log = (work / "bridge.log").open("w")
    proc = subprocess.Popen([sys.executable, "-m", "fresco_bridge.cli", "serve", "--config",
                             str(cfg)], stdout=subprocess.PIPE, stderr=log, text=True)
    try:
        assert proc.stdout is not None
        line = proc.stdout.readline()
        m = READY.search(line)
        if m is None:
            raise RuntimeError(f"bridge did not start: {line!r} (see {work / 'bridge.log'})")
        yield proc.pid, [int(p.split("=")[1]) for p in m.group(1).split(", ")]
    finally:
        proc.terminate()
        proc.wait(30)
        log.close()


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--minutes", type=float, default=10.0)
    ap.add_argument("--sites", type=int, default=32)
    ap.add_argument("--rate", type=float, default=20.0, help="steps/s per client")
    ap.add_argument("--warmup", type=float, default=60.0, help="s")
    ap.add_argument("--sample", type=float, default=2.0, help="s between two RSS/fd samples")
    ap.add_argument("--workdir", type=Path, default=None,
                    help="keep the bridge's config, log and run directory here")
    ap.add_argument("--json", type=Path, default=None, help="also write the summary here")
    ap.add_argument("--quick", action="store_true", help="20 s, 8 sites, 5 s warm-up")
    args = ap.parse_args(argv)
    if args.quick:
        args.minutes, args.sites, args.warmup = min(args.minutes, 1 / 3), 8, 5.0
        args.sample = min(args.sample, 1.0)
    if args.workdir is not None:
        args.workdir.mkdir(parents=True, exist_ok=True)
    load_start = os.getloadavg()
    result, run_dir = soak(60.0 * args.minutes, sites=args.sites, rate=args.rate,
                           warmup=args.warmup, sample=args.sample, workdir=args.workdir)
    summary = result.summary()
    summary["run_dir"] = str(run_dir)
    summary["record_bytes"] = (run_dir / "record.jsonl").stat().st_size
    summary["load_average_start"] = load_start
    summary["load_average_end"] = os.getloadavg()
    text = json.dumps(summary, indent=2)
    print(text)
    if args.json is not None:
        args.json.write_text(text + "\n", encoding="utf-8")
    p99 = [w["p99_ms"] for w in summary["latency_windows"]]
    if p99:
        print(f"p99 per window (ms): {p99}; median of windows "
              f"{statistics.median(p99):.2f}, max/min {max(p99) / min(p99):.2f}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
