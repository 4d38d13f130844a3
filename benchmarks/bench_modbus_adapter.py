"""The Modbus controller adapter against a raw pymodbus client, and the full lab per step.

1. **Adapter overhead.** One ``sim-actuator serve --protocol modbus`` process (ideal elastic
   rig, so every move completes in the execute reply). In one asyncio loop, alternating blocks:
   ``ModbusController.set_ctrl`` + ``get_daq`` (the adapter's cycle per pseudo-dynamic step)
   vs an ``AsyncModbusTcpClient`` issuing the same three transactions on the same server (FC03
   status read, FC23 command+execute+status, FC03 measurement read) and decoding the floats,
   without the adapter's checks (heartbeat, state, sequence/target echo, lock, errors).
   Target: adapter overhead ≤ 20 % (median of per-block ratios).
2. **Full lab.** ``fresco-bridge lab up`` (docker/compose.yaml: mosquitto, sim-actuator over
   Modbus, the bridge with MQTT telemetry and the run record) and a real OpenSeesPy two-story
   frame (two genericClient elements: the damper over Modbus, story 2 served in-process),
   2000 steps, timed inside the OpenSeesPy process; the same frame against a bridge serving
   both sites in-process is the baseline of the same run.

    python -m benchmarks.bench_modbus_adapter [--quick] [--blocks 40] [--cycles 100] [--steps 2000]

Feeds BENCHMARKS.md, "Modbus adapter". ``--quick``: 4 blocks of 20 cycles and a 200-step lab,
a smoke run.
"""

from __future__ import annotations

import argparse
import asyncio
import json
import math
import os
import signal
import statistics
import subprocess
import sys
import tempfile
import time
import tomllib
from pathlib import Path
from typing import Any

from pymodbus.client import AsyncModbusTcpClient

from benchmarks.bench_opensees_bridge import machine_info, opensees_env
from fresco_bridge.controls.modbus import ModbusController, ModbusControllerConfig
from fresco_bridge.lab import Topology, dump_toml, localize_bridge_config
from sim_actuator.servers.modbus import Reg, decode_float32, encode_float32

REPO = Path(__file__).resolve().parents[1]
MODULE = "benchmarks.bench_modbus_adapter"
COMPOSE = REPO / "docker" / "compose.yaml"
STATUS = Reg.SIM_TIME + 2 - Reg.STATE
TARGET_OVERHEAD = 0.20
DT = 0.01
MASS = 0.0202228
ALPHA_M = 1.2


class BenchmarkError(RuntimeError):
    """A benchmark process failed or did not report a result."""


# --- 1. adapter vs raw pymodbus ------------------------------------------------------------------


def _target(i: int) -> float:
    return 2.0 * math.sin(0.05 * i)


async def _adapter_block(ctl: ModbusController, start: int, n: int) -> tuple[float, float]:
    """(wall s, client CPU s) per cycle."""
    t0, c0 = time.perf_counter(), time.process_time()
    for i in range(start, start + n):
        await ctl.set_ctrl((_target(i),))
        await ctl.get_daq()
    return (time.perf_counter() - t0) / n, (time.process_time() - c0) / n


async def _raw_block(client: AsyncModbusTcpClient, start: int, n: int,
                     ramp: float) -> tuple[float, float]:
    ramp_words = encode_float32(ramp)
    t0, c0 = time.perf_counter(), time.process_time()
    for i in range(start, start + n):
        before = await client.read_holding_registers(Reg.STATE, count=STATUS, device_id=1)
        reply = await client.readwrite_registers(
            read_address=Reg.STATE, read_count=STATUS, write_address=Reg.COMMAND,
            values=[*encode_float32(_target(i)), *ramp_words, 1], device_id=1)
        words = reply.registers
        while words[0] == 1:  # MOVING (never, with an ideal rig at time scale 0)
            words = (await client.read_holding_registers(Reg.STATE, count=STATUS,
                                                         device_id=1)).registers
        after = await client.read_holding_registers(Reg.STATE, count=STATUS, device_id=1)
        w = list(after.registers)
        decode_float32(w[2:4])
        decode_float32(w[4:6])
        del before
    return (time.perf_counter() - t0) / n, (time.process_time() - c0) / n


def _start_sim_actuator() -> tuple[subprocess.Popen[str], int]:
    proc = subprocess.Popen(
        [sys.executable, "-m", "sim_actuator.cli", "serve", "--protocol", "modbus", "--port", "0",
         "--preset", "ideal-elastic"],
        stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, cwd=REPO)
    assert proc.stdout is not None
    line = proc.stdout.readline()
    if not line.startswith("sim-actuator ready"):
        proc.kill()
        raise BenchmarkError(f"sim-actuator did not start: {line} {proc.communicate()[1]}")
    return proc, int(line.split("port=")[1].split()[0])


async def _overhead(port: int, blocks: int, cycles: int) -> dict[str, Any]:
    cfg = ModbusControllerConfig.model_validate({"port": port, "ramp_time": 0.1})
    ctl = ModbusController(cfg)
    await ctl.connect()
    raw = AsyncModbusTcpClient("127.0.0.1", port=port, timeout=2, retries=0)
    if not await raw.connect():
        raise BenchmarkError("raw pymodbus client cannot connect")
    wall: dict[str, list[float]] = {"adapter": [], "raw": []}
    cpu: dict[str, list[float]] = {"adapter": [], "raw": []}
    ratios, cpu_ratios = [], []
    i = 0
    await _adapter_block(ctl, i, cycles // 4)  # warm-up, both paths
    await _raw_block(raw, i, cycles // 4, cfg.ramp_time)
    for b in range(blocks):  # alternate which goes first: load drifts hit both alike
        for which in (("adapter", "raw") if b % 2 == 0 else ("raw", "adapter")):
            w, c = (await _adapter_block(ctl, i, cycles) if which == "adapter"
                    else await _raw_block(raw, i, cycles, cfg.ramp_time))
            wall[which].append(w)
            cpu[which].append(c)
            i += cycles
        ratios.append(wall["adapter"][-1] / wall["raw"][-1])
        cpu_ratios.append(cpu["adapter"][-1] / cpu["raw"][-1])
    sequence = await ctl.sequence()
    await ctl.close()
    raw.close()
    q = statistics.quantiles(ratios, n=4)
    return {
        "adapter_us_per_cycle": 1e6 * statistics.median(wall["adapter"]),
        "raw_us_per_cycle": 1e6 * statistics.median(wall["raw"]),
        "overhead": statistics.median(ratios) - 1.0,
        "overhead_iqr": [q[0] - 1.0, q[2] - 1.0],
        "adapter_cpu_us_per_cycle": 1e6 * statistics.median(cpu["adapter"]),
        "raw_cpu_us_per_cycle": 1e6 * statistics.median(cpu["raw"]),
        "cpu_overhead": statistics.median(cpu_ratios) - 1.0,
        "blocks": blocks, "cycles_per_block": cycles,
        "moves_on_server": sequence,
    }


def bench_overhead(blocks: int, cycles: int) -> dict[str, Any]:
    proc, port = _start_sim_actuator()
    try:
        return asyncio.run(_overhead(port, blocks, cycles))
    finally:
        proc.send_signal(signal.SIGTERM)
        proc.wait(10)


# --- 2. full lab: OpenSeesPy through lab up ----------------------------------------------------


def _opensees_client_main(ports: list[int], steps: int) -> None:
    """The two-story frame (damper + story 2 as genericClients), timed around ``analyze``."""
    import openseespy.opensees as ops  # type: ignore[import-untyped]

    ops.wipe()
    ops.model("basic", "-ndm", 1, "-ndf", 1)
    for tag in (1, 2, 3):
        ops.node(tag, 0.0)
    ops.fix(1, 1)
    ops.mass(2, MASS)
    ops.mass(3, MASS)
    for ele, (ni, nj), port in ((1, (1, 2), ports[0]), (2, (2, 3), ports[1])):
        ops.element("genericClient", ele, "-node", ni, nj, "-dof", 1, "-dof", 1,
                    "-server", port, "127.0.0.1")
    ops.timeSeries("Trig", 1, 0.0, 1.0e6, 0.8, "-factor", 1500.0)  # mm/s², 1.25 Hz
    ops.pattern("UniformExcitation", 1, 1, "-accel", 1)
    ops.rayleigh(ALPHA_M, 0.0, 0.0, 0.0)
    ops.system("FullGeneral")
    ops.numberer("Plain")
    ops.constraints("Plain")
    ops.algorithm("Linear", "-initial")  # non-iterative, as pseudo-dynamic tests run
    ops.integrator("Newmark", 0.5, 0.25)
    ops.analysis("Transient")
    step_s: list[float] = []
    peak = 0.0
    t0 = time.perf_counter()
    for _ in range(steps):
        ts = time.perf_counter()
        if ops.analyze(1, DT) != 0:
            raise BenchmarkError("transient analysis failed")
        step_s.append(time.perf_counter() - ts)
        peak = max(peak, abs(ops.nodeDisp(2, 1)))
    total = time.perf_counter() - t0
    ops.wipe()
    step_s.sort()
    print("RESULT " + json.dumps({
        "ms_per_step": 1e3 * total / steps,
        "median_step_ms": 1e3 * statistics.median(step_s),
        "p99_step_ms": 1e3 * step_s[math.ceil(0.99 * steps) - 1],
        "peak_story1_drift_mm": peak,
    }), flush=True)


def _run_client(ports: list[int], steps: int) -> dict[str, Any]:
    proc = subprocess.run(
        [sys.executable, "-m", MODULE, "client", "--ports", *map(str, ports), "--steps",
         str(steps)], cwd=REPO, env=opensees_env(), capture_output=True, text=True, timeout=600)
    out = [ln for ln in proc.stdout.splitlines() if ln.startswith("RESULT ")]
    if proc.returncode != 0 or not out:
        raise BenchmarkError(f"OpenSeesPy client failed (rc {proc.returncode}): "
                             f"{proc.stdout[-800:]} {proc.stderr[-1500:]}")
    result: dict[str, Any] = json.loads(out[-1][len("RESULT "):])
    return result


def _free_ports(n: int) -> list[int]:
    import socket

    socks = [socket.socket() for _ in range(n)]
    for s in socks:
        s.bind(("127.0.0.1", 0))
    ports = [s.getsockname()[1] for s in socks]
    for s in socks:
        s.close()
    return ports


def _lab_env() -> dict[str, str]:
    names = ("LAB_BRIDGE_PORT", "LAB_STORY2_PORT", "LAB_CONTROLLER_PORT", "LAB_MQTT_PORT")
    return {**os.environ, **dict(zip(names, map(str, _free_ports(4)), strict=True))}


def bench_full_lab(steps: int) -> dict[str, Any]:
    """ms/step of the frame through ``lab up`` (Modbus) and through an all-in-process bridge."""
    env = _lab_env()
    with tempfile.TemporaryDirectory(prefix="fb-lab-bench-") as tmp:
        lab = subprocess.Popen(
            [sys.executable, "-m", "fresco_bridge.cli", "lab", "up", "--compose", str(COMPOSE),
             "--runs", str(Path(tmp) / "runs")],
            stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True, env=env, cwd=REPO)
        try:
            assert lab.stdout is not None
            deadline = time.monotonic() + 60
            for line in lab.stdout:
                if line.startswith("lab: ready:"):
                    break
                if time.monotonic() > deadline:
                    raise BenchmarkError("lab up did not get ready")
            else:
                raise BenchmarkError("lab up exited before it was ready")
            ports = [int(env["LAB_BRIDGE_PORT"]), int(env["LAB_STORY2_PORT"])]
            modbus = _run_client(ports, steps)
            in_process = _in_process_lab(env, Path(tmp), steps)  # same broker, same run
        finally:
            lab.send_signal(signal.SIGINT)
            lab.communicate(timeout=60)
        modbus["lab_up_exit"] = lab.returncode
    return {"modbus_lab": modbus, "in_process": in_process,
            "ratio": modbus["ms_per_step"] / in_process["ms_per_step"]}


def _in_process_lab(env: dict[str, str], tmp: Path, steps: int) -> dict[str, Any]:
    """The lab's bridge config (record on, MQTT telemetry to the lab's broker) with the damper
    in-process (rig.toml's model), on free ports: the no-controller baseline of the same run."""
    topo = Topology.load(COMPOSE, env=env)
    text = localize_bridge_config((COMPOSE.parent / "lab.toml").read_text(), "lab.toml", topo,
                                  "bridge", tmp / "ref-runs")
    cfg = tomllib.loads(text)
    rig = tomllib.loads((COMPOSE.parent / "rig.toml").read_text())["specimen"]
    cfg["sites"][0]["controller"] = {"kind": "sim", "model": rig["kind"],
                                     "params": rig["params"]}
    for site in cfg["sites"]:
        site["port"] = 0
    path = tmp / "in-process.toml"
    path.write_text(dump_toml(cfg))
    bridge = subprocess.Popen(
        [sys.executable, "-m", "fresco_bridge.cli", "serve", "--config", str(path)],
        stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, cwd=REPO)
    try:
        assert bridge.stdout is not None
        line = bridge.stdout.readline()
        if not line.startswith("fresco-bridge ready"):
            raise BenchmarkError(f"bridge did not start: {line} {bridge.stderr}")
        bound = dict(kv.split("=") for kv in line.split(":", 1)[1].replace(",", " ").split())
        return _run_client([int(bound["damper"]), int(bound["story2"])], steps)
    finally:
        bridge.send_signal(signal.SIGTERM)
        bridge.communicate(timeout=30)


# --- driver ------------------------------------------------------------------------------------


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(prog=MODULE, description=__doc__)
    sub = parser.add_subparsers(dest="command")
    p_client = sub.add_parser("client")
    p_client.add_argument("--ports", type=int, nargs=2, required=True)
    p_client.add_argument("--steps", type=int, default=2000)
    parser.add_argument("--blocks", type=int, default=40)
    parser.add_argument("--cycles", type=int, default=100)
    parser.add_argument("--steps", type=int, default=2000)
    parser.add_argument("--quick", action="store_true", help="4 blocks of 20 cycles, 200 steps")
    args = parser.parse_args(argv)
    if args.quick:
        args.blocks, args.cycles, args.steps = 4, 20, 200
    if args.command == "client":
        _opensees_client_main(args.ports, args.steps)
        return
    print("machine: " + json.dumps(machine_info()), flush=True)
    over = bench_overhead(args.blocks, args.cycles)
    verdict = "meets" if over["overhead"] <= TARGET_OVERHEAD else "MISSES"
    print(f"adapter write+read cycle: {over['adapter_us_per_cycle']:.0f} µs, raw pymodbus "
          f"{over['raw_us_per_cycle']:.0f} µs, overhead {100 * over['overhead']:+.1f} % "
          f"(interquartile {100 * over['overhead_iqr'][0]:+.1f} .. "
          f"{100 * over['overhead_iqr'][1]:+.1f} %; {verdict} the ≤ "
          f"{100 * TARGET_OVERHEAD:.0f} % target); client CPU "
          f"{over['adapter_cpu_us_per_cycle']:.0f} vs {over['raw_cpu_us_per_cycle']:.0f} µs "
          f"({100 * over['cpu_overhead']:+.1f} %)", flush=True)
    print("overhead: " + json.dumps(over), flush=True)
    lab = bench_full_lab(args.steps)
    print(f"full lab, OpenSeesPy {args.steps} steps: {lab['modbus_lab']['ms_per_step']:.3f} "
          f"ms/step through lab up (Modbus damper), {lab['in_process']['ms_per_step']:.3f} "
          f"ms/step with the damper in-process ({lab['ratio']:.2f}x)", flush=True)
    print("full_lab: " + json.dumps(lab), flush=True)
    print("machine after: " + json.dumps(machine_info()), flush=True)


if __name__ == "__main__":
    main()
