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
import sys
from collections.abc import Sequence

from sim_actuator.config import PRESETS, RigConfig, RigConfigError, build_rig, load_rig_config
from sim_actuator.config import preset as get_preset
from sim_actuator.servers.controller import RigController
from sim_actuator.servers.modbus import ModbusRigServer
from sim_actuator.servers.mts_stub import MtsStubServer

__all__ = ["main"]

DEFAULT_PORTS = {"modbus": 5020, "mts": 5021}


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
        help="TCP port (default 5020 modbus, 5021 mts; 0 = any free port)",
    )
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


async def _serve(args: argparse.Namespace, config: RigConfig) -> int:
    controller = RigController(build_rig(config), time_scale=args.time_scale)
    port = DEFAULT_PORTS[args.protocol] if args.port is None else args.port
    server: ModbusRigServer | MtsStubServer
    if args.protocol == "modbus":
        server = ModbusRigServer(controller, host=args.host, port=port)
    else:
        server = MtsStubServer(controller, host=args.host, port=port)
    stop = asyncio.Event()
    loop = asyncio.get_running_loop()
    for signum in (signal.SIGTERM, signal.SIGINT):
        loop.add_signal_handler(signum, stop.set)
    try:
        host, bound = await server.start()
    except (OSError, RuntimeError) as exc:
        print(f"sim-actuator: error: cannot listen on {args.host}:{port}: {exc}", file=sys.stderr)
        await controller.close()
        return 1
    controller.start_heartbeat(args.heartbeat_hz)
    print(
        f"sim-actuator ready protocol={args.protocol} host={host} port={bound} "
        f"rig={config.name}",
        flush=True,
    )
    try:
        await stop.wait()
    finally:
        await server.stop()
        await controller.close()
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
