"""A real ``sim-actuator serve`` process (preset ``ideal-elastic``) behind a bridge site: start
it, write the bridge's config for it, drive a link, read its Modbus registers back."""

from __future__ import annotations

import contextlib
import os
import signal
import subprocess
import sys
from collections.abc import Iterator

from pymodbus.client import ModbusTcpClient

from fresco_bridge.daemon import BridgeThread
from fresco_bridge.integrator.link import GenericClientLink
from sim_actuator.servers.modbus import Reg, decode_float32

K = 68.0  # preset ideal-elastic, kN/mm
TIMEOUT = 3.0  # controller_timeout of the bridge, s


@contextlib.contextmanager
def sim_actuator(protocol: str, port: int, *extra: str) -> Iterator[subprocess.Popen[str]]:
    proc = subprocess.Popen(
        [sys.executable, "-m", "sim_actuator.cli", "serve", "--protocol", protocol,
         "--port", str(port), "--preset", "ideal-elastic", *extra],
        stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
    )
    try:
        assert proc.stdout is not None
        line = proc.stdout.readline()
        assert line.startswith("sim-actuator ready"), line + (proc.stderr.read()
                                                               if proc.stderr else "")
        yield proc
    finally:
        if proc.poll() is None:
            os.kill(proc.pid, signal.SIGCONT)
            proc.terminate()
        proc.wait(10)


def bridge_toml(protocol: str, port: int, *, recovery: float = 30.0,
                **controller: float) -> str:
    """A bridge on one ``sim-actuator`` site; ``recovery`` defaults to the product's default."""
    extra = "".join(f"{k} = {v!r}\n" for k, v in controller.items())
    return f"""
[bridge]
controller_timeout = {TIMEOUT}
controller_recovery = {recovery}
[[sites]]
name = "act"
port = 0
[sites.controller]
kind = "{protocol}"
port = {port}
stiffness = {K}
heartbeat_timeout = 1.0
request_timeout = 1.0
connect_timeout = 1.0
{extra}"""


def site_state(b: BridgeThread) -> tuple[str, str]:
    return b.call(lambda: (str(b.bridge.sites["act"].state), b.bridge.sites["act"].reason))


def drive(link: GenericClientLink, steps: range, amp: float = 0.05) -> list[float]:
    forces = []
    for i in steps:
        link.set_trial((amp * i * (-1) ** i,), time=0.01 * i)
        forces.append(link.force()[0])
        link.commit()
    return forces


def modbus_registers(port: int) -> dict[str, float]:
    client = ModbusTcpClient("127.0.0.1", port=port, timeout=2, retries=0)
    assert client.connect()
    try:
        r = client.read_holding_registers(Reg.STATE, count=Reg.MAP_VERSION - Reg.STATE + 1,
                                          device_id=1)
        assert not r.isError(), r
        w = r.registers
        return {"sequence": w[Reg.SEQUENCE - Reg.STATE],
                "target": decode_float32(w[Reg.TARGET - Reg.STATE:Reg.TARGET - Reg.STATE + 2]),
                "state": w[0]}
    finally:
        client.close()
