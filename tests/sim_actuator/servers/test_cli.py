"""``sim-actuator serve`` as a real subprocess: ready line, one cycle, clean exit on a signal."""

from __future__ import annotations

import asyncio
import os
import re
import signal
import sys
from pathlib import Path

import pytest
from pymodbus.client import AsyncModbusTcpClient

from sim_actuator.cli import main
from sim_actuator.servers.modbus import Reg, decode_float32, encode_float32
from tests.support.paths import REPO

READY = re.compile(r"^sim-actuator ready protocol=(\w+) host=(\S+) port=(\d+) rig=(\S+)$")


async def _start(*args: str) -> tuple[asyncio.subprocess.Process, str, int]:
    env = {**os.environ, "PYTHONUNBUFFERED": "1"}
    proc = await asyncio.create_subprocess_exec(
        sys.executable, "-m", "sim_actuator.cli", "serve", "--port", "0", *args,
        stdout=asyncio.subprocess.PIPE, stderr=asyncio.subprocess.PIPE, cwd=REPO, env=env,
    )
    assert proc.stdout is not None
    line = (await asyncio.wait_for(proc.stdout.readline(), 30)).decode().strip()
    match = READY.match(line)
    if match is None:
        proc.kill()
        _, err = await proc.communicate()
        raise AssertionError(f"no ready line, got {line!r}; stderr: {err.decode()}")
    return proc, match.group(2), int(match.group(3))


async def _stop(proc: asyncio.subprocess.Process, signum: int) -> int:
    proc.send_signal(signum)
    try:
        return await asyncio.wait_for(proc.wait(), 15)
    except TimeoutError:
        proc.kill()
        await proc.wait()
        raise


def test_modbus_server_process_serves_a_cycle_and_exits_on_sigterm() -> None:
    async def scenario() -> int:
        proc, host, port = await _start("--protocol", "modbus", "--preset", "ideal-bilinear")
        try:
            client = AsyncModbusTcpClient(host, port=port, timeout=3, retries=0)
            assert await client.connect()
            w = await client.write_registers(
                Reg.COMMAND, [*encode_float32(0.25), *encode_float32(0.1), 1], device_id=1)
            assert not w.isError(), w
            r = await client.read_input_registers(Reg.STATE, count=6, device_id=1)
            assert not r.isError(), r
            client.close()
            assert r.registers[0] == 2  # DONE
            assert decode_float32(r.registers[2:4]) == 0.25
            assert decode_float32(r.registers[4:6]) == pytest.approx(68.0 * 0.25, rel=1e-7)
        finally:
            rc = await _stop(proc, signal.SIGTERM)
        return rc

    assert asyncio.run(scenario()) == 0


def test_mts_server_process_exits_cleanly_on_sigint() -> None:
    async def scenario() -> int:
        proc, host, port = await _start("--protocol", "mts", "--preset", "ideal-elastic")
        try:
            reader, writer = await asyncio.open_connection(host, port)
            writer.write(b"OPEN\nRUN 0.5 5\n")
            assert (await reader.readline()) == b"OK test=1\n"
            reply = (await reader.readline()).decode()
            assert "displacement=0.5 force=34.0 " in reply
            writer.close()
        finally:
            rc = await _stop(proc, signal.SIGINT)
        return rc

    assert asyncio.run(scenario()) == 0


def test_bad_rig_choices_exit_with_status_2(tmp_path: Path,
                                           capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["serve", "--protocol", "mts", "--preset", "nope"]) == 2
    assert "unknown rig preset 'nope'" in capsys.readouterr().err
    bad = tmp_path / "rig.toml"
    bad.write_text('[specimen]\nkind = "elastic"\nparams = { k = -1.0 }\n', encoding="utf-8")
    assert main(["serve", "--protocol", "modbus", "--rig", str(bad)]) == 2
    err = capsys.readouterr().err
    assert "rig.toml: invalid rig description" in err
    assert "k must be > 0" in err


def test_presets_are_listed(capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["presets"]) == 0
    out = capsys.readouterr().out
    assert "ideal-bilinear:" in out
    assert "lab-realistic:" in out


@pytest.mark.parametrize(("args", "message"), [
    (["--protocol", "generic-tcp", "--channels", "0"], "--channels must be >= 1"),
    (["--protocol", "modbus", "--transport", "udp"], "options of --protocol generic-tcp"),
    (["--protocol", "generic-tcp", "--tls-cert", "a.crt"], "go together"),
    (["--protocol", "generic-tcp", "--transport", "udp", "--tls-cert", "a", "--tls-key", "b",
      "--tls-client-ca", "c"], "cannot load the TLS files"),
])
def test_generic_tcp_options_are_checked_before_serving(
        args: list[str], message: str, capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["serve", *args, "--preset", "ideal-elastic"]) == 2
    assert message in capsys.readouterr().err
