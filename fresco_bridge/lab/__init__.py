"""``fresco-bridge lab``: the docker compose lab topology as local processes, and its integrator.

``docker/compose.yaml`` is the one description of the lab: each service carries an ``x-local``
block (the command to run it on this machine, how to tell it is ready). ``lab up`` reads it,
starts the selected services in ``depends_on`` order, waits for each with a deadline, forwards
their output prefixed with the service name, and stops them in reverse order (SIGTERM, then
SIGKILL after a grace period) on Ctrl-C, SIGTERM, when a one-shot service (the integrator)
finishes, or when a service dies. Children die with this process (``PR_SET_PDEATHSIG``), so
even a killed ``lab up`` leaves no orphans.

The bridge config a compose service mounts names compose hostnames and container ports; for a
local run it is rewritten to 127.0.0.1 and the host ports compose publishes (``localize``).
"""

from __future__ import annotations

import threading
from pathlib import Path
from typing import Any

from .compose import (
    DEFAULT_COMPOSE,
    LOOPBACK,
    LabError,
    LabService,
    Topology,
    dump_toml,
    interpolate,
    localize_bridge_config,
)
from .integrate import run_integrator
from .processes import LabOptions, guard_main, run_lab, signals_set

__all__ = [
    "DEFAULT_COMPOSE",
    "LabError",
    "LabOptions",
    "LabService",
    "Topology",
    "add_lab_parser",
    "dump_toml",
    "guard_main",
    "interpolate",
    "lab_command",
    "localize_bridge_config",
    "run_integrator",
    "run_lab",
]


def add_lab_parser(sub: Any) -> None:
    """``fresco-bridge lab up|integrate`` (called by the CLI to register the subcommand)."""
    p_lab = sub.add_parser("lab", help="the docker compose lab topology as local processes")
    lab_sub = p_lab.add_subparsers(dest="lab_command", required=True)
    p_up = lab_sub.add_parser("up", help="start mosquitto, sim-actuator and the bridge (and the "
                              "integrator) from docker/compose.yaml; Ctrl-C stops them")
    p_up.add_argument("--compose", type=Path, default=DEFAULT_COMPOSE,
                      help="compose file (default %(default)s, else the one of this checkout)")
    p_up.add_argument("--with-integrator", action="store_true",
                      help="also run the demo integrator (profile `integrator`); the lab stops "
                      "when it finishes")
    p_up.add_argument("--profile", action="append", default=[], help="extra compose profile")
    p_up.add_argument("--controller", choices=("modbus", "mts"), default=None,
                      help="protocol of the simulated controller (sets LAB_CONTROLLER and "
                      "LAB_BRIDGE_CONFIG; default: the compose defaults, modbus)")
    p_up.add_argument("--runs", type=Path, default=Path("runs"), help="run directory root")
    p_up.add_argument("--ready-timeout", type=float, default=30.0,
                      help="seconds each service may take to be ready (default %(default)s)")
    p_int = lab_sub.add_parser("integrate", help="drive a running bridge's damper site with the "
                               "demo's two-story frame (the compose `integrator` service)")
    p_int.add_argument("--host", default=LOOPBACK)
    p_int.add_argument("--port", type=int, default=8090)
    p_int.add_argument("--duration", type=float, default=10.0, help="record length, s")
    p_int.add_argument("--pga", type=float, default=3.0, help="PGA in m/s² (default 3.0)")
    p_int.add_argument("--seed", type=int, default=1, help="synthetic record seed")
    p_int.add_argument("--connect-timeout", type=float, default=30.0)


def lab_command(args: Any) -> int:
    """Run ``fresco-bridge lab ...``; LabError propagates to the CLI boundary."""
    if args.lab_command == "integrate":
        run_integrator(args.host, args.port, duration=args.duration, pga=args.pga,
                       seed=args.seed, connect_timeout=args.connect_timeout)
        return 0
    env: dict[str, str] = {}
    if args.controller is not None:
        env["LAB_CONTROLLER"] = args.controller
        env["LAB_BRIDGE_CONFIG"] = "lab.toml" if args.controller == "modbus" else "lab-mts.toml"
    profiles = tuple(args.profile) + (("integrator",) if args.with_integrator else ())
    compose = args.compose
    checkout = Path(__file__).resolve().parents[2] / DEFAULT_COMPOSE  # a source checkout
    if compose == DEFAULT_COMPOSE and not compose.exists() and checkout.exists():
        compose = checkout
    opts = LabOptions(compose=compose, profiles=profiles, env=env, runs=args.runs,
                      ready_timeout=args.ready_timeout)
    stop = threading.Event()
    with signals_set(stop):
        return run_lab(opts, stop=stop)
