"""``sim-actuator``: serve a simulated rig over Modbus TCP or the MTS-like stub protocol.

``sim-actuator serve --protocol modbus --port 5020 --preset ideal-bilinear`` prints one ready
line on stdout once listening (``sim-actuator ready protocol=... host=... port=... rig=...``;
with ``--port 0`` it names the port picked) and exits with status 0 on SIGTERM or SIGINT.
"""

from __future__ import annotations

import argparse
import asyncio
import contextlib
import logging
import math
import signal
import ssl
import sys
from collections.abc import Sequence

from sim_actuator.config import (
    PRESETS,
    RigConfig,
    RigConfigError,
    build_rig,
    channel_config,
    load_rig_config,
)
from sim_actuator.config import preset as get_preset
from sim_actuator.servers.controller import RigController
from sim_actuator.servers.generic_tcp import GenericTcpRigServer
from sim_actuator.servers.modbus import ModbusRigServer
from sim_actuator.servers.mts_stub import MtsStubServer

__all__ = ["main"]

DEFAULT_PORTS = {"modbus": 5020, "mts": 5021, "generic-tcp": 5022}


def _parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog="sim-actuator", description="Simulated structural test rig and its servers."
    )
    commands = parser.add_subparsers(dest="command", required=True)
    serve = commands.add_parser("serve", help="serve a rig over one protocol until SIGTERM")
    serve.add_argument("--protocol", choices=sorted(DEFAULT_PORTS), required=True)
    serve.add_argument("--host", default="127.0.0.1", help="address to bind (default %(default)s)")
    serve.add_argument(
        "--port", type=int, default=None,
        help="port (default 5020 modbus, 5021 mts, 5022 generic-tcp; 0 = any free port)",
    )
    serve.add_argument("--channels", type=int, default=1,
                       help="actuators served, one rig each (default 1)")
    serve.add_argument("--transport", choices=["tcp", "udp"], default="tcp",
                       help="generic-tcp: tcp (default) or udp (OpenFresco -udp)")
    serve.add_argument("--tls-cert", metavar="FILE",
                       help="generic-tcp over mutual TLS (OpenFresco -ssl): server.crt")
    serve.add_argument("--tls-key", metavar="FILE", help="its key (server.key)")
    serve.add_argument("--tls-client-ca", metavar="FILE",
                       help="the CA client certificates must be issued by (server_ca.crt)")
    rig = serve.add_mutually_exclusive_group(required=True)
    rig.add_argument("--rig", metavar="FILE", help="rig description, TOML")
    rig.add_argument("--preset", metavar="NAME", help=f"named rig: {', '.join(PRESETS)}")
    serve.add_argument(
        "--time-scale", type=float, default=0.0,
        help="wall seconds per simulated second (default 0: as fast as possible)",
    )
    serve.add_argument("--heartbeat-hz", type=float, default=10.0,
                       help="heartbeat counter rate (default %(default)s)")
    serve.add_argument("--log-level", default="WARNING",
                       choices=["DEBUG", "INFO", "WARNING", "ERROR"])
    commands.add_parser("presets", help="list the named rigs")
    return parser


def _tls(args: argparse.Namespace) -> ssl.SSLContext | None:
    """Mutual TLS as OpenFresco's TCP_SocketSSL server: a client certificate is required."""
    files = (args.tls_cert, args.tls_key, args.tls_client_ca)
    if not any(files):
        return None
    if not all(files):
        raise ValueError("--tls-cert, --tls-key and --tls-client-ca go together")
    ctx = ssl.SSLContext(ssl.PROTOCOL_TLS_SERVER)
    ctx.minimum_version = ssl.TLSVersion.TLSv1_2
    ctx.verify_mode = ssl.CERT_REQUIRED
    try:
        ctx.load_cert_chain(args.tls_cert, args.tls_key)
        ctx.load_verify_locations(cafile=args.tls_client_ca)
    except (OSError, ssl.SSLError) as exc:
        raise ValueError(f"cannot load the TLS files: {exc}") from None
    return ctx


async def _serve(args: argparse.Namespace, config: RigConfig) -> int:
    controllers = [RigController(build_rig(channel_config(config, c)),
                                 time_scale=args.time_scale) for c in range(args.channels)]
    port = DEFAULT_PORTS[args.protocol] if args.port is None else args.port
    server: ModbusRigServer | MtsStubServer | GenericTcpRigServer
    if args.protocol == "generic-tcp":
        server = GenericTcpRigServer(controllers, host=args.host, port=port,
                                     transport=args.transport, tls=args.tls)
    elif args.protocol == "modbus":
        server = ModbusRigServer(controllers, host=args.host, port=port)
    else:
        server = MtsStubServer(controllers, host=args.host, port=port)
    stop = asyncio.Event()
    loop = asyncio.get_running_loop()
    for signum in (signal.SIGTERM, signal.SIGINT):
        loop.add_signal_handler(signum, stop.set)
    try:
        host, bound = await server.start()
    except (OSError, RuntimeError) as exc:
        print(f"sim-actuator: error: cannot listen on {args.host}:{port}: {exc}", file=sys.stderr)
        for c in controllers:
            await c.close()
        return 1
    for c in controllers:
        c.start_heartbeat(args.heartbeat_hz)
    print(
        f"sim-actuator ready protocol={args.protocol} host={host} port={bound} "
        f"rig={config.name}" + (f" channels={args.channels}" if args.channels != 1 else ""),
        flush=True,
    )
    try:
        await stop.wait()
    finally:
        await server.stop()
        for c in controllers:
            await c.close()
        for signum in (signal.SIGTERM, signal.SIGINT):
            loop.remove_signal_handler(signum)
    return 0


def main(argv: Sequence[str] | None = None) -> int:
    """Entry point of the ``sim-actuator`` console script; returns the exit status."""
    args = _parser().parse_args(argv)
    if args.command == "presets":
        for name, cfg in PRESETS.items():
            print(f"{name}: {cfg.description}")
        return 0
    logging.basicConfig(level=args.log_level, stream=sys.stderr,
                        format="%(asctime)s %(levelname)s %(name)s: %(message)s")
    time_scale_ok = math.isfinite(args.time_scale) and args.time_scale >= 0.0
    if not (time_scale_ok and math.isfinite(args.heartbeat_hz) and args.heartbeat_hz > 0.0):
        print("sim-actuator: error: --time-scale must be >= 0 and --heartbeat-hz > 0",
              file=sys.stderr)
        return 2
    if args.channels < 1:
        print("sim-actuator: error: --channels must be >= 1", file=sys.stderr)
        return 2
    if args.protocol != "generic-tcp" and (args.transport != "tcp" or args.tls_cert):
        print("sim-actuator: error: --transport and --tls-* are options of --protocol "
              "generic-tcp", file=sys.stderr)
        return 2
    try:
        args.tls = _tls(args)
        if args.tls is not None and args.transport == "udp":
            raise ValueError("TLS runs over TCP, not with --transport udp")
    except ValueError as exc:
        print(f"sim-actuator: error: {exc}", file=sys.stderr)
        return 2
    try:
        config = load_rig_config(args.rig) if args.rig else get_preset(args.preset)
    except RigConfigError as exc:
        print(f"sim-actuator: error: {exc}", file=sys.stderr)
        return 2
    with contextlib.suppress(KeyboardInterrupt):
        return asyncio.run(_serve(args, config))
    return 0


if __name__ == "__main__":  # pragma: no cover
    raise SystemExit(main())
