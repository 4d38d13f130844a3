"""Step cost: the bridge against the fastest simple server, same run, pinned and unpinned.

Why: the bridge must not be the bottleneck of a hybrid test (targets: within 1.3× of a bare
socket server in ms/step and 2.0× in server CPU per step, record on with the default
durability; a 64-DOF element within 1.5×; ≤ 500 record bytes per committed step; flat memory
over 200 000 steps). Every party is its own process (``benchmarks/_step_peers.py``): a real
OpenSeesPy ``genericClient`` or a scripted client, and either ``fresco-bridge serve`` or the
blocking reference server.

Method: each round runs every variant once, in an order that reverses every round (drifting
load hits bridge and reference alike); ``pinned`` rounds start every process under
``taskset -c 1`` (server and client share one CPU: the stable comparison), ``unpinned`` rounds
let the scheduler place them. Reported per variant: ms/step (median, [min – max] over rounds),
server CPU per step (user + system of the server process from ``/proc``), step p50/p99/p99.9
and, for the scripted clients, per-message latency percentiles; the verdict uses the ratio of
medians and the median of the per-round ratios. Each round also times a fixed pure-Python
workload pinned to CPU 1 (``calibration``, the machine's fast or slow mode) and the load
average, since this machine is shared.

    python -m benchmarks.bench_opensees_bridge [--quick] [--rounds 3] [--unpinned-rounds 5]
        [--steps 2000] [--no-64] [--profile FILE]
    python -m benchmarks.bench_opensees_bridge rss [--rss-steps 200000]

Feeds BENCHMARKS.md, "Step cost and scaling" (and the RSS mode), "Multi-DOF elements" (the
64-DOF variants), "Record size and durability" (record bytes per step). ``--quick``: one pinned
round of 200 steps (100 at 64 DOF; RSS over 2000 steps), a smoke run.
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import os
import signal
import statistics
import subprocess
import sys
import tempfile
import threading
import time
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from fresco_bridge.opensees_runtime import OpenSeesUnavailable
from fresco_bridge.opensees_runtime import opensees_env as runtime_env

REPO = Path(__file__).resolve().parents[1]
PEERS = "benchmarks._step_peers"
STEPS = 2000
STEPS_64 = 300
RSS_STEPS = 200_000
TARGET_RATIO = 1.3
TARGET_CPU_RATIO = 2.0
TARGET_RATIO_64 = 1.5
TARGET_BYTES_PER_STEP = 500
TARGET_RSS_GROWTH = 0.05
RUN_TIMEOUT = 900.0
PIN = ("taskset", "-c", "1")


class BenchmarkError(RuntimeError):
    """A benchmark process failed or did not report a result."""


@dataclass(frozen=True)
class Variant:
    """One server configuration and the client that drives it."""

    name: str
    server: str  # "reference", "bridge" or "none" (OpenSees alone)
    client: str = "opensees"  # or "scripted"
    dofs: int = 1
    model: str = "bilinear"
    record: bool = True
    fsync: str | None = None  # None: the default durability
    sync_interval: float | None = None  # None: the default record.sync_interval
    steps: int = STEPS
    tree: str | None = None  # another checkout's fresco_bridge (before/after in one run)
    event_loop: str | None = None  # None: the default ([bridge] event_loop)


REFERENCE = Variant("reference (blocking + QUICKACK)", "reference")
BRIDGE = Variant("bridge: record on, default durability", "bridge")
SCRIPTED_REF = Variant("scripted 1-DOF: reference", "reference", client="scripted")
SCRIPTED_BRIDGE = Variant("scripted 1-DOF: bridge", "bridge", client="scripted")
VARIANTS = (
    REFERENCE,
    BRIDGE,
    Variant("bridge: record on, fsync inline", "bridge", fsync="inline"),
    Variant("bridge: record off", "bridge", record=False),
    Variant("bridge: record on, asyncio loop", "bridge", event_loop="asyncio"),
    SCRIPTED_REF,
    SCRIPTED_BRIDGE,
    Variant("OpenSees alone (zeroLength, no socket)", "none"),
)
REF_64 = Variant("scripted 64-DOF: reference", "reference", client="scripted", dofs=64,
                 steps=STEPS_64)
BRIDGE_64 = Variant("scripted 64-DOF: bridge (elastic)", "bridge", client="scripted", dofs=64,
                    model="elastic", steps=STEPS_64)
PAIRS = ((BRIDGE, REFERENCE), (SCRIPTED_BRIDGE, SCRIPTED_REF), (BRIDGE_64, REF_64))


def opensees_env() -> dict[str, str]:
    """The peers' environment: OpenSeesPy's bundled BLAS/LAPACK on the loader path
    (``fresco_bridge.opensees_runtime``, the one home) and this repository importable."""
    try:
        env = runtime_env()
    except OpenSeesUnavailable as exc:
        raise BenchmarkError(str(exc)) from None
    env["PYTHONPATH"] = f"{REPO}:{env.get('PYTHONPATH', '')}".rstrip(":")
    return env


def bridge_config(variant: Variant, run_dir: Path) -> str:
    """Lab TOML for one site serving the element with a simulated specimen."""
    params = ("{ k = 100.0 }" if variant.model == "elastic"
              else "{ k0 = 100.0, fy = 20.0, alpha = 0.02 }")
    fsync = "" if variant.fsync is None else f'fsync = "{variant.fsync}"\n'
    if variant.sync_interval is not None:
        fsync += f"sync_interval = {variant.sync_interval!r}\n"
    loop = "" if variant.event_loop is None else f'event_loop = "{variant.event_loop}"\n'
    return f"""
[bridge]
run_name = "bench"
run_dir = {json.dumps(str(run_dir))}
{loop}
[record]
enabled = {"true" if variant.record else "false"}
{fsync}
[[sites]]
name = "spec"
port = 0
dofs = {variant.dofs}
setup = "NoTransformation"
[sites.controller]
kind = "sim"
model = "{variant.model}"
params = {params}
"""


def code_origin(tree: str | None) -> str:
    """Which step-path code a bridge server of this tree runs: compiled or pure, and from where
    (a ``--compare-tree`` serves its own pure sources only if they come first on the path)."""
    env = opensees_env()
    if tree is not None:
        env["PYTHONPATH"] = f"{tree}:{env['PYTHONPATH']}"
    code = ("import fresco_bridge.cli, protocol.element as e, fresco_bridge.sites.experimental "
            "as x; print(e.__file__, x.__file__)")
    with tempfile.TemporaryDirectory() as work:
        out = subprocess.run([sys.executable, "-c", code], cwd=work, env=env, text=True,
                             capture_output=True, check=True).stdout.split()
    kind = "pure" if all(f.endswith(".py") for f in out) else "compiled"
    return f"{kind}: {', '.join(out)}"


def _await_line(proc: subprocess.Popen[str], prefix: str) -> str:
    assert proc.stdout is not None
    for line in proc.stdout:
        if line.startswith(prefix):
            return line[len(prefix):].strip()
    err = proc.stderr.read() if proc.stderr else ""
    raise BenchmarkError(f"server exited before printing {prefix!r} (rc {proc.wait()}): "
                         f"{err[-1500:]}")


def _start_server(variant: Variant, work: Path, pin: bool, profile: Path | None = None
                  ) -> tuple[subprocess.Popen[str], int]:
    pre = list(PIN) if pin else []
    if variant.server == "reference":
        cmd = [*pre, sys.executable, "-m", PEERS, "reference-server"]
        prefix = "reference ready: "
    else:
        cfg = work / "bench.toml"
        cfg.write_text(bridge_config(variant, work / "runs"))
        prof = ["-m", "cProfile", "-o", str(profile)] if profile else []
        cmd = [*pre, sys.executable, *prof, "-m", "fresco_bridge.cli", "serve", "--config",
               str(cfg)]
        prefix = "fresco-bridge ready: spec="
    env = opensees_env()
    if variant.tree is not None:
        env["PYTHONPATH"] = f"{variant.tree}:{env['PYTHONPATH']}"
    proc = subprocess.Popen(cmd, cwd=work, env=env, stdout=subprocess.PIPE,
                            stderr=subprocess.PIPE, text=True)
    try:
        port = int(_await_line(proc, prefix))
    except BaseException:
        proc.kill()
        proc.wait()
        raise
    return proc, port


def process_cpu_seconds(pid: int) -> float:
    """CPU a process (all its threads) has used so far (Linux /proc), 0.0 where unavailable.

    Summed from each thread's ``schedstat`` (nanoseconds) where the kernel has it: ``stat``
    counts clock ticks (10 ms), i.e. 5 µs per step of a 2000-step run, coarser than the
    differences measured."""
    try:
        return sum(int(Path(task, "schedstat").read_text().split()[0])
                   for task in Path(f"/proc/{pid}/task").iterdir()) / 1e9
    except (OSError, ValueError, IndexError):
        pass
    try:
        fields = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()
    except OSError:
        return 0.0
    return (int(fields[11]) + int(fields[12])) / os.sysconf("SC_CLK_TCK")


def process_rss_mb(pid: int) -> float:
    """Resident set size of a process in MB (Linux /proc), 0.0 where unavailable."""
    try:
        for line in Path(f"/proc/{pid}/status").read_text().splitlines():
            if line.startswith("VmRSS:"):
                return int(line.split()[1]) / 1024.0
    except OSError:
        pass
    return 0.0


def _client_cmd(variant: Variant, port: int | None, pin: bool, steps: int) -> list[str]:
    pre = list(PIN) if pin else []
    role = "scripted-client" if variant.client == "scripted" else "opensees-client"
    cmd = [*pre, sys.executable, "-m", PEERS, role, "--steps", str(steps), "--dofs",
           str(variant.dofs)]
    return cmd + (["--port", str(port)] if port is not None else [])


def _run_client(cmd: list[str], on_progress: Any = None) -> dict[str, Any]:
    proc = subprocess.Popen(cmd, cwd=REPO, env=opensees_env(), stdout=subprocess.PIPE,
                            stderr=subprocess.PIPE, text=True)
    result: dict[str, Any] | None = None
    timer = threading.Timer(RUN_TIMEOUT, proc.kill)
    timer.start()
    try:
        assert proc.stdout is not None
        for line in proc.stdout:
            if line.startswith("PROGRESS ") and on_progress is not None:
                on_progress(int(line.split()[1]))
            elif line.startswith("RESULT "):
                result = json.loads(line[len("RESULT "):])
        err = proc.stderr.read() if proc.stderr else ""
        rc = proc.wait()
    finally:
        timer.cancel()
    if rc != 0 or result is None:
        raise BenchmarkError(f"client failed (rc {rc}): {err[-1500:]}")
    return result


def record_bytes_per_commit(run_root: Path) -> tuple[float, int] | None:
    """Size of the run record over its committed steps (None: no record)."""
    from fresco_bridge.record.export import read_record

    records = sorted(run_root.glob("*/record.jsonl"))
    if not records:
        return None
    path = records[-1]
    commits = sum(1 for r in read_record(path) if r["kind"] == "commit")
    return (path.stat().st_size / commits if commits else float("nan")), commits


def run_variant(variant: Variant, pin: bool, profile: Path | None = None,
                steps: int | None = None, on_progress: Any = None) -> dict[str, Any]:
    """One client run against a fresh server process of this variant."""
    steps = variant.steps if steps is None else steps
    if variant.server == "none":
        return _run_client(_client_cmd(variant, None, pin, steps))
    with tempfile.TemporaryDirectory(prefix="fb-bench-") as tmp:
        proc, port = _start_server(variant, Path(tmp), pin, profile)
        try:
            cpu0 = process_cpu_seconds(proc.pid)
            progress = None if on_progress is None else (lambda n: on_progress(proc.pid, n))
            if on_progress is not None:
                on_progress(proc.pid, 0)
            result = _run_client(_client_cmd(variant, port, pin, steps), progress)
            result["server_cpu_ms_per_step"] = 1e3 * (process_cpu_seconds(proc.pid) - cpu0) / steps
            result["server_rss_mb"] = process_rss_mb(proc.pid)
        finally:
            if variant.server == "bridge":
                proc.send_signal(signal.SIGTERM)
            try:
                out, err = proc.communicate(timeout=60)
            except subprocess.TimeoutExpired:
                proc.kill()
                out, err = proc.communicate()
        if proc.returncode != 0:  # after the client finished: report it, keep the timing
            tail = err.strip().splitlines()[-1:] or ["(no stderr)"]
            result["server_exit"] = f"rc {proc.returncode}: {tail[0]}"
        counts = [ln for ln in out.splitlines() if ln.startswith("COUNTS ")]
        if counts:
            msgs = json.loads(counts[-1][len("COUNTS "):])
            result["messages_per_step"] = sum(msgs.values()) / steps
        if variant.server == "bridge" and variant.record:
            got = record_bytes_per_commit(Path(tmp) / "runs")
            if got is not None:
                result["record_bytes_per_step"], result["commits"] = got
    return result


def load() -> str:
    return " ".join(f"{x:.2f}" for x in os.getloadavg())


def calibration(pin: bool = True) -> float:
    cmd = [*(PIN if pin else ()), sys.executable, "-m", PEERS, "calibrate"]
    return float(_run_client(cmd)["calibration_ms"])


def machine_info() -> dict[str, str]:
    """What the numbers were measured on (the BLAS thread settings are reported, not changed)."""
    cpu = "unknown"
    try:
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            if line.startswith("model name"):
                cpu = line.split(":", 1)[1].strip()
                break
    except OSError:
        pass
    blas = {k: v for k, v in os.environ.items() if "OPENBLAS" in k or k == "OMP_NUM_THREADS"}
    return {
        "nproc": str(os.cpu_count()),
        "cpu": cpu,
        "python": sys.version.split()[0],
        "blas_env": ", ".join(f"{k}={v}" for k, v in sorted(blas.items())) or "(none set)",
        "loadavg": load(),
    }


@dataclass
class Samples:
    runs: list[dict[str, Any]] = field(default_factory=list)

    def median(self, key: str) -> float:
        return statistics.median(r.get(key, float("nan")) for r in self.runs)


@dataclass
class Rounds:
    """Every run of one mode (pinned or unpinned), by variant, in round order."""

    pinned: bool
    by_variant: dict[str, Samples] = field(default_factory=dict)
    context: list[str] = field(default_factory=list)  # per round: load, calibration


def run_rounds(variants: Sequence[Variant], rounds: int, pin: bool) -> Rounds:
    """Every variant once per round; the order reverses each round."""
    out = Rounds(pin, {v.name: Samples() for v in variants})
    mode = "pinned (taskset -c 1)" if pin else "unpinned"
    for rnd in range(rounds):
        order = list(variants) if rnd % 2 == 0 else list(reversed(variants))
        cal = calibration()
        ctx = f"round {rnd + 1}: load {load()}, calibration {cal:.1f} ms"
        out.context.append(ctx)
        print(f"[{mode}] {ctx}", flush=True)
        for v in order:
            r = run_variant(v, pin)
            r["calibration_ms"] = cal
            out.by_variant[v.name].runs.append(r)
            s = r["step_ms"]
            extra = ""
            if "message_us" in r:
                extra = "; µs/msg p50/p99/p99.9 " + ", ".join(
                    f"{c}: {m['p50']:.0f}/{m['p99']:.0f}/{m['p999']:.0f}"
                    for c, m in r["message_us"].items() if c in ("10", "13", "14"))
            if "record_bytes_per_step" in r:
                extra += f"; record {r['record_bytes_per_step']:.0f} B/step"
            print(f"  {v.name:<44} {r['ms_per_step']:8.4f} ms/step  step p50/p99/p99.9/max "
                  f"{s['p50']:.3f}/{s['p99']:.3f}/{s['p999']:.3f}/{s['max']:.2f} ms; server CPU "
                  f"{r.get('server_cpu_ms_per_step', 0.0):.3f} ms/step{extra}", flush=True)
            if "server_exit" in r:
                print(f"    warning: server process exited {r['server_exit']}", flush=True)
    return out


def _paired(rounds: Rounds, a: str, b: str, key: str) -> list[float]:
    ra, rb = rounds.by_variant[a].runs, rounds.by_variant[b].runs
    return [x[key] / y[key] for x, y in zip(ra, rb, strict=True) if y.get(key)]


def summarize(rounds: Rounds) -> str:
    """Tables and verdicts of one mode."""
    mode = "pinned (taskset -c 1)" if rounds.pinned else "unpinned"
    n = len(next(iter(rounds.by_variant.values())).runs)
    lines = [f"### {mode}, {n} rounds", "", *(f"- {c}" for c in rounds.context), "",
             "| variant | ms/step median | [min – max] | server CPU ms/step | step p50 / p99 / "
             "p99.9 / max ms | record B/step |", "|---|---|---|---|---|---|"]
    for name, s in rounds.by_variant.items():
        ms = [r["ms_per_step"] for r in s.runs]
        st = {k: statistics.median(r["step_ms"][k] for r in s.runs)
              for k in ("p50", "p99", "p999", "max")}
        rec = s.median("record_bytes_per_step")
        lines.append(
            f"| {name} | {statistics.median(ms):.4f} | [{min(ms):.4f} – {max(ms):.4f}] | "
            f"{s.median('server_cpu_ms_per_step'):.3f} | {st['p50']:.3f} / {st['p99']:.3f} / "
            f"{st['p999']:.3f} / {st['max']:.2f} | {'' if rec != rec else f'{rec:.0f}'} |")
    msg_rows = [(name, s) for name, s in rounds.by_variant.items() if "message_us" in s.runs[0]]
    if msg_rows:
        lines += ["", "| variant | message | p50 µs | p99 µs | p99.9 µs | max µs |",
                  "|---|---|---|---|---|---|"]
        for name, s in msg_rows:
            for code in s.runs[0]["message_us"]:
                q = {k: statistics.median(r["message_us"][code][k] for r in s.runs)
                     for k in ("p50", "p99", "p999", "max")}
                lines.append(f"| {name} | {code} | {q['p50']:.1f} | {q['p99']:.1f} | "
                             f"{q['p999']:.1f} | {q['max']:.0f} |")
    lines.append("")
    for bridge, ref in PAIRS:
        if bridge.name not in rounds.by_variant or ref.name not in rounds.by_variant:
            continue
        target = TARGET_RATIO_64 if bridge.dofs > 1 else TARGET_RATIO
        b, r = rounds.by_variant[bridge.name], rounds.by_variant[ref.name]
        ratio = b.median("ms_per_step") / r.median("ms_per_step")
        paired = statistics.median(_paired(rounds, bridge.name, ref.name, "ms_per_step"))
        cpu = b.median("server_cpu_ms_per_step") / r.median("server_cpu_ms_per_step")
        lines.append(
            f"- {bridge.name} / {ref.name}: ms/step ratio of medians **{ratio:.2f}** (median of "
            f"per-round ratios {paired:.2f}; target ≤ {target}: "
            f"{'met' if max(ratio, paired) <= target else 'NOT met'}); server CPU ratio "
            f"**{cpu:.2f}** (target ≤ {TARGET_CPU_RATIO}: "
            f"{'met' if cpu <= TARGET_CPU_RATIO else 'NOT met'})")
    rec = rounds.by_variant.get(BRIDGE.name)
    if rec is not None:
        b = rec.median("record_bytes_per_step")
        ok = "met" if b <= TARGET_BYTES_PER_STEP else "NOT met"
        lines.append(f"- record: {b:.0f} bytes per committed 1-DOF step (target ≤ "
                     f"{TARGET_BYTES_PER_STEP}: {ok})")
    return "\n".join(lines)


def run_rss(steps: int, pin: bool) -> str:
    """The bridge's RSS along a long run (scripted 1-DOF client, record on)."""
    variant = Variant("scripted 1-DOF: bridge", "bridge", client="scripted", steps=steps)
    samples: list[tuple[int, float]] = []

    def sample(pid: int, n: int) -> None:
        samples.append((n, process_rss_mb(pid)))
        if n:
            print(f"  {n:7d} steps: RSS {samples[-1][1]:.1f} MB", flush=True)

    start = time.perf_counter()
    r = run_variant(variant, pin, on_progress=sample)
    wall = time.perf_counter() - start
    warm = next((mb for n, mb in samples if n >= steps // 20), samples[0][1])
    end = samples[-1][1]
    growth = (end - warm) / warm
    ok = "met" if growth <= TARGET_RSS_GROWTH else "NOT met"
    return (f"RSS over {steps} steps ({'pinned' if pin else 'unpinned'}, load {load()}): "
            f"{samples[0][1]:.1f} MB at start, {warm:.1f} MB after {steps // 20} steps, "
            f"{end:.1f} MB at the end (growth {100 * growth:+.2f} %, target ≤ "
            f"{100 * TARGET_RSS_GROWTH:.0f} %: {ok}); "
            f"{r['ms_per_step']:.4f} ms/step, server CPU {r['server_cpu_ms_per_step']:.3f} "
            f"ms/step, record {r.get('record_bytes_per_step', float('nan')):.0f} B/step, "
            f"{wall:.0f} s")


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(prog="benchmarks.bench_opensees_bridge", description=__doc__,
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("mode", nargs="?", default="bench", choices=("bench", "rss"))
    parser.add_argument("--rounds", type=int, default=3, help="pinned rounds (0: none)")
    parser.add_argument("--unpinned-rounds", type=int, default=5, help="(0: none)")
    parser.add_argument("--steps", type=int, default=STEPS)
    parser.add_argument("--no-64", action="store_true", help="skip the 64-DOF variants")
    parser.add_argument("--steps-64", type=int, default=STEPS_64)
    parser.add_argument("--compare-tree", type=Path, default=None,
                        help="add the primary bridge variant and its record-off one served "
                        "from this checkout")
    parser.add_argument("--only", default=None,
                        help="comma-separated substrings: run only the matching variants")
    parser.add_argument("--rss-steps", type=int, default=RSS_STEPS)
    parser.add_argument("--profile", type=Path, default=None,
                        help="also run the primary bridge variant once under cProfile")
    parser.add_argument("--quick", action="store_true", help="one short pinned round")
    args = parser.parse_args(argv)
    if args.quick:
        args.rounds, args.unpinned_rounds = 1, 0
        args.steps, args.steps_64 = min(args.steps, 200), min(args.steps_64, 100)
        args.rss_steps = min(args.rss_steps, 2000)
    info = machine_info()
    print("step cost; " + "; ".join(f"{k}: {v}" for k, v in info.items()), flush=True)
    if args.mode == "rss":
        print(run_rss(args.rss_steps, pin=True), flush=True)
        return
    variants = [dataclasses.replace(v, steps=args.steps) for v in VARIANTS]
    if args.compare_tree is not None:
        tree = args.compare_tree.resolve()
        variants[2:2] = [dataclasses.replace(BRIDGE, name=f"bridge @ {tree.name}", tree=str(tree)),
                         dataclasses.replace(BRIDGE, name=f"bridge @ {tree.name}: record off",
                                             tree=str(tree), record=False)]
    if not args.no_64:
        variants += [dataclasses.replace(v, steps=args.steps_64) for v in (REF_64, BRIDGE_64)]
    if args.only:
        keys = args.only.split(",")
        variants = [v for v in variants if any(k in v.name for k in keys)]
    for tree in sorted({v.tree or "" for v in variants}):
        print(f"code of the bridge{' @ ' + tree if tree else ''}: {code_origin(tree or None)}",
              flush=True)
    reports = []
    if args.rounds:
        reports.append(summarize(run_rounds(variants, args.rounds, pin=True)))
        print(reports[-1], flush=True)
    if args.unpinned_rounds:
        reports.append(summarize(run_rounds(variants, args.unpinned_rounds, pin=False)))
        print(reports[-1], flush=True)
    print(f"\nload at the end: {load()}", flush=True)
    if args.profile is not None:
        r = run_variant(BRIDGE, pin=True, profile=args.profile.resolve())
        print(f"profiled run: {r['ms_per_step']:.4f} ms/step (under cProfile); profile "
              f"written to {args.profile}", flush=True)


if __name__ == "__main__":
    main()
