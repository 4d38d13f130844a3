"""TLS sites under connection churn: does the bridge's memory reach a plateau?

Question: a TLS site's RSS once grew from 63 to 180 MB over ~13,000 connections (plain sites
stayed flat). A leak, or the allocator's working set filling up? Target: RSS flat (within
5 %) over the last half of >= 50,000 connections.

Method: the bridge is its own process (``python -m fresco_bridge.cli serve``) with ``--sites``
mutual-TLS sites (certificates made here with the ``openssl`` CLI), recording on. One client
per site in this process connects over loopback, one connection after another (``--burst``:
that many at once; all but one are then refused busy): four of five present a certificate of
the site's CA and run a short session (size ID, trial, getForce, commit, DIE: the force is
checked), the fifth one of another CA and is refused. After each round of ``--round``
connections the bridge's VmRSS and open fds are read from ``/proc``.

    .venv/bin/python -m benchmarks.bench_tls_memory [--quick] [--connections 50000]
        [--round 5000] [--sites 2] [--burst 1] [--event-loop uvloop|asyncio] [--json FILE]

Feeds BENCHMARKS.md, "Fuzz and soak". ``--quick``: 2,000 connections in rounds of 500.
"""

from __future__ import annotations

import argparse
import asyncio
import contextlib
import json
import os
import ssl
import subprocess
import sys
import tempfile
import textwrap
import time
from collections import Counter
from pathlib import Path
from typing import Any

from protocol import NEED_DATA, Action, ElementClientSession, Signals, SizeID

from .bench_soak import proc_fds, proc_rss, serving

K = 10.0
REFUSED_EVERY = 5
EC = ["-newkey", "ec", "-pkeyopt", "ec_paramgen_curve:prime256v1", "-nodes"]


def _openssl(d: Path, *args: str) -> None:
    subprocess.run(["openssl", *args], cwd=d, check=True, capture_output=True, timeout=30)


def make_pki(d: Path) -> None:
    """ca/other_ca, server and client (of ca), stranger (of other_ca): PEM files in ``d``."""
    for ca in ("ca", "other_ca"):
        _openssl(d, "req", "-x509", *EC, "-keyout", f"{ca}.key", "-out", f"{ca}.crt",
                 "-days", "2", "-subj", f"/CN={ca}",
                 "-addext", "basicConstraints=critical,CA:TRUE",
                 "-addext", "keyUsage=critical,keyCertSign,cRLSign")
    for name, ca in (("server", "ca"), ("client", "ca"), ("stranger", "other_ca")):
        _openssl(d, "req", *EC, "-keyout", f"{name}.key", "-out", f"{name}.csr",
                 "-subj", f"/CN={name}")
        (d / f"{name}.ext").write_text("basicConstraints=CA:FALSE\nsubjectAltName=IP:127.0.0.1\n")
        _openssl(d, "x509", "-req", "-in", f"{name}.csr", "-CA", f"{ca}.crt", "-CAkey",
                 f"{ca}.key", "-CAcreateserial", "-out", f"{name}.crt", "-days", "2",
                 "-extfile", f"{name}.ext")


def config(pki: Path, sites: int, run_dir: Path, event_loop: str) -> str:
    head = textwrap.dedent(f"""
        [bridge]
        run_dir = "{run_dir}"
        run_name = "tls-memory"
        event_loop = "{event_loop}"
        """)
    return head + "".join(textwrap.dedent(f"""
        [[sites]]
        name = "s{i}"
        port = 0
        tls = true
        cert_file = "{pki / 'server.crt'}"
        key_file = "{pki / 'server.key'}"
        client_ca_file = "{pki / 'ca.crt'}"
        [sites.controller]
        model = "elastic"
        params = {{ k = {K} }}
        """) for i in range(sites))


def _client_context(pki: Path, cert: str) -> ssl.SSLContext:
    ctx = ssl.create_default_context(cafile=str(pki / "ca.crt"))
    ctx.load_cert_chain(str(pki / f"{cert}.crt"), str(pki / f"{cert}.key"))
    return ctx


async def _session(port: int, ctx: ssl.SSLContext, d: float) -> str:
    """A client of the site's CA: size ID, trial, getForce (checked), commit, DIE ("served"),
    or "busy" when another client holds the site (bursts)."""
    session = ElementClientSession(SizeID.for_generic_client(1, 1))
    try:
        reader, writer = await asyncio.open_connection("127.0.0.1", port, ssl=ctx,
                                                       server_hostname="127.0.0.1")
    except (OSError, ssl.SSLError):
        return "busy"  # refused before the handshake
    try:
        writer.write(session.start() + session.send_trial(
            Signals(disp=(d,), vel=(0.0,), accel=(0.0,), time=(d,)))
            + session.send_request(Action.GET_FORCE))
        while (ev := session.next_event()) is NEED_DATA:
            try:
                data = await reader.read(65536)
            except (OSError, ssl.SSLError):
                data = b""
            if not data:
                return "busy"
            session.receive_data(data)
        force = ev.values[0]  # type: ignore[union-attr]
        if abs(force - K * d) > 1e-9:
            raise AssertionError(f"force {force} for d {d}, expected {K * d}")
        writer.write(session.send_commit() + session.send_die())
        await writer.drain()
        return "served"
    finally:
        writer.close()
        with contextlib.suppress(OSError, ssl.SSLError):
            await writer.wait_closed()


async def _refused(port: int, ctx: ssl.SSLContext) -> str:
    """One connection with another CA's certificate: the bridge must refuse it."""
    try:
        reader, writer = await asyncio.open_connection("127.0.0.1", port, ssl=ctx,
                                                       server_hostname="127.0.0.1")
    except (OSError, ssl.SSLError):
        return "refused"  # in the handshake (TLS 1.2)
    try:
        data = await reader.read(1)  # TLS 1.3: the refusal arrives at the first read
    except (OSError, ssl.SSLError):
        data = b""
    finally:
        writer.close()
    if data:
        raise AssertionError("a client of another CA was served")
    return "refused"


async def _rounds(ports: list[int], pki: Path, pid: int, total: int, round_size: int,
                  burst: int, outcomes: Counter[str]) -> list[dict[str, Any]]:
    good, stranger = _client_context(pki, "client"), _client_context(pki, "stranger")
    rounds: list[dict[str, Any]] = []
    done = 0
    t0 = time.monotonic()

    async def one(port: int, n: int) -> str:
        async with asyncio.timeout(60):
            if n % REFUSED_EVERY == REFUSED_EVERY - 1:
                return await _refused(port, stranger)
            return await _session(port, good, 0.001 * (n % 1000))

    async def worker(port: int, start: int, stop: int) -> None:
        for first in range(start, stop, burst):  # ``burst`` connections at once
            outcomes.update(await asyncio.gather(
                *(one(port, n) for n in range(first, min(first + burst, stop)))))

    rounds.append({"connections": 0, "rss_mib": round(proc_rss(pid) / 2**20, 1),
                   "fds": proc_fds(pid), "s": 0.0})
    while done < total:
        n = min(round_size, total - done)
        cuts = [done + n * i // len(ports) for i in range(len(ports) + 1)]
        await asyncio.gather(*(worker(port, cuts[i], cuts[i + 1])
                               for i, port in enumerate(ports)))
        done += n
        await asyncio.sleep(0.5)  # the bridge finishes closing the last sessions
        rounds.append({"connections": done, "rss_mib": round(proc_rss(pid) / 2**20, 1),
                       "fds": proc_fds(pid), "s": round(time.monotonic() - t0, 1)})
        print(f"{done:>7} connections: RSS {rounds[-1]['rss_mib']} MiB, "
              f"{rounds[-1]['fds']} fds, {rounds[-1]['s']} s", flush=True)
    return rounds


def run(total: int, round_size: int, sites: int, event_loop: str, work: Path,
        burst: int = 1) -> dict[str, Any]:
    pki = work / "pki"
    pki.mkdir()
    make_pki(pki)
    cfg = work / "tls.toml"
    cfg.write_text(config(pki, sites, work / "runs", event_loop), encoding="utf-8")
    with serving(cfg, work) as (pid, ports):
        outcomes: Counter[str] = Counter()
        rounds = asyncio.run(_rounds(ports, pki, pid, total, round_size, burst, outcomes))
    half = [r["rss_mib"] for r in rounds if r["connections"] >= total / 2]
    return {"event_loop": event_loop, "sites": sites, "connections": total, "burst": burst,
            "outcomes": dict(outcomes), "rounds": rounds,
            "rss_last_half_min_mib": min(half), "rss_last_half_max_mib": max(half),
            "rss_last_half_growth_pct": round(100 * (max(half) / min(half) - 1), 2)}


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--connections", type=int, default=50_000)
    ap.add_argument("--round", type=int, default=5_000, help="connections between RSS samples")
    ap.add_argument("--sites", type=int, default=2, help="TLS sites, one client each")
    ap.add_argument("--event-loop", choices=("uvloop", "asyncio"), default="uvloop")
    ap.add_argument("--burst", type=int, default=1,
                    help="connections each client opens at once (> 1: most are refused busy)")
    ap.add_argument("--json", type=Path, default=None, help="also write the summary here")
    ap.add_argument("--quick", action="store_true", help="2,000 connections, rounds of 500")
    args = ap.parse_args(argv)
    if args.quick:
        args.connections, args.round = min(args.connections, 2_000), min(args.round, 500)
    load_start = os.getloadavg()
    with tempfile.TemporaryDirectory(prefix="fresco-tls-memory-") as tmp:
        summary = run(args.connections, args.round, args.sites, args.event_loop, Path(tmp),
                      args.burst)
    summary["load_average_start"] = load_start
    summary["load_average_end"] = os.getloadavg()
    text = json.dumps(summary, indent=2)
    print(text)
    if args.json is not None:
        args.json.write_text(text + "\n", encoding="utf-8")
    return 0


if __name__ == "__main__":
    sys.exit(main())
