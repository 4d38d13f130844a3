"""A client that vanishes while its request waits: noticed at once, nothing of it forwarded.

Reading goes on while a request waits (only buffered), so the bridge sees the EOF of a client
killed during an operator pause; the wait is cancelled and a later ``resume`` has no dead
client's command to forward.
"""

from __future__ import annotations

import contextlib
import socket
import threading
from collections.abc import Callable

import pytest

from fresco_bridge.cli import main as cli_main
from fresco_bridge.daemon import BridgeThread
from fresco_bridge.integrator.link import GenericClientLink
from fresco_bridge.record import read_record
from fresco_bridge.sites import SiteState
from tests.support.spied_bridge import (
    BEYOND,
    LIMITS,
    WITHIN,
    config,
    first_step,
    good_session,
    spy,
    state,
    wait_for,
)


def test_a_client_gone_during_a_limit_pause_is_noticed_and_its_command_never_sent(
    run_bridge: Callable[[str], BridgeThread], capsys: pytest.CaptureFixture[str]
) -> None:
    bridge = run_bridge(config(LIMITS["increment"], "pause"))
    sent = spy(bridge)
    link = GenericClientLink("127.0.0.1", bridge.ports["spec"], 1, data_size=1,
                             timeout=30.0).connect()
    first_step(link)
    link.set_trial((BEYOND["increment"],), time=0.2)
    outcome: list[object] = []

    def ask_force() -> None:
        try:
            outcome.append(link.force()[0])
        except (ConnectionError, OSError) as exc:
            outcome.append(exc)

    waiter = threading.Thread(target=ask_force)
    waiter.start()
    site = bridge.bridge.sites["spec"]
    wait_for(lambda: bridge.call(lambda: site.pending) is not None, "the command to wait")
    assert link.sock is not None
    link.sock.shutdown(socket.SHUT_RDWR)  # the integrator dies: FIN, no DIE
    waiter.join(10)
    with contextlib.suppress(OSError):
        link.sock.close()
    link.sock = None
    # noticed without any operator action, the wait is over and the client is gone
    wait_for(lambda: bridge.call(lambda: site.peer) == "", "the session to end")
    assert bridge.call(lambda: site.pending) is None
    assert state(bridge) is SiteState.PAUSED  # the pause itself carries over
    assert sent == [(WITHIN,)]
    assert cli_main(["ctl", "resume", "--site", "spec", "--run-dir",
                     str(bridge.run_dir)]) == 0
    capsys.readouterr()
    assert sent == [(WITHIN,)]  # resume forwarded nothing of the dead client
    good_session(bridge.ports["spec"])
    assert sent[0] == (WITHIN,) and (BEYOND["increment"],) not in sent
    closes = [r for r in read_record(bridge.run_dir) if r.get("event") == "session-close"]
    assert "connection lost" in closes[0]["reason"]
