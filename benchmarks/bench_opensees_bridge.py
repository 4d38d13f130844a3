"""OpenSeesPy 1-DOF transient through the full bridge vs a minimal blocking-socket server.

Why: the bridge must not be the bottleneck of a hybrid test. OpenFresco 2.8's own element
server stalls ~40-50 ms per step (client Nagle + server delayed ACK); a minimal server that
re-arms TCP_QUICKACK after every read does ~0.14 ms/step. The bridge (asyncio, simulated
specimen, run record on) should stay within 1.5x of that reference, measured in the same run.

Every party is its own process, as in deployment: the OpenSeesPy client (timed inside, with
``time.perf_counter`` around the ``analyze`` loop), the bridge (``fresco-bridge serve``) and
the reference server (``reference-server`` sub-command of this module).

    python -m benchmarks.bench_opensees_bridge [--repeats 3] [--steps 2000] [--profile FILE]
"""

from __future__ import annotations

import argparse
import importlib.util
import json
import os
import signal
import socket
import statistics
import struct
import subprocess
import sys
import tempfile
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

REPO = Path(__file__).resolve().parents[1]
MODULE = "benchmarks.bench_opensees_bridge"
STEPS = 2000
DT = 0.01
MASS = 1.0
K_REFERENCE = 100.0
# 1 Hz sine base acceleration; amplitude keeps the bilinear specimen (k0 100, fy 20,
# dy 0.2) elastic, so the bridge and the reference exchange the same messages per step.
ACCEL_AMPLITUDE = 5.0
ACCEL_FREQUENCY = 1.0
TARGET_MS_PER_STEP = 0.2
TARGET_RATIO = 1.5
START_TIMEOUT = 60.0
RUN_TIMEOUT = 300.0


class BenchmarkError(RuntimeError):
    """A benchmark process failed or did not report a result."""


# --- reference server (runs in its own process) -------------------------------------------


def _recv_exact(conn: socket.socket, n: int) -> bytes | None:
    buf = bytearray()
    while len(buf) < n:
        chunk = conn.recv(n - len(buf))
        if not chunk:
            return None
        buf += chunk
        conn.setsockopt(socket.IPPROTO_TCP, socket.TCP_QUICKACK, 1)
    return bytes(buf)


def serve_reference_once(listener: socket.socket) -> dict[int, int]:
    """Serve one genericClient session with a linear spring K; returns message counts by code.

    Blocking socket, exact reads, TCP_QUICKACK re-armed after every recv: the minimal server
    that avoids the Nagle + delayed-ACK stall (protocol spec §3.11).
    """
    conn, _ = listener.accept()
    counts: dict[int, int] = {}
    with conn:
        ident = _recv_exact(conn, 44)
        if ident is None:
            raise BenchmarkError("reference server: client closed before sending its ID")
        sizes = struct.unpack("<11i", ident)
        data_size, n = sizes[10], sizes[0]
        if n != 1:
            raise BenchmarkError(f"reference server serves 1 DOF, client announced {n}")
        nbytes = 8 * data_size
        zero = struct.pack(f"<{data_size}d", *([0.0] * data_size))
        stiff = struct.pack(f"<{data_size}d", K_REFERENCE, *([0.0] * (data_size - 1)))
        disp = 0.0
        while True:
            msg = _recv_exact(conn, nbytes)
            if msg is None:
                break
            code, d = struct.unpack_from("<2d", msg)
            action = int(code)
            counts[action] = counts.get(action, 0) + 1
            if action == 3:
                disp = d
            elif action == 10:
                conn.sendall(struct.pack(f"<{data_size}d", K_REFERENCE * disp,
                                         *([0.0] * (data_size - 1))))
            elif action in (12, 13):
                conn.sendall(stiff)
            elif action in (14, 15):
                conn.sendall(zero)
            elif action == 99:
                break
    return counts


def _reference_server_main() -> None:
    with socket.socket(socket.AF_INET, socket.SOCK_STREAM) as listener:
        listener.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
        listener.bind(("127.0.0.1", 0))
        listener.listen(1)
        print(f"reference ready: {listener.getsockname()[1]}", flush=True)
        counts = serve_reference_once(listener)
    print("COUNTS " + json.dumps(counts), flush=True)


# --- OpenSeesPy client (runs in its own process) -------------------------------------------


def _opensees_client_main(port: int | None, steps: int) -> None:
    """Build the 1-DOF model (genericClient, or a local elastic spring if no port); time it."""
    import math
    import time

    import openseespy.opensees as ops  # type: ignore[import-untyped]

    ops.wipe()
    ops.model("basic", "-ndm", 1, "-ndf", 1)
    ops.node(1, 0.0)
    ops.mass(1, MASS)
    if port is not None:
        ops.element("genericClient", 1, "-node", 1, "-dof", 1, "-server", port, "127.0.0.1")
    else:
        ops.node(0, 0.0)
        ops.fix(0, 1)
        ops.uniaxialMaterial("Elastic", 1, K_REFERENCE)
        ops.element("zeroLength", 1, 0, 1, "-mat", 1, "-dir", 1)
    ops.timeSeries("Trig", 1, 0.0, 1.0e6, 1.0 / ACCEL_FREQUENCY, "-factor", ACCEL_AMPLITUDE)
    ops.pattern("UniformExcitation", 1, 1, "-accel", 1)
    ops.system("FullGeneral")
    ops.numberer("Plain")
    ops.constraints("Plain")
    ops.test("NormDispIncr", 1e-12, 50)
    ops.algorithm("Newton")
    ops.integrator("Newmark", 0.5, 0.25)
    ops.analysis("Transient")
    step_s: list[float] = []
    iterations = 0
    peak = 0.0
    clock = time.perf_counter
    t0 = clock()
    for _ in range(steps):
        ts = clock()
        if ops.analyze(1, DT) != 0:
            raise BenchmarkError("transient analysis failed")
        step_s.append(clock() - ts)
        iterations += ops.testIter()
        peak = max(peak, abs(ops.nodeDisp(1, 1)))
    total = clock() - t0
    ops.wipe()
    first = step_s[0]
    step_s.sort()
    result = {
        "ms_per_step": 1e3 * total / steps,
        "first_step_ms": 1e3 * first,
        "median_step_ms": 1e3 * statistics.median(step_s),
        "p99_step_ms": 1e3 * step_s[min(steps - 1, math.ceil(0.99 * steps) - 1)],
        "max_step_ms": 1e3 * step_s[-1],
        "newton_iterations_per_step": iterations / steps,
        "peak_disp": peak,
    }
    print("RESULT " + json.dumps(result), flush=True)


# --- driver ---------------------------------------------------------------------------------


@dataclass(frozen=True)
class Variant:
    """One server configuration under test."""

    name: str
    kind: str  # "reference", "bridge" or "local" (no socket at all)
    model: str = "bilinear"
    record: bool = True
    fsync: str = "background"


VARIANTS = (
    Variant("reference (blocking + QUICKACK)", "reference"),
    Variant("bridge: bilinear, record on, fsync background", "bridge"),
    Variant("bridge: elastic, record on, fsync background", "bridge", model="elastic"),
    Variant("bridge: bilinear, record on, fsync inline", "bridge", fsync="inline"),
    Variant("bridge: bilinear, record off", "bridge", record=False),
    Variant("OpenSees alone (zeroLength, no socket)", "local"),
)
PRIMARY_BRIDGE = VARIANTS[1].name
REFERENCE = VARIANTS[0].name


@dataclass
class Samples:
    ms_per_step: list[float] = field(default_factory=list)
    details: list[dict[str, Any]] = field(default_factory=list)


def opensees_env() -> dict[str, str]:
    """OpenSeesPy's Linux wheel bundles BLAS/LAPACK the loader must find before start-up."""
    spec = importlib.util.find_spec("openseespylinux")
    if spec is None or not spec.submodule_search_locations:
        raise BenchmarkError("openseespy is not installed in this interpreter")
    lib = Path(next(iter(spec.submodule_search_locations))) / "lib"
    env = dict(os.environ)
    env["LD_LIBRARY_PATH"] = f"{lib}:{env.get('LD_LIBRARY_PATH', '')}".rstrip(":")
    env["PYTHONPATH"] = f"{REPO}:{env.get('PYTHONPATH', '')}".rstrip(":")
    return env


def bridge_config(variant: Variant, run_dir: Path) -> str:
    """Lab TOML for one site serving the 1-DOF element with a simulated specimen."""
    params = ("{ k = 100.0 }" if variant.model == "elastic"
              else "{ k0 = 100.0, fy = 20.0, alpha = 0.02 }")
    return f"""
[bridge]
run_name = "bench"
run_dir = {json.dumps(str(run_dir))}

[record]
enabled = {"true" if variant.record else "false"}
fsync = "{variant.fsync}"

[[sites]]
name = "spec"
port = 0
dofs = 1
setup = "NoTransformation"
[sites.controller]
kind = "sim"
model = "{variant.model}"
params = {params}
"""


def _await_line(proc: subprocess.Popen[str], prefix: str) -> str:
    assert proc.stdout is not None
    for line in proc.stdout:
        if line.startswith(prefix):
            return line[len(prefix):].strip()
    err = proc.stderr.read() if proc.stderr else ""
    raise BenchmarkError(f"server exited before printing {prefix!r} (rc {proc.wait()}): "
                         f"{err[-1500:]}")


def _start_server(variant: Variant, work: Path, profile: Path | None) -> tuple[
        subprocess.Popen[str], int]:
    env = opensees_env()
    if variant.kind == "reference":
        cmd = [sys.executable, "-m", MODULE, "reference-server"]
        prefix = "reference ready: "
    else:
        cfg = work / "bench.toml"
        cfg.write_text(bridge_config(variant, work / "runs"))
        prof = ["-m", "cProfile", "-o", str(profile)] if profile else []
        cmd = [sys.executable, *prof, "-m", "fresco_bridge.cli", "serve", "--config", str(cfg)]
        prefix = "fresco-bridge ready: spec="
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
    """User + system CPU a process has used so far (Linux /proc), 0.0 where unavailable."""
    try:
        fields = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()
    except OSError:
        return 0.0
    return (int(fields[11]) + int(fields[12])) / os.sysconf("SC_CLK_TCK")


def _run_client(port: int | None, steps: int) -> dict[str, Any]:
    args = [sys.executable, "-m", MODULE, "client", "--steps", str(steps)]
    if port is not None:
        args += ["--port", str(port)]
    proc = subprocess.run(args, cwd=REPO, env=opensees_env(), capture_output=True, text=True,
                          timeout=RUN_TIMEOUT)
    out = [ln for ln in proc.stdout.splitlines() if ln.startswith("RESULT ")]
    if proc.returncode != 0 or not out:
        raise BenchmarkError(f"OpenSeesPy client failed (rc {proc.returncode}): "
                             f"{proc.stdout[-1000:]} {proc.stderr[-1500:]}")
    result: dict[str, Any] = json.loads(out[-1][len("RESULT "):])
    return result


def run_variant(variant: Variant, steps: int, profile: Path | None = None) -> dict[str, Any]:
    """One client run against a fresh server process of this variant."""
    if variant.kind == "local":
        return _run_client(None, steps)
    with tempfile.TemporaryDirectory(prefix="fb-bench-") as tmp:
        proc, port = _start_server(variant, Path(tmp), profile)
        try:
            cpu0 = process_cpu_seconds(proc.pid)
            result = _run_client(port, steps)
            result["server_cpu_ms_per_step"] = 1e3 * (process_cpu_seconds(proc.pid) - cpu0) / steps
        finally:
            if variant.kind == "bridge":
                proc.send_signal(signal.SIGTERM)
            try:
                out, err = proc.communicate(timeout=30)
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
            result["messages"] = msgs
    return result


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
        "loadavg": " ".join(os.getloadavg().__repr__().strip("()").split(", ")),
    }


def run_benchmark(repeats: int = 3, steps: int = STEPS,
                  variants: tuple[Variant, ...] = VARIANTS) -> dict[str, Samples]:
    """All variants, alternated round by round so drifting machine load hits them alike."""
    samples = {v.name: Samples() for v in variants}
    for rnd in range(repeats):
        for v in variants:
            r = run_variant(v, steps)
            samples[v.name].ms_per_step.append(r["ms_per_step"])
            samples[v.name].details.append(r)
            print(f"  round {rnd + 1}/{repeats}  {v.name:<48} {r['ms_per_step']:8.4f} ms/step"
                  f"  (median step {r['median_step_ms']:.4f}, p99 {r['p99_step_ms']:.4f},"
                  f" max {r['max_step_ms']:.2f} ms; {r['newton_iterations_per_step']:.2f}"
                  f" iter/step; server CPU {r.get('server_cpu_ms_per_step', 0.0):.3f}"
                  f" ms/step)", flush=True)
            if "messages" in r:
                print(f"    messages/step {r['messages_per_step']:.2f} by code {r['messages']}")
            if "server_exit" in r:
                print(f"    warning: server process exited {r['server_exit']}", flush=True)
    return samples


def summarize(samples: dict[str, Samples]) -> str:
    """Median [min-max] table, the bridge/reference ratio and the verdict against the target."""
    lines = ["| variant | ms/step median | [min – max] | server CPU ms/step (median) |"
             " iter/step |", "|---|---|---|---|---|"]
    med = {}
    for name, s in samples.items():
        med[name] = statistics.median(s.ms_per_step)
        it = statistics.median(d["newton_iterations_per_step"] for d in s.details)
        cpu = statistics.median(d.get("server_cpu_ms_per_step", 0.0) for d in s.details)
        lines.append(f"| {name} | {med[name]:.4f} | [{min(s.ms_per_step):.4f} – "
                     f"{max(s.ms_per_step):.4f}] | {cpu:.3f} | {it:.2f} |")
    if PRIMARY_BRIDGE in med and REFERENCE in med:
        ratio = med[PRIMARY_BRIDGE] / med[REFERENCE]
        ok_abs = med[PRIMARY_BRIDGE] <= TARGET_MS_PER_STEP
        ok_ratio = ratio <= TARGET_RATIO
        lines += [
            "",
            f"ratio bridge/reference (medians): {ratio:.2f}",
            f"target ≤ {TARGET_MS_PER_STEP} ms/step: {'met' if ok_abs else 'NOT met'}; "
            f"target ratio ≤ {TARGET_RATIO}: {'met' if ok_ratio else 'NOT met'}",
        ]
    return "\n".join(lines)


def main(argv: list[str] | None = None) -> None:
    """Run the benchmark (default) or one of its worker processes (sub-commands)."""
    parser = argparse.ArgumentParser(prog=MODULE, description=__doc__,
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("role", nargs="?", default="bench",
                        choices=("bench", "reference-server", "client"))
    parser.add_argument("--repeats", type=int, default=3)
    parser.add_argument("--steps", type=int, default=STEPS)
    parser.add_argument("--port", type=int, default=None, help="client: server port")
    parser.add_argument("--profile", type=Path, default=None,
                        help="bench: also run the primary bridge variant once under cProfile")
    args = parser.parse_args(argv)
    if args.role == "reference-server":
        _reference_server_main()
        return
    if args.role == "client":
        _opensees_client_main(args.port, args.steps)
        return
    info = machine_info()
    print(f"OpenSeesPy 1-DOF transient, {args.steps} steps, {args.repeats} rounds; "
          + "; ".join(f"{k}: {v}" for k, v in info.items()), flush=True)
    samples = run_benchmark(args.repeats, args.steps)
    print(summarize(samples), flush=True)
    if args.profile is not None:
        primary = next(v for v in VARIANTS if v.name == PRIMARY_BRIDGE)
        r = run_variant(primary, args.steps, profile=args.profile.resolve())
        print(f"profiled run: {r['ms_per_step']:.4f} ms/step (under cProfile); "
              f"profile written to {args.profile}", flush=True)


if __name__ == "__main__":
    main()
