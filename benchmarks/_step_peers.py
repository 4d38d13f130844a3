"""The processes the step-cost benchmark times: the reference server and the two clients.

Every party is its own process, as in deployment. The driver (``bench_opensees_bridge``)
starts them, possibly pinned with ``taskset -c 1``:

- ``reference-server --dofs N``: the fastest simple server, blocking socket, exact reads,
  ``TCP_QUICKACK`` re-armed after every ``recv`` (protocol spec §3.11); a linear spring
  K = 100 per DOF (diagonal stiffness), zero damping and mass.
- ``opensees-client``: a real OpenSeesPy ``genericClient`` (1 DOF, Newmark + Newton, 2 Newton
  iterations = 14 messages per step), timed inside with ``time.perf_counter``.
- ``scripted-client --dofs N``: a blocking-socket client that sends exactly what
  ``genericClient`` sends for an n-DOF element in that analysis (Nagle left on, as OpenSees
  does): per step ``3 10 14 13 14  3 10 14 13 14  3 10 14 5``. It times every message from
  the first byte sent to the last byte of its reply, so it reports latency percentiles per
  action code, which OpenSees cannot.

Each client prints one ``RESULT {json}`` line; ``PROGRESS steps`` lines mark long runs (the
RSS mode samples the server's memory at each).
"""

from __future__ import annotations

import json
import math
import socket
import struct
import sys
import time
from typing import Any

from protocol import SizeID

K_REFERENCE = 100.0
DT = 0.01
MASS = 1.0
# 1 Hz sine base acceleration; amplitude keeps the bilinear specimen (k0 100, fy 20,
# dy 0.2) elastic, so the bridge and the reference exchange the same messages per step.
ACCEL_AMPLITUDE = 5.0
ACCEL_FREQUENCY = 1.0
STEP_CODES = (3, 10, 14, 13, 14, 3, 10, 14, 13, 14, 3, 10, 14, 5)
"""genericClient's messages per step (Newton, 2 iterations), as the reference server counts
them for the OpenSeesPy client: 3 × code 3, 3 × 10, 5 × 14, 2 × 13, 1 × 5."""
PROGRESS_EVERY = 10_000


class PeerError(RuntimeError):
    """A benchmark peer failed."""


def percentiles(samples: list[float]) -> dict[str, float]:
    """p50 / p99 / p99.9 / max (nearest rank) of ``samples``."""
    s = sorted(samples)
    n = len(s)

    def rank(q: float) -> float:
        return s[min(n - 1, max(0, math.ceil(q * n) - 1))]

    return {"p50": rank(0.50), "p99": rank(0.99), "p999": rank(0.999), "max": s[-1]}


# --- reference server ------------------------------------------------------------------------


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
    """Serve one genericClient session with a linear spring K per DOF; message counts by code."""
    conn, _ = listener.accept()
    counts: dict[int, int] = {}
    with conn:
        ident = _recv_exact(conn, 44)
        if ident is None:
            raise PeerError("reference server: client closed before sending its ID")
        sizes = struct.unpack("<11i", ident)
        data_size, n = sizes[10], sizes[0]
        nbytes = 8 * data_size
        vec = struct.Struct(f"<{data_size}d")
        trial = struct.Struct(f"<{n}d")
        zero = bytes(nbytes)
        k = [0.0] * data_size
        for i in range(n):
            k[i * n + i] = K_REFERENCE
        stiff = vec.pack(*k)
        pad = [0.0] * (data_size - n)
        disp: tuple[float, ...] = (0.0,) * n
        while True:
            msg = _recv_exact(conn, nbytes)
            if msg is None:
                break
            action = int(struct.unpack_from("<d", msg)[0])
            counts[action] = counts.get(action, 0) + 1
            if action == 3:
                disp = trial.unpack_from(msg, 8)
            elif action == 10:
                conn.sendall(vec.pack(*[K_REFERENCE * d for d in disp], *pad))
            elif action in (12, 13):
                conn.sendall(stiff)
            elif action in (14, 15):
                conn.sendall(zero)
            elif action == 99:
                break
    return counts


def reference_server_main() -> None:
    with socket.socket(socket.AF_INET, socket.SOCK_STREAM) as listener:
        listener.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
        listener.bind(("127.0.0.1", 0))
        listener.listen(1)
        print(f"reference ready: {listener.getsockname()[1]}", flush=True)
        counts = serve_reference_once(listener)
    print("COUNTS " + json.dumps(counts), flush=True)


# --- OpenSeesPy client -----------------------------------------------------------------------


def opensees_client_main(port: int | None, steps: int) -> None:
    """Build the 1-DOF model (genericClient, or a local elastic spring if no port); time it."""
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
    # UniformExcitation integrates the series over its whole span when it is built: a span of
    # the run only (a span of 1e6 s delays the first step by tens of seconds).
    t_end = (steps + 10) * DT
    ops.timeSeries("Trig", 1, 0.0, t_end, 1.0 / ACCEL_FREQUENCY, "-factor", ACCEL_AMPLITUDE)
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
    for i in range(steps):
        ts = clock()
        if ops.analyze(1, DT) != 0:
            raise PeerError("transient analysis failed")
        step_s.append(clock() - ts)
        iterations += ops.testIter()
        peak = max(peak, abs(ops.nodeDisp(1, 1)))
        if (i + 1) % PROGRESS_EVERY == 0:
            print(f"PROGRESS {i + 1}", flush=True)
    total = clock() - t0
    ops.wipe()
    result = {
        "ms_per_step": 1e3 * total / steps,
        "step_ms": {k: 1e3 * v for k, v in percentiles(step_s).items()},
        "newton_iterations_per_step": iterations / steps,
        "peak_disp": peak,
    }
    print("RESULT " + json.dumps(result), flush=True)


# --- scripted genericClient ------------------------------------------------------------------


def scripted_client_main(port: int, dofs: int, steps: int) -> None:
    """genericClient's byte stream for an n-DOF element; every message timed."""
    n = dofs
    sid = SizeID.for_generic_client(n)
    ds = sid.data_size
    vec = struct.Struct(f"<{ds}d")
    nbytes = 8 * ds
    sock = socket.create_connection(("127.0.0.1", port), timeout=30.0)
    # Nagle stays on, as in OpenSees' TCP_Socket for genericClient (spec §2.2).
    sock.sendall(struct.pack("<11i", *sid.ctrl.as_tuple(), *sid.daq.as_tuple(), ds))
    buf = bytearray(nbytes)
    view = memoryview(buf)
    requests = {c: vec.pack(float(c), *([0.0] * (ds - 1))) for c in (5, 10, 13, 14, 15, 99)}

    def trial(d: float, t: float) -> bytes:
        # code 3: disp, vel, accel (n each), time (1), from slot 1
        return vec.pack(3.0, *([d] * n), *([0.0] * (2 * n)), t, *([0.0] * (ds - 2 - 3 * n)))

    def reply() -> None:
        got = 0
        while got < nbytes:
            r = sock.recv_into(view[got:])
            if r == 0:
                raise PeerError("server closed the connection")
            got += r

    sock.sendall(trial(0.0, 0.0))
    sock.sendall(requests[15])
    reply()
    per_code: dict[int, list[float]] = {c: [] for c in set(STEP_CODES)}
    step_s: list[float] = []
    clock = time.perf_counter
    d_prev = 0.0
    t0 = clock()
    for i in range(steps):
        t = (i + 1) * DT
        d = 0.1 * math.sin(2.0 * math.pi * t)
        # as OpenSees' Newmark + Newton sends them: the last committed displacement with the
        # new time, the corrected one, then the converged one again (identical)
        trials = (trial(d_prev, t), trial(d, t), trial(d, t))
        d_prev = d
        ts = clock()
        k = 0
        for code in STEP_CODES:
            m0 = clock()
            if code == 3:
                sock.sendall(trials[k])
                k += 1
            elif code == 5:
                sock.sendall(requests[5])
            else:
                sock.sendall(requests[code])
                reply()
            per_code[code].append(clock() - m0)
        step_s.append(clock() - ts)
        if (i + 1) % PROGRESS_EVERY == 0:
            print(f"PROGRESS {i + 1}", flush=True)
    total = clock() - t0
    sock.sendall(requests[99])
    sock.close()
    result: dict[str, Any] = {
        "ms_per_step": 1e3 * total / steps,
        "step_ms": {k: 1e3 * v for k, v in percentiles(step_s).items()},
        "message_us": {str(c): {k: 1e6 * v for k, v in percentiles(s).items()}
                       for c, s in sorted(per_code.items())},
        "newton_iterations_per_step": 2.0,
    }
    print("RESULT " + json.dumps(result), flush=True)


def calibration_ms(repeats: int = 5) -> float:
    """A fixed pure-Python workload (best of ``repeats``): tells the machine's mode apart."""
    best = math.inf
    for _ in range(repeats):
        t0 = time.perf_counter()
        acc = 0
        for i in range(300_000):
            acc += i * i % 7
        best = min(best, time.perf_counter() - t0)
    return 1e3 * best


def main(argv: list[str]) -> None:
    import argparse

    p = argparse.ArgumentParser(prog="benchmarks._step_peers")
    p.add_argument("role", choices=("reference-server", "opensees-client", "scripted-client",
                                    "calibrate"))
    p.add_argument("--port", type=int, default=None)
    p.add_argument("--dofs", type=int, default=1)
    p.add_argument("--steps", type=int, default=2000)
    a = p.parse_args(argv)
    if a.role == "reference-server":
        reference_server_main()
    elif a.role == "opensees-client":
        opensees_client_main(a.port, a.steps)
    elif a.role == "scripted-client":
        if a.port is None:
            raise SystemExit("scripted-client needs --port")
        scripted_client_main(a.port, a.dofs, a.steps)
    else:
        print(f"RESULT {json.dumps({'calibration_ms': calibration_ms()})}", flush=True)


if __name__ == "__main__":
    main(sys.argv[1:])
