"""The safety layer in front of a real controller: ``sim-actuator serve --protocol modbus`` in its
own process. What reached the controller is read back from its registers (target, sequence,
state), independently of the bridge."""

from __future__ import annotations

import math
import time
from pathlib import Path

import pytest

from fresco_bridge import ctl
from fresco_bridge.integrator.link import GenericClientLink
from fresco_bridge.record import read_record
from tests.support.bridge import RunningBridge
from tests.support.controller import (
    K,
    bridge_toml,
    drive,
    modbus_registers,
    sim_actuator,
    site_state,
)
from tests.support.net import free_ports

LIMITS = "[[sites.limits]]\ndisp_min = -1.0\ndisp_max = 1.0\n"
DONE, INTERLOCK = 2, 4


def _wait_idle(b, timeout: float = 10.0) -> None:  # type: ignore[no-untyped-def]
    deadline = time.monotonic() + timeout
    while site_state(b)[0] != "IDLE" or b.call(lambda: b.bridge.sites["act"].peer):
        assert time.monotonic() < deadline, site_state(b)
        time.sleep(0.02)


def test_rejected_command_never_reaches_the_controller_which_holds(tmp_path: Path) -> None:
    (port,) = free_ports(1)
    with sim_actuator("modbus", port), \
            RunningBridge(bridge_toml("modbus", port) + LIMITS, tmp_path) as b:
        with GenericClientLink("127.0.0.1", b.ports["act"], 1, data_size=1) as link:
            drive(link, range(1, 4))
            before = modbus_registers(port)
            link.set_trial((1.5,), time=0.04)  # beyond disp_max
            assert math.isnan(link.force()[0])  # HOLD: told to stop, never the rejected move
            state, reason = site_state(b)
            assert state == "HOLD" and "absolute limit 1 mm" in reason
            time.sleep(0.3)  # the hold reaches the controller in the background
            after = modbus_registers(port)
            assert after["sequence"] == before["sequence"]  # no motion command was executed
            assert after["target"] == pytest.approx(before["target"])
            assert after["state"] == INTERLOCK  # controller.hold() engaged the interlock
        _wait_idle(b)
        with GenericClientLink("127.0.0.1", b.ports["act"], 1, data_size=1) as link:
            # a new session: the adapter releases the interlock it engaged, motion resumes
            assert drive(link, range(1, 3)) == pytest.approx([-K * 0.05, K * 0.1], rel=1e-6)
        assert modbus_registers(port)["state"] == DONE


def test_operator_abort_holds_the_real_controller_until_resumed(tmp_path: Path) -> None:
    (port,) = free_ports(1)
    with sim_actuator("modbus", port), \
            RunningBridge(bridge_toml("modbus", port) + LIMITS, tmp_path) as b:
        sock = ctl.find_socket(None, b.run_dir, tmp_path)
        link = GenericClientLink("127.0.0.1", b.ports["act"], 1, data_size=1).connect()
        drive(link, range(1, 3))
        answer = ctl.request(sock, "abort", "act")
        assert answer["ok"] and answer["sites"][0]["state"] == "FAULT"
        deadline = time.monotonic() + 5.0
        while modbus_registers(port)["state"] != INTERLOCK:
            assert time.monotonic() < deadline, "the abort never held the controller"
            time.sleep(0.02)
        sequence = modbus_registers(port)["sequence"]
        link.set_trial((0.2,), time=0.03)
        assert math.isnan(link.force()[0])  # told to stop: NaN, never a stale force
        link.close()  # the integrator stops: DIE
        assert modbus_registers(port)["sequence"] == sequence  # nothing moved after the abort
        deadline = time.monotonic() + 5.0
        while b.call(lambda: b.bridge.sites["act"].peer):  # the aborted session ends
            assert time.monotonic() < deadline, "the aborted session never ended"
            time.sleep(0.02)
        assert ctl.request(sock, "resume", "act")["ok"]
        with GenericClientLink("127.0.0.1", b.ports["act"], 1, data_size=1) as again:
            assert drive(again, range(1, 3)) == pytest.approx([-K * 0.05, K * 0.1], rel=1e-6)
        run_dir = b.run_dir
    kinds = [r["event"] for r in read_record(run_dir) if r["kind"] == "event"]
    assert kinds[:5] == ["session-open", "abort", "integrator-stop", "session-close", "resume"]
