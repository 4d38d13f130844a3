"""A twin that lives as long as the test: a real ``fresco-bridge serve`` (record on) with a sim
bilinear source and its ``online_improved`` twin (previous-step), driven over TCP.

* ``long`` (default): one N-step source + twin session (a long synthetic displacement: a sine
  whose amplitude sweeps 0.5-4 mm, yield at 0.75 mm). Per tenth of the run: the twin's update
  time p99 (the record's update lines), the twin's trial + force round trip p50, and the RSS of
  the bridge and its learner worker. Then ``kill -9`` and ``serve --resume``: seconds to the
  ready line, from the learner's checkpoint and (``--without-checkpoint``) with the checkpoint
  removed (the whole record replayed). Targets: no HOLD, no NaN; p99 last tenth <= 1.5x the
  first; RSS growth <= 20 MB; ready-after-resume <= 5 s.
* ``catch-up``: ten source-only sessions of 2,500 steps, then a source + twin session: the
  twin answers from step 1, each answer within the learner's deadline (2 s); how many of its
  answers were learned through less than they asked for (``upto``, ``twins/catchup.py``) and
  where it caught up.

Everything (the client, the bridge and its learner worker) runs on CPU 1 when the machine has
it, as under ``taskset -c 1``.

    python -m benchmarks.bench_twin_long [--steps 100000] [--without-checkpoint]
    python -m benchmarks.bench_twin_long catch-up

Feeds BENCHMARKS.md, "Updatable sites".
"""

from __future__ import annotations

import argparse
import math
import os
import signal
import subprocess
import tempfile
import time
from pathlib import Path

import numpy as np

from benchmarks.bench_opensees_bridge import process_rss_mb
from benchmarks.bench_twin import _offline_csv, _pin
from fresco_bridge.integrator.link import GenericClientLink
from fresco_bridge.record.export import read_record
from protocol import Action
from tests.support.serve import source_and_twin, start_cli, started, workers_of

NANS: list[int] = []
"""The steps the twin answered NaN at (``drive(nan_ok=True)``)."""


def lab(folder: Path, updater: str, deadline: float) -> Path:
    """The source (sim bilinear, yield at 0.75 mm) and its ``updater`` twin with the offline
    database of ``bench_twin`` (``deadline``: the learner's; the controller timeout 2.5x it)."""
    offline = _offline_csv(folder / "offline.csv")
    path = source_and_twin(folder / "lab.toml", folder / "runs", "long", updater=updater,
                           fy=15.0, twin=f'offline = "{offline}"\nlearner_deadline = {deadline}\n')
    path.write_text(path.read_text().replace(
        'run_name = "long"\n', f'run_name = "long"\ncontroller_timeout = {2.5 * deadline}\n', 1))
    return path


def serve(folder: Path, *args: str) -> tuple[subprocess.Popen[str], tuple[int, ...], float]:
    """A bridge process, its ports and the seconds it took to print its ready line."""
    start = time.perf_counter()
    log = folder / f"serve-{time.monotonic_ns()}.log"
    proc = start_cli(folder, "serve", *args, stderr=log)
    ports, _ = started(proc, deadline=600, log=log)  # says why a bridge did not start
    return proc, ports, time.perf_counter() - start


def worker_of(pid: int) -> int | None:
    return next(iter(workers_of(pid)), None)


def disp(i: int) -> float:
    amplitude = 0.5 + 3.5 * 0.5 * (1 - math.cos(2 * math.pi * i / 3000))
    return amplitude * math.sin(2 * math.pi * i / 50)


def drive(ports: tuple[int, ...], steps: int, *, twin: bool, sample: int = 0,
          on_sample: object = None, pace: float = 0.0, nan_ok: bool = False) -> list[float]:
    """``steps`` source (+ twin) steps, one every ``pace`` s at most; the twin's trial + force
    round trips (s). A NaN answer of the twin raises RuntimeError (``nan_ok``: is counted in
    ``NANS`` and the run goes on)."""
    trips: list[float] = []
    start = time.perf_counter()
    with GenericClientLink("127.0.0.1", ports[0], 1, data_size=1) as source:
        link = GenericClientLink("127.0.0.1", ports[1], 1, data_size=1).connect() if twin \
            else None
        for i in range(1, steps + 1):
            d = disp(i)
            source.set_trial((d,), time=0.01 * i)
            source.force()
            if link is not None:
                t0 = time.perf_counter()
                link.set_trial((0.8 * d,), time=0.01 * i)
                f = link.force()
                trips.append(time.perf_counter() - t0)
                if not math.isfinite(f[0]):
                    if not nan_ok:
                        raise RuntimeError(f"the twin answered {f} at step {i}")
                    NANS.append(i)
            source.commit()
            if link is not None:
                link.commit()
            if sample and i % sample == 0 and callable(on_sample):
                on_sample(i)
            if pace:
                time.sleep(max(0.0, start + pace * i - time.perf_counter()))
        if link is not None:
            link.request(Action.GET_DISP)
            link.close()
    return trips


def long_run(steps: int, without_checkpoint: bool, deadline: float) -> None:
    updater = "online_improved"
    with tempfile.TemporaryDirectory(prefix="bench-twin-long-") as tmp:
        folder = Path(tmp)
        cfg = lab(folder, updater, deadline)
        proc, ports, ready = serve(folder, "--config", str(cfg))
        worker = worker_of(proc.pid)
        print(f"start: ready in {ready:.2f} s; {steps} steps, online_improved previous-step, "
              f"learner deadline {deadline:g} s")
        rss: list[tuple[float, float]] = []

        def sample(_i: int) -> None:
            rss.append((process_rss_mb(proc.pid), process_rss_mb(worker or 0)))

        sample(0)
        t0 = time.perf_counter()
        try:
            trips = np.asarray(drive(ports, steps, twin=True, sample=steps // 10,
                                     on_sample=sample, nan_ok=True)) * 1e6
        except RuntimeError as exc:
            _failed(folder, exc)
        wall = time.perf_counter() - t0
        proc.send_signal(signal.SIGKILL)
        proc.wait(30)
        (run,) = [p for p in (folder / "runs").iterdir() if p.is_dir()]
        read = time.perf_counter()
        lines = list(read_record(run))
        read = time.perf_counter() - read
        secs = np.array([float(r["secs"]) for r in lines
                         if r["kind"] == "update" and r.get("site") == "twin1"]) * 1e3
        holds = [r for r in lines if r["kind"] == "event" and "hold" in str(r.get("event"))]
        lost = [r for r in lines if r["kind"] == "event" and "learner" in str(r.get("event"))]
        tenth = max(secs.size // 10, 1)
        p99 = [float(np.percentile(secs[k * tenth:(k + 1) * tenth], 99)) for k in range(10)]
        trip = [float(np.median(trips[k * (trips.size // 10):(k + 1) * (trips.size // 10)]))
                for k in range(10)]
        print(f"{wall:.0f} s ({1e3 * wall / steps:.2f} ms/step); HOLD events {len(holds)}, "
              f"learner events {len(lost)}; update lines {secs.size}; NaN answers "
              f"{len(NANS)} (from step {NANS[0] if NANS else '-'})")
        for r in lost + holds:
            print(f"  {r.get('event')}: {r.get('reason')}")
        print("update time p99 per tenth (ms): " + " ".join(f"{v:.2f}" for v in p99))
        print(f"  last / first tenth: {p99[-1] / p99[0]:.2f} (target <= 1.5)")
        print("twin trial + force p50 per tenth (us): " + " ".join(f"{v:.0f}" for v in trip))
        print(f"  whole run p50 {float(np.median(trips)):.0f} us, p99 "
              f"{float(np.percentile(trips, 99)):.0f} us")
        print("RSS MB bridge / worker per tenth: "
              + " ".join(f"{b:.0f}/{w:.0f}" for b, w in rss))
        grow = [rss[-1][k] - rss[1][k] for k in (0, 1)]
        print(f"  growth after the first tenth: bridge {grow[0]:+.1f}, worker {grow[1]:+.1f} MB "
              "(target <= 20)")
        checkpoint = run / "learner-damper.checkpoint"
        size = checkpoint.stat().st_size if checkpoint.exists() else 0
        print(f"record {(run / 'record.jsonl').stat().st_size / 1e6:.1f} MB (one pass of "
              f"read_record: {read:.2f} s), checkpoint "
              f"{size / 1e3:.0f} kB")
        variants = [("from the checkpoint", False)] + ([("whole record replayed", True)]
                                                       if without_checkpoint else [])
        for name, remove in variants:
            if remove:
                checkpoint.unlink(missing_ok=True)
            begun = time.time()
            second, ports, ready = serve(folder, "--config", str(cfg), "--resume", str(run))
            print(f"ready-after-resume, {name}: {ready:.2f} s (target <= 5)", flush=True)
            print("  its log, s after the start: " + milestones(folder, begun))
            NANS.clear()
            drive(ports, 5, twin=True, nan_ok=True)
            second.send_signal(signal.SIGKILL)
            second.wait(30)
            print(f"  then 5 steps: the twin answered NaN at {len(NANS)} of them")


MILESTONES = {"specimen restored": "one pass over the record read",
              "resumes from its checkpoint": "checkpoint cut", "RESUMED": "resume point",
              "live (twins": "worker live"}


def milestones(folder: Path, begun: float) -> str:
    """When the newest bridge log says each resume milestone (its lines' wall times)."""
    log = max(folder.glob("serve-*.log"), key=lambda p: p.stat().st_mtime)
    out = []
    for line in log.read_text().splitlines():
        for key, name in MILESTONES.items():
            if key in line:
                stamp = time.mktime(time.strptime(line[:19], "%Y-%m-%d %H:%M:%S"))
                out.append(f"{name} {stamp + int(line[20:23]) / 1e3 - begun:.2f}")
    return ", ".join(out)


def _failed(folder: Path, exc: Exception) -> None:
    print(f"FAILED: {exc}; the bridge's log:")
    for log in folder.glob("serve-*.log"):
        print("".join(log.read_text().splitlines(keepends=True)[-15:]))
    raise exc


def catch_up(sessions: int, steps: int, pace: float, updater: str, deadline: float) -> None:
    with tempfile.TemporaryDirectory(prefix="bench-twin-catch-up-") as tmp:
        folder = Path(tmp)
        cfg = lab(folder, updater, deadline)
        proc, ports, _ = serve(folder, "--config", str(cfg))
        try:
            for _ in range(sessions):
                drive(ports, steps, twin=False, pace=pace)
            trips = np.asarray(drive(ports, 200, twin=True)) * 1e3
        except RuntimeError as exc:
            _failed(folder, exc)
        finally:
            proc.send_signal(signal.SIGTERM)
            proc.wait(60)
        (run,) = [p for p in (folder / "runs").iterdir() if p.is_dir()]
        lines = list(read_record(run))
        updates = [r for r in lines if r["kind"] == "update" and r.get("site") == "twin1"]
        behind = [r for r in updates if "upto" in r]
        caught = [r for r in lines if r.get("event") == "learner-caught-up"]
        print(f"{updater}: {sessions} source-only sessions of {steps} steps (one every "
              f"{1e3 * pace:g} ms at most), then a pair of 200 steps: "
              f"the twin answered every step; first answer {trips[0]:.1f} ms, max "
              f"{float(trips.max()):.1f} ms, p50 {float(np.median(trips)):.2f} ms "
              f"(deadline {1e3 * deadline:g} ms)")
        first = behind[0]["upto"] if behind and behind[0]["step"] == 1 else None
        print(f"  answers learned through less than asked (upto): {len(behind)} of "
              f"{len(updates)}; step 1 learned through source {first or 'all it asked'}; "
              f"last: {behind[-1]['upto'] if behind else '-'}; caught up at twin step "
              f"{caught[0].get('step', '?') if caught else '-'} "
              f"({caught[0]['reason'] if caught else 'not within the pair'})")


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("mode", nargs="?", default="long", choices=("long", "catch-up"))
    parser.add_argument("--steps", type=int, default=100_000)
    parser.add_argument("--without-checkpoint", action="store_true",
                        help="also resume with the checkpoint removed")
    parser.add_argument("--sessions", type=int, default=10)
    parser.add_argument("--session-steps", type=int, default=2500)
    parser.add_argument("--pace", type=float, default=0.0, help="catch-up: ms per source step")
    parser.add_argument("--updater", default="online_improved", help="catch-up: the updater")
    parser.add_argument("--learner-deadline", type=float, default=2.0,
                        help="s (the default's); the controller timeout is 2.5x it")
    args = parser.parse_args(argv)
    _pin(1)
    print(f"load average {os.getloadavg()[0]:.1f}")
    if args.mode == "long":
        long_run(args.steps, args.without_checkpoint, args.learner_deadline)
    else:
        catch_up(args.sessions, args.session_steps, args.pace / 1e3, args.updater,
                 args.learner_deadline)


if __name__ == "__main__":
    main()
