"""The bridge's per-step Python work alone: protocol → site → safety → controller → record → reply.

Why: ``bench_opensees_bridge`` measures the whole step (sockets, event loop, two processes); this
one attributes the server's CPU. It starts a real ``Bridge`` (the daemon's own assembly: record,
taps, monitors) from the same TOML, then feeds a session's bytes straight into the connection
pump, in process, with the scripted genericClient's message sequence (``_step_peers.STEP_CODES``).
No socket, no event-loop round trip: what is left is exactly the code a ``data_received`` runs.

    python -m benchmarks.bench_step_path [--quick] [--dofs 1] [--steps 20000] [--no-record]
        [--limits] [--whole-steps] [--set SECTION.KEY=VALUE ...] [--profile FILE]
        [--sort tottime] [--controller sim|rig] [--elastic]

Feeds BENCHMARKS.md, "Step cost and scaling". ``--quick``: 200 steps, one repeat (a smoke run).

Each message is fed on its own, as a socket delivers a genericClient's requests (it waits for
every reply); ``--whole-steps`` feeds a step's 14 messages as one chunk instead. ``--set``
overrides a TOML key for attribution (e.g. ``--set telemetry.monitors=false``,
``--set record.fsync='"off"'``). ``--controller rig``: one in-process simulated rig per
actuator (preset ``ideal-elastic``, 10 ms ramps) instead of the ``sim`` models; ``--elastic``:
an elastic specimen at 1 DOF too (as at more DOFs), to compare actuator counts.

Reported: µs of process CPU per step (``time.process_time``, best of ``--repeats``), and with
``--profile`` the cProfile table (top 30 by ``--sort``).
"""

from __future__ import annotations

import argparse
import asyncio
import cProfile
import math
import pstats
import struct
import tempfile
import time
from pathlib import Path

from protocol import SizeID

from ._step_peers import DT, STEP_CODES


def config_text(run_dir: Path, dofs: int, record: bool, limits: bool,
                overrides: dict[str, dict[str, str]] | None = None,
                site: str | None = None, *,
                controller: str = "sim", elastic: bool = False) -> str:
    """The bench's TOML; ``site`` replaces the ``[[sites]]`` table (named ``spec``)."""
    model = ('model = "elastic"\nparams = { k = 100.0 }' if dofs > 1 or elastic
             else 'model = "bilinear"\nparams = { k0 = 100.0, fy = 20.0, alpha = 0.02 }')
    if controller == "rig":
        model = 'preset = "ideal-elastic"\nramp_time = 0.01'
    elif controller != "sim":
        raise ValueError(f"controller must be sim or rig, got {controller!r}")
    lim = "".join(f"\n[[sites.limits]]\nactuator = {a}\ndisp_min = -50.0\ndisp_max = 50.0\n"
                  "disp_increment = 10.0\nforce_min = -1e6\nforce_max = 1e6\n"
                  for a in range(1, dofs + 1)) if limits else ""
    extra = overrides or {}

    def section(name: str) -> str:
        return "".join(f"{k} = {v}\n" for k, v in extra.get(name, {}).items())

    return f"""
[bridge]
run_name = "path"
run_dir = "{run_dir}"
{section("bridge")}
[record]
enabled = {"true" if record else "false"}
{section("record")}
[telemetry]
{section("telemetry")}
{site or default_site(dofs, model, lim, controller)}"""


def default_site(dofs: int, model: str, lim: str, controller: str = "sim") -> str:
    return f"""
[[sites]]
name = "spec"
port = 0
dofs = {dofs}
setup = "NoTransformation"
[sites.controller]
kind = "{controller}"
{model}
{lim}"""


def session_bytes(dofs: int, steps: int, per_message: bool = False
                  ) -> tuple[bytes, list[bytes]]:
    """The ID message and the bytes of each step, as the scripted client sends them (one
    chunk per step, or with ``per_message`` one chunk per message)."""
    sid = SizeID.for_generic_client(dofs)
    ds = sid.data_size
    vec = struct.Struct(f"<{ds}d")
    ident = struct.pack("<11i", *sid.ctrl.as_tuple(), *sid.daq.as_tuple(), ds)
    req = {c: vec.pack(float(c), *([0.0] * (ds - 1))) for c in (5, 10, 13, 14, 15)}

    def trial(d: float, t: float) -> bytes:
        return vec.pack(3.0, *([d] * dofs), *([0.0] * (2 * dofs)), t,
                        *([0.0] * (ds - 2 - 3 * dofs)))

    out = []
    d_prev = 0.0
    for i in range(steps):
        t = (i + 1) * DT
        d = 0.1 * math.sin(2.0 * math.pi * t)
        trials = iter((trial(d_prev, t), trial(d, t), trial(d, t)))
        d_prev = d
        step = [next(trials) if c == 3 else req[c] for c in STEP_CODES]
        if per_message:
            out.extend(step)
        else:
            out.append(b"".join(step))
    return ident + trial(0.0, 0.0) + req[15], out


async def run(dofs: int, steps: int, record: bool, limits: bool, repeats: int,
              profile: Path | None, *, per_message: bool = True,
              overrides: dict[str, dict[str, str]] | None = None,
              site: str | None = None, controller: str = "sim",
              elastic: bool = False) -> list[float]:
    from fresco_bridge.config import parse_config
    from fresco_bridge.daemon import Bridge
    from fresco_bridge.server.connection import SessionPump, SiteListener
    from fresco_bridge.sites.access import Allowlist

    per_step: list[float] = []
    with tempfile.TemporaryDirectory(prefix="fb-path-") as tmp:
        text = config_text(Path(tmp) / "runs", dofs, record, limits, overrides, site,
                           controller=controller, elastic=elastic)
        bridge = Bridge(parse_config(text), text)
        await bridge.start()
        try:
            site = bridge.sites["spec"]
            listener = SiteListener(site, Allowlist(["127.0.0.1"]), 65536, 60.0)
            for rep in range(repeats + (profile is not None)):
                head, body = session_bytes(dofs, steps, per_message)
                replies = 0

                def send(_data: bytes) -> None:
                    nonlocal replies
                    replies += 1

                pump = SessionPump(listener, f"bench:{rep}", send, lambda: None,
                                   lambda _on: None, transport="tcp")
                pump.feed(head)
                prof = cProfile.Profile() if rep == repeats else None
                c0 = time.process_time()
                if prof is not None:
                    prof.enable()
                for chunk in body:
                    pump.feed(chunk)
                if prof is not None:
                    prof.disable()
                    assert profile is not None
                    prof.dump_stats(str(profile))
                else:
                    per_step.append(1e6 * (time.process_time() - c0) / steps)
                assert not pump.closed, "session ended early"
                assert site.step == steps, (site.step, steps)
                assert replies == 1 + 10 * steps, replies
                pump.feed(b"")
        finally:
            await bridge.close()
    return per_step


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(prog="benchmarks.bench_step_path", description=__doc__,
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--dofs", type=int, default=1)
    parser.add_argument("--steps", type=int, default=20000)
    parser.add_argument("--repeats", type=int, default=3)
    parser.add_argument("--no-record", action="store_true")
    parser.add_argument("--limits", action="store_true", help="a disp limit with increment")
    parser.add_argument("--whole-steps", action="store_true",
                        help="feed each step's 14 messages as one chunk")
    parser.add_argument("--set", action="append", default=[], metavar="SECTION.KEY=VALUE",
                        help="override a TOML key (the value in TOML syntax)")
    parser.add_argument("--profile", type=Path, default=None)
    parser.add_argument("--sort", default="tottime")
    parser.add_argument("--quick", action="store_true", help="200 steps, one repeat")
    parser.add_argument("--controller", choices=["sim", "rig"], default="sim")
    parser.add_argument("--elastic", action="store_true",
                        help="an elastic specimen at 1 DOF too")
    args = parser.parse_args(argv)
    if args.quick:
        args.steps, args.repeats = min(args.steps, 200), 1
    overrides: dict[str, dict[str, str]] = {}
    for item in args.set:
        key, sep, value = item.partition("=")
        sect, dot, name = key.partition(".")
        if not (sep and dot and name):
            parser.error(f"--set {item!r}: expected SECTION.KEY=VALUE")
        overrides.setdefault(sect, {})[name] = value
    per_step = asyncio.run(run(args.dofs, args.steps, not args.no_record, args.limits,
                               args.repeats, args.profile, per_message=not args.whole_steps,
                               overrides=overrides, controller=args.controller,
                               elastic=args.elastic))
    feed = "whole steps" if args.whole_steps else "per message"
    sets = "".join(f", {item}" for item in args.set)
    who = "" if args.controller == "sim" else f" ({args.controller} controller)"
    print(f"step path{who}, {args.dofs} DOF, record {'off' if args.no_record else 'on'}, limits "
          f"{'on' if args.limits else 'off'}, {feed}{sets}: {min(per_step):.1f} µs CPU/step best, "
          f"{sorted(per_step)[len(per_step) // 2]:.1f} median of {len(per_step)}", flush=True)
    if args.profile is not None:
        pstats.Stats(str(args.profile)).sort_stats(args.sort).print_stats(30)


if __name__ == "__main__":
    main()
