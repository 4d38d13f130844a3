"""A bridge on an elastic specimen (k = K) with limits under a policy, and a spy on what reaches
its (real, in-process) controller: the safety and peer-loss tests' common ground."""

from __future__ import annotations

import math
import socket
import struct
import textwrap
import time
from collections.abc import Callable

import pytest

from fresco_bridge.controls.base import InlineController
from fresco_bridge.daemon import BridgeThread
from fresco_bridge.integrator.link import GenericClientLink
from fresco_bridge.sites import SiteState
from protocol import SizeID

K = 10.0  # kN/mm, elastic specimen: force = K * ctrl

LIMITS = {
    "absolute": "disp_min = -1.0\ndisp_max = 1.0\n",
    "increment": "disp_increment = 0.5\n",
    "velocity": "velocity = 5.0\n",  # mm/s; trials 0.1 s apart: 0.5 mm per step
}
WITHIN = 0.4  # first step: within every limit above
BEYOND = {"absolute": 1.3, "increment": 1.3, "velocity": 1.3}


def config(limits: str, policy: str, extra: str = "") -> str:
    return textwrap.dedent(f"""
        [bridge]
        run_name = "safety"
        [[sites]]
        name = "spec"
        port = 0
        [sites.controller]
        model = "elastic"
        params = {{ k = {K} }}
        [[sites.limits]]
        policy = "{policy}"
        """) + limits + extra


def spy(bridge: BridgeThread, site: str = "spec") -> list[tuple[float, ...]]:
    """Every command that reaches the (real, in-process) controller, in order."""
    calls: list[tuple[float, ...]] = []
    controller = bridge.bridge.sites[site].controller
    assert isinstance(controller, InlineController), "the site calls set_ctrl_now: spied here"
    original = controller.set_ctrl_now

    def set_ctrl_now(disp: tuple[float, ...]) -> None:
        calls.append(disp)
        original(disp)

    bridge.call(lambda: setattr(controller, "set_ctrl_now", set_ctrl_now))
    return calls


def state(bridge: BridgeThread, site: str = "spec") -> SiteState:
    return bridge.call(lambda: bridge.bridge.sites[site].state)


def wait_for(predicate: Callable[[], bool], what: str, timeout: float = 10.0) -> None:
    deadline = time.monotonic() + timeout
    while not predicate():
        assert time.monotonic() < deadline, f"timed out waiting for {what}"
        time.sleep(0.01)


def first_step(link: GenericClientLink) -> None:
    link.set_trial((WITHIN,), time=0.1)
    assert link.force()[0] == pytest.approx(K * WITHIN)
    link.commit()


def good_session(port: int, steps: int = 3) -> None:
    with GenericClientLink("127.0.0.1", port, 1, data_size=1) as link:
        for i in range(1, steps + 1):
            link.set_trial((0.1 * i,), time=0.1 * i)
            assert link.force()[0] == pytest.approx(K * 0.1 * i)
            link.commit()


def refused(port: int) -> bool:
    """The bridge will not serve a new 1-DOF genericClient connection: it tells it to stop."""
    with socket.create_connection(("127.0.0.1", port), timeout=5.0) as s:
        return told_to_stop(s)


def told_to_stop(s: socket.socket) -> bool:
    """``s``, a connection the bridge refused, is told to stop the way OpenSees understands
    (``server/refusal.py``): after a 1-DOF size ID and a trial, its force request is answered
    with NaN only, and its DIE ends the connection. False if a number came back (served)."""
    vector = struct.Struct("<5d")
    s.sendall(SizeID.for_generic_client(1, 1).encode() + vector.pack(3.0, 0.01, 0, 0, 1.0)
              + vector.pack(10.0, 0, 0, 0, 0))
    reply = b""
    while len(reply) < vector.size:
        chunk = s.recv(vector.size - len(reply))
        assert chunk, "the refused connection was closed before its request was answered"
        reply += chunk
    if not all(math.isnan(v) for v in vector.unpack(reply)):
        return False
    s.sendall(vector.pack(99.0, 0, 0, 0, 0))
    try:
        return s.recv(1) == b""
    except ConnectionResetError:
        return True
