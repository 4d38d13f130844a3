"""A bridge with three elastic sites and what the session tests ask of it: a good client
served, a client that vanishes, the site's peer, session closes and refusals."""

from __future__ import annotations

import textwrap

import pytest

from fresco_bridge.daemon import BridgeThread
from fresco_bridge.integrator.link import GenericClientLink
from fresco_bridge.record import read_record

K = 10.0


def config(idle: float = 60.0, extra_site: str = "", deadline: float = 5.0) -> str:
    """Three elastic sites: ``tcp``, ``udp`` and ``other`` (TCP)."""
    return textwrap.dedent(f"""
        [bridge]
        run_name = "sessions"
        session_idle_timeout = {idle}
        message_deadline = {deadline}
        max_data_size = 4096
        allowed_clients = ["127.0.0.1"]
        [[sites]]
        name = "tcp"
        port = 0
        [sites.controller]
        model = "elastic"
        params = {{ k = {K} }}
        [[sites]]
        name = "udp"
        port = 0
        transport = "udp"
        [sites.controller]
        model = "elastic"
        params = {{ k = {K} }}
        [[sites]]
        name = "other"
        port = 0
        [sites.controller]
        model = "elastic"
        params = {{ k = {K} }}
        """) + extra_site


def steps(link: GenericClientLink, n: int = 3, start: int = 1) -> None:
    for i in range(start, start + n):
        link.set_trial((0.1 * i,), time=0.1 * i)
        assert link.force()[0] == pytest.approx(K * 0.1 * i)
        link.commit()


def served(port: int, transport: str = "tcp") -> None:
    with GenericClientLink("127.0.0.1", port, 1, data_size=1, transport=transport,
                           timeout=5.0) as link:
        steps(link)


def vanish(link: GenericClientLink) -> None:
    """The integrator is killed: its socket goes away without DIE."""
    assert link.sock is not None
    link.sock.close()
    link.sock = None


def peer(bridge: BridgeThread, site: str) -> str:
    return bridge.call(lambda: bridge.bridge.sites[site].peer)


def closes(bridge: BridgeThread, site: str) -> list[str]:
    return [r["reason"] for r in read_record(bridge.run_dir)
            if r.get("event") == "session-close" and r["site"] == site]


def refusals(bridge: BridgeThread, site: str) -> dict[str, int]:
    counts = bridge.call(lambda: bridge.bridge.sites[site].status()["refused"])
    assert isinstance(counts, dict)
    return counts
