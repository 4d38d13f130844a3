"""The ``generic-tcp`` controller against the real GenericTCP rig server on loopback: TCP, UDP
and mutual TLS; the parameter file; a server that goes away and comes back; config errors."""

from __future__ import annotations

import asyncio
import shutil
import subprocess
from collections.abc import Awaitable, Callable
from pathlib import Path
from typing import Any, TypeVar

import pytest
from pydantic import ValidationError

from fresco_bridge.controls.base import ControllerLinkError
from fresco_bridge.controls.generic_tcp import GenericTcpController, GenericTcpControllerConfig
from sim_actuator.config import build_rig, preset
from sim_actuator.servers.controller import RigController
from sim_actuator.servers.generic_tcp import GenericTcpRigServer

T = TypeVar("T")
K = 68.0  # preset ideal-elastic, kN/mm


def run(factory: Callable[[], Awaitable[T]]) -> T:
    async def bounded() -> T:
        return await asyncio.wait_for(factory(), 30)

    return asyncio.run(bounded())


def channels(n: int, name: str = "ideal-elastic") -> list[RigController]:
    return [RigController(build_rig(preset(name))) for _ in range(n)]


def config(port: int, **options: Any) -> GenericTcpControllerConfig:
    defaults: dict[str, Any] = {"reconnect_min": 0.0, "reconnect_max": 0.01,
                                "request_timeout": 1.0}
    return GenericTcpControllerConfig(port=port, **{**defaults, **options})


@pytest.mark.parametrize("transport", ["tcp", "udp"])
def test_three_actuators_move_and_measure(transport: str) -> None:
    async def scenario() -> None:
        server = GenericTcpRigServer(channels(3), transport=transport)
        _, port = await server.start()
        ctl = GenericTcpController(config(port, transport=transport), 3)
        try:
            await ctl.connect()
            for i in range(1, 6):
                target = (0.1 * i, -0.2 * i, 0.05 * i)
                await ctl.set_ctrl(target)
                daq = await ctl.get_daq()
                assert daq.disp == pytest.approx(target, abs=1e-12)
                assert daq.force == pytest.approx([K * t for t in target], rel=1e-12)
            assert [c.rig.command for c in server.channels.controllers] == \
                pytest.approx([0.5, -1.0, 0.25])
            assert await ctl.tangent_stiffness() == (K, 0, 0, 0, K, 0, 0, 0, K)
        finally:
            await ctl.close()
            await server.stop()

    run(scenario)


def test_the_parameter_file_reaches_the_server_on_every_link(tmp_path: Path) -> None:
    init = tmp_path / "lab.par"
    init.write_text("# ramp of every move\nramp_time 0.25\n")

    async def scenario() -> None:
        rigs = channels(1, "servo-hydraulic")
        server = GenericTcpRigServer(rigs)
        _, port = await server.start()
        ctl = GenericTcpController(config(port, init_file=init), 1)
        try:
            await ctl.set_ctrl((1.0,))
            await ctl.get_daq()
            assert server.channels.ramp_time == 0.25
            assert rigs[0].ramp_time == 0.25
        finally:
            await ctl.close()
            await server.stop()

    run(scenario)


def test_a_server_that_went_away_gets_no_motion_before_a_measurement_on_the_new_link() -> None:
    async def scenario() -> None:
        rigs = channels(2)
        server = GenericTcpRigServer(rigs)
        _, port = await server.start()
        ctl = GenericTcpController(config(port), 2)
        try:
            await ctl.set_ctrl((1.0, 2.0))
            assert (await ctl.get_daq()).disp == pytest.approx((1.0, 2.0))
            await server.stop()  # every connection closed: the lab's program restarts
            with pytest.raises(ControllerLinkError, match=r"link lost|cannot connect"):
                await ctl.set_ctrl((1.5, 2.5))
                await ctl.get_daq()
            server = GenericTcpRigServer(rigs, port=port)  # same rigs: they held position
            await server.start()
            with pytest.raises(ControllerLinkError, match=r"only after a measurement.*not sent"):
                await ctl.set_ctrl((1.5, 2.5))
            assert [c.rig.command for c in rigs] == [1.0, 2.0]  # nothing moved
            assert (await ctl.get_daq()).disp == pytest.approx((1.0, 2.0))  # read first
            await ctl.set_ctrl((1.5, 2.5))
            assert (await ctl.get_daq()).disp == pytest.approx((1.5, 2.5))
            assert ctl.links_opened == 2 and server.connections == 1
        finally:
            await ctl.close()
            await server.stop()

    run(scenario)


def test_a_silent_server_is_a_lost_link_within_the_request_timeout() -> None:
    async def scenario() -> None:
        async def mute(reader: asyncio.StreamReader, writer: asyncio.StreamWriter) -> None:
            await reader.read(1 << 20)  # reads, never answers
            await asyncio.sleep(5)

        server = await asyncio.start_server(mute, "127.0.0.1", 0)
        port = server.sockets[0].getsockname()[1]
        ctl = GenericTcpController(config(port, request_timeout=0.2), 1)
        try:
            await ctl.set_ctrl((1.0,))
            with pytest.raises(ControllerLinkError, match=r"no reply within 0.2 s"):
                await ctl.get_daq()
        finally:
            await ctl.close()
            server.close()

    run(scenario)


@pytest.mark.parametrize(("options", "message"), [
    ({"ctrl_modes": (1, 1, 0, 0, 0)}, r"sends \['disp', 'vel'\].*must be \[1, 0, 0, 0, 0\]"),
    ({"daq_modes": (1, 0, 0, 0, 0)}, "force .* must be 1"),
    ({"ctrl_modes": (2, 0, 0, 0, 0)}, "less than or equal to 1"),
    ({"transport": "ssl"}, 'transport = "ssl" .* needs cert_file, key_file, ca_file'),
    ({"cert_file": "a.crt"}, 'cert_file: only with transport = "ssl"'),
    ({"init_file": "/nonexistent/lab.par"}, "init_file: cannot read /nonexistent/lab.par"),
])
def test_config_errors_say_what_and_why(options: dict[str, Any], message: str) -> None:
    with pytest.raises(ValidationError, match=message):
        GenericTcpControllerConfig(port=1, **options)


# -- mutual TLS ------------------------------------------------------------------------------

EC = ["-newkey", "ec", "-pkeyopt", "ec_paramgen_curve:prime256v1", "-nodes"]


def _ssl(*args: str, cwd: Path) -> None:
    subprocess.run(["openssl", *args], cwd=cwd, check=True, capture_output=True, timeout=30)


def _pki(d: Path) -> None:
    _ssl("req", "-x509", *EC, "-keyout", "ca.key", "-out", "ca.crt", "-days", "2", "-subj",
         "/CN=ca", "-addext", "basicConstraints=critical,CA:TRUE", "-addext",
         "keyUsage=critical,keyCertSign,cRLSign", cwd=d)
    for name in ("server", "client"):
        _ssl("req", *EC, "-keyout", f"{name}.key", "-out", f"{name}.csr", "-subj",
             f"/CN={name}", cwd=d)
        (d / f"{name}.ext").write_text("basicConstraints=CA:FALSE\nsubjectAltName=IP:127.0.0.1\n")
        _ssl("x509", "-req", "-in", f"{name}.csr", "-CA", "ca.crt", "-CAkey", "ca.key",
             "-CAcreateserial", "-out", f"{name}.crt", "-days", "2", "-extfile", f"{name}.ext",
             cwd=d)


@pytest.mark.skipif(shutil.which("openssl") is None, reason="needs the openssl CLI")
def test_mutual_tls_as_openfresco_ssl(tmp_path: Path) -> None:
    import ssl

    _pki(tmp_path)
    server_ctx = ssl.SSLContext(ssl.PROTOCOL_TLS_SERVER)
    server_ctx.verify_mode = ssl.CERT_REQUIRED
    server_ctx.load_cert_chain(tmp_path / "server.crt", tmp_path / "server.key")
    server_ctx.load_verify_locations(tmp_path / "ca.crt")

    async def scenario() -> None:
        server = GenericTcpRigServer(channels(1), tls=server_ctx)
        _, port = await server.start()
        ctl = GenericTcpController(config(
            port, transport="ssl", cert_file=tmp_path / "client.crt",
            key_file=tmp_path / "client.key", ca_file=tmp_path / "ca.crt"), 1)
        plain = GenericTcpController(config(port, request_timeout=0.5), 1)
        try:
            await ctl.set_ctrl((0.5,))
            assert (await ctl.get_daq()).force == pytest.approx((K * 0.5,))
            await ctl.close()
            await plain.set_ctrl((2.0,))  # plain TCP to a TLS server: never a move
            with pytest.raises(ControllerLinkError):
                await plain.get_daq()
            assert server.channels.controllers[0].rig.command == 0.5
        finally:
            await ctl.close()
            await plain.close()
            await server.stop()

    run(scenario)


def test_a_server_refusing_the_sites_sizes_is_named_as_the_likely_cause() -> None:
    async def scenario() -> None:
        server = GenericTcpRigServer(channels(1))  # one channel; the site drives two
        _, port = await server.start()
        ctl = GenericTcpController(config(port), 2)
        try:
            await ctl.set_ctrl((1.0, 1.0))  # sent before the server's refusal arrives
            with pytest.raises(ControllerLinkError, match=r"before any reply on this link.*"
                                                          r"2 actuator\(s\).*its log says why"):
                await ctl.get_daq()
            assert server.channels.controllers[0].rig.command == 0.0  # nothing moved
        finally:
            await ctl.close()
            await server.stop()

    run(scenario)


def test_the_parameter_file_over_udp_is_chunked_as_openfresco_does(tmp_path: Path) -> None:
    init = tmp_path / "lab.par"
    init.write_text("ramp_time 0.5\n" + "# " + "x" * 12000 + "\n")  # a line over 9126 bytes

    async def scenario() -> None:
        server = GenericTcpRigServer(channels(2), transport="udp")
        _, port = await server.start()
        ctl = GenericTcpController(config(port, transport="udp", init_file=init), 2)
        try:
            await ctl.set_ctrl((0.5, -0.5))
            assert (await ctl.get_daq()).force == pytest.approx((K * 0.5, -K * 0.5))
            assert server.channels.ramp_time == 0.5
        finally:
            await ctl.close()
            await server.stop()

    run(scenario)


def test_one_master_at_a_time() -> None:
    async def scenario() -> None:
        rigs = channels(1)
        server = GenericTcpRigServer(rigs)
        _, port = await server.start()
        first = GenericTcpController(config(port), 1)
        second = GenericTcpController(config(port), 1)
        try:
            await first.set_ctrl((1.0,))
            await first.get_daq()
            with pytest.raises(ControllerLinkError, match=r"link lost"):  # closed at once
                await second.set_ctrl((5.0,))
                await second.get_daq()
            assert rigs[0].rig.command == 1.0  # the second master moved nothing
            await first.set_ctrl((1.5,))
            assert (await first.get_daq()).disp == pytest.approx((1.5,))
        finally:
            await first.close()
            await second.close()
            await server.stop()

    run(scenario)
