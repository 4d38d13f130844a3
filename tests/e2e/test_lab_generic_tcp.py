"""A bridge site on the ``generic-tcp`` controller against a real ``sim-actuator serve --protocol
generic-tcp --channels 3`` process, over TCP and UDP; the server process is killed mid-run.

With ``bridge.controller_recovery`` the integrator's request waits: the restarted server is read
first over the new link, the same setpoint goes out once, and the step is served with fresh
measurements — every step of the run is committed once, none lost, none made up. Without it
the site HOLDs and answers NaN, and the restarted server is sent nothing.
"""

from __future__ import annotations

import contextlib
import math
import signal
import subprocess
import threading
import time
from pathlib import Path

import pytest

from fresco_bridge.daemon import BridgeThread
from fresco_bridge.integrator.link import GenericClientLink
from fresco_bridge.record.export import committed_steps
from tests.support.bridge import RunningBridge
from tests.support.controller import sim_actuator
from tests.support.net import free_ports

K = 68.0  # preset ideal-elastic, kN/mm
N = 3


def generic_tcp_server(port: int, transport: str,
                       *extra: str) -> contextlib.AbstractContextManager[subprocess.Popen[str]]:
    """``sim-actuator serve --protocol generic-tcp`` with three ideal-elastic channels."""
    return sim_actuator("generic-tcp", port, "--transport", transport, "--channels", str(N),
                        *extra)


def bridge_toml(port: int, transport: str, recovery: float) -> str:
    return f"""
[bridge]
controller_timeout = 3.0
controller_recovery = {recovery}
[[sites]]
name = "col"
port = 0
dofs = {N}
setup = "NoTransformation"
[sites.controller]
kind = "generic-tcp"
port = {port}
transport = "{transport}"
stiffness = {K}
request_timeout = 1.0
connect_timeout = 1.0
reconnect_min = 0.02
reconnect_max = 0.1
"""


def trial(i: int) -> tuple[float, ...]:
    return (0.05 * i, -0.02 * i * (-1) ** i, 0.01 * i)


def step(link: GenericClientLink, i: int) -> tuple[float, ...]:
    link.set_trial(trial(i), time=0.01 * i)
    force = link.force()
    link.commit()
    return force


def site_state(b: BridgeThread) -> tuple[str, str]:
    return b.call(lambda: (str(b.bridge.sites["col"].state), b.bridge.sites["col"].reason))


@pytest.mark.parametrize("transport", ["tcp", "udp"])
def test_a_killed_server_is_waited_for_and_no_step_is_lost(tmp_path: Path,
                                                            transport: str) -> None:
    (port,) = free_ports(1)
    restarted: list[subprocess.Popen[str]] = []
    stack = contextlib.ExitStack()
    with generic_tcp_server(port, transport) as proc, \
            RunningBridge(bridge_toml(port, transport, recovery=30.0), tmp_path) as b, stack:
        with GenericClientLink("127.0.0.1", b.ports["col"], N, timeout=30.0) as link:
            for i in range(1, 11):
                assert step(link, i) == pytest.approx([K * d for d in trial(i)], rel=1e-12)
            proc.kill()
            proc.wait(5)

            def restart() -> None:
                time.sleep(0.6)
                restarted.append(stack.enter_context(generic_tcp_server(port, transport)))

            thread = threading.Thread(target=restart)
            thread.start()
            # the request waits for the server; the restarted rigs start at 0 mm and are
            # driven to the step's setpoint once the new link has been read
            forces = [step(link, i) for i in range(11, 31)]
            thread.join(10)
            assert restarted, "the server was not restarted"
            assert forces == [pytest.approx([K * d for d in trial(i)], rel=1e-12)
                              for i in range(11, 31)]
            assert site_state(b) == ("RUNNING", "")
        run_dir = b.run_dir
    steps = [s for s in committed_steps(run_dir) if s.site == "col"]
    assert [s.step for s in steps] == list(range(1, 31))  # every step once, none lost
    for s in steps:
        i = s.step
        assert s.cmd_disp == pytest.approx(trial(i)) and s.meas_disp == pytest.approx(trial(i))


@pytest.mark.parametrize("transport", ["tcp", "udp"])
def test_without_recovery_a_killed_server_holds_and_the_new_one_is_sent_nothing(
        tmp_path: Path, transport: str) -> None:
    (port,) = free_ports(1)
    with generic_tcp_server(port, transport) as proc, \
            RunningBridge(bridge_toml(port, transport, recovery=0.0), tmp_path) as b:
        with GenericClientLink("127.0.0.1", b.ports["col"], N, timeout=30.0) as link:
            for i in range(1, 6):
                step(link, i)
            proc.kill()
            proc.wait(5)
            assert all(math.isnan(f) for f in step(link, 6))
            state, reason = site_state(b)
            assert state == "HOLD" and f"generic-tcp controller 127.0.0.1:{port}" in reason
            with generic_tcp_server(port, transport, "--log-level", "INFO") as again:
                for i in range(7, 10):
                    assert all(math.isnan(f) for f in step(link, i))
                assert site_state(b)[0] == "HOLD"
                again.send_signal(signal.SIGTERM)
                _, err = again.communicate(timeout=10)
        assert "size ID" not in err  # never even connected to: nothing was sent
