"""``server/refusal.py``: a refused genericClient is answered with NaN, within bounds: at most
``MAX_REFUSALS`` of a site at once (a flood of refused connections holds no more), and each
for at most ``REFUSAL_WINDOW`` s; the served client never notices."""

from __future__ import annotations

import socket
import time
from pathlib import Path

import pytest

from fresco_bridge.integrator.link import GenericClientLink
from fresco_bridge.server.refusal import MAX_REFUSALS, REFUSAL_WINDOW
from tests.support.bridge import RunningBridge
from tests.support.spied_bridge import told_to_stop, wait_for

CONFIG = """
[bridge]
run_name = "refusal"
[[sites]]
name = "spring"
port = 0
dofs = 1
[sites.controller]
model = "elastic"
params = { k = 50.0 }
"""


def _closed_at_once(s: socket.socket) -> bool:
    try:
        s.sendall(b"\0" * 44)  # a size ID's worth: a closed connection answers nothing
        return s.recv(1) == b""
    except (ConnectionResetError, BrokenPipeError):
        return True


def test_a_flood_of_refused_clients_holds_at_most_max_refusals(tmp_path: Path) -> None:
    with RunningBridge(CONFIG, tmp_path) as bridge:
        port = bridge.ports["spring"]
        with GenericClientLink("127.0.0.1", port, 1, data_size=1) as served:
            served.set_trial((0.1,), time=0.1)
            assert served.force()[0] == pytest.approx(5.0)
            held = [socket.create_connection(("127.0.0.1", port), timeout=5.0)
                    for _ in range(MAX_REFUSALS)]
            try:
                wait_for(lambda: bridge.call(
                    lambda: bridge.bridge.sites["spring"].rejections.total) >= MAX_REFUSALS,
                    "the refusals")
                extra = socket.create_connection(("127.0.0.1", port), timeout=5.0)
                with extra:
                    assert _closed_at_once(extra)  # past the bound: closed, as before
                assert all(told_to_stop(s) for s in held)  # each answered NaN, then DIE
            finally:
                for s in held:
                    s.close()
            again = socket.create_connection(("127.0.0.1", port), timeout=5.0)
            with again:  # the slots came back with their clients' DIE
                assert told_to_stop(again)
            served.commit()
            served.set_trial((0.2,), time=0.2)
            assert served.force()[0] == pytest.approx(10.0)
            served.commit()


def test_a_refused_client_that_never_leaves_is_closed_after_the_window(tmp_path: Path) -> None:
    with RunningBridge(CONFIG, tmp_path) as bridge:
        port = bridge.ports["spring"]
        with GenericClientLink("127.0.0.1", port, 1, data_size=1) as served:
            served.set_trial((0.1,), time=0.1)
            served.force()
            t0 = time.monotonic()
            with socket.create_connection(("127.0.0.1", port),
                                          timeout=REFUSAL_WINDOW + 20) as idle:
                assert idle.recv(1) == b""  # it sent nothing, nor DIE: closed by the bridge
            waited = time.monotonic() - t0
            assert REFUSAL_WINDOW - 1.0 < waited < REFUSAL_WINDOW + 15
            served.commit()
