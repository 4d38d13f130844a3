"""Fault injection between the bridge and a real ``sim-actuator serve`` process.

The controller process is killed (SIGKILL) or hung (SIGSTOP) mid-run, or its replies are
corrupted on the wire by a proxy (wrong register count, Modbus exception codes, garbage bytes,
garbage MTS lines), or its heartbeat stops. Every case must end in HOLD with a reason that names
the controller and the fault, no command forwarded while holding, and a bridge that serves the
next session once the fault is gone.

With ``bridge.controller_recovery`` > 0 a lost or silent controller is waited for inside the
integrator's request: back in time, the same session goes on with fresh measurements; not back,
the session is ended (the client sees the connection close). A controller *fault* is never
recovered. The tests of the plain HOLD (NaN answers until the session ends) set it to 0.
"""

from __future__ import annotations

import asyncio
import contextlib
import json
import math
import os
import signal
import struct
import subprocess
import sys
import threading
import time
from pathlib import Path

import pytest

from fresco_bridge.daemon import BridgeThread
from fresco_bridge.integrator.link import GenericClientLink
from fresco_bridge.record.export import committed_steps, read_record
from protocol import Action
from tests.support.bridge import OPENSEES_SCRIPT, RunningBridge, opensees_env, run_opensees
from tests.support.controller import (
    TIMEOUT,
    K,
    bridge_toml,
    drive,
    modbus_registers,
    sim_actuator,
    site_state,
)
from tests.support.net import free_ports

NO_RECOVERY = 0.0  # controller_recovery that keeps the plain HOLD (NaN answers)


def wait_idle(b: BridgeThread, timeout: float = 10.0) -> None:
    """Until the site closed the last session (its DIE and commits processed)."""
    deadline = time.monotonic() + timeout
    while site_state(b)[0] != "IDLE":
        assert time.monotonic() < deadline, site_state(b)
        time.sleep(0.01)


def hold_events(run_dir: Path) -> list[dict[str, object]]:
    return [r for r in read_record(run_dir)
            if r.get("kind") == "event" and r.get("event") == "hold"]


# -- the controller process killed / hung ---------------------------------------------------------


@pytest.mark.parametrize("protocol", ["modbus", "mts"])
def test_without_recovery_a_killed_controller_holds_then_a_new_session_resumes(tmp_path: Path,
                                                                    protocol: str) -> None:
    (port,) = free_ports(1)
    with sim_actuator(protocol, port) as proc, \
            RunningBridge(bridge_toml(protocol, port, recovery=NO_RECOVERY), tmp_path) as b:
        link = GenericClientLink("127.0.0.1", b.ports["act"], 1, data_size=1, timeout=10.0)
        with link:
            good = drive(link, range(1, 11))
            assert good[-1] == pytest.approx(K * 0.5, rel=1e-6)
            proc.kill()
            proc.wait(5)
            t0 = time.monotonic()
            link.set_trial((0.55,), time=0.11)
            stale = link.force()[0]  # answered (no hang): NaN, so the integrator stops
            assert time.monotonic() - t0 < TIMEOUT + 1.0
            assert math.isnan(stale)
            state, reason = site_state(b)
            assert state == "HOLD"
            assert f"{protocol} controller 127.0.0.1:{port}" in reason
            assert any(w in reason for w in ("link lost", "cannot connect", "link is down"))
            link.commit()
            # the controller comes back; the holding session forwards nothing to it
            with sim_actuator(protocol, port):
                for i in range(12, 20):
                    link.set_trial((0.05 * i,), time=0.01 * i)
                    assert math.isnan(link.force()[0])
                    link.commit()
                if protocol == "modbus":
                    regs = modbus_registers(port)
                    assert regs["sequence"] == 0 and regs["target"] == 0.0  # no move, ever
                assert site_state(b)[0] == "HOLD"
                link.close()  # the integrator ends the session cleanly (DIE)
                # the run resumes: a new session, the adapter reconnects and moves again
                with GenericClientLink("127.0.0.1", b.ports["act"], 1, data_size=1,
                                       timeout=10.0) as link2:
                    again = drive(link2, range(1, 6))
                    assert again == pytest.approx([K * 0.05 * i * (-1) ** i
                                                   for i in range(1, 6)], rel=1e-6)
                    assert site_state(b) == ("RUNNING", "")
                wait_idle(b)
                if protocol == "modbus":
                    assert modbus_registers(port)["sequence"] == 5
        run_dir = b.run_dir
    holds = hold_events(run_dir)
    assert len(holds) == 1 and "controller" in str(holds[0].get("reason"))
    sessions = {s.session for s in committed_steps(run_dir)}
    assert sessions == {1, 2}


def test_hung_controller_holds_within_the_deadline_and_the_session_ends_cleanly(
        tmp_path: Path) -> None:
    (port,) = free_ports(1)
    with sim_actuator("modbus", port) as proc, \
            RunningBridge(bridge_toml("modbus", port, recovery=NO_RECOVERY), tmp_path) as b:
        with GenericClientLink("127.0.0.1", b.ports["act"], 1, data_size=1,
                               timeout=10.0) as link:
            drive(link, range(1, 6))
            os.kill(proc.pid, signal.SIGSTOP)  # accepts TCP, never answers
            t0 = time.monotonic()
            link.set_trial((0.3,), time=0.06)
            assert math.isnan(link.force()[0])  # HOLD: told to stop
            elapsed = time.monotonic() - t0
            assert elapsed < TIMEOUT + 1.0, elapsed
            state, reason = site_state(b)
            assert state == "HOLD"
            assert "modbus controller" in reason
            assert any(w in reason for w in ("No response", "did not answer", "link lost"))
            link.commit()
        wait_idle(b)  # DIE sent: the session closed, the site is idle, the bridge still serves
        os.kill(proc.pid, signal.SIGCONT)
        with GenericClientLink("127.0.0.1", b.ports["act"], 1, data_size=1,
                               timeout=10.0) as link:
            assert drive(link, range(1, 3)) == pytest.approx([-K * 0.05, K * 0.1], rel=1e-6)
        wait_idle(b)
        run_dir = b.run_dir
    # steps 1-5 of session 1 (the held step is not committed), then 2 in session 2
    assert [s.session for s in committed_steps(run_dir)] == [1] * 5 + [2] * 2


def test_stale_heartbeat_holds_with_its_reason(tmp_path: Path) -> None:
    (port,) = free_ports(1)
    with sim_actuator("modbus", port, "--heartbeat-hz", "0.001"), \
            RunningBridge(bridge_toml("modbus", port, recovery=NO_RECOVERY), tmp_path) as b, \
            GenericClientLink("127.0.0.1", b.ports["act"], 1, data_size=1, timeout=10.0) as link:
        drive(link, range(1, 3))
        time.sleep(1.3)  # > heartbeat_timeout with a counter that does not move
        link.set_trial((0.3,), time=0.03)
        link.force()
        state, reason = site_state(b)
        assert state == "HOLD"
        assert "stale heartbeat" in reason and "heartbeat_timeout 1 s" in reason


# -- corrupted replies on the wire ---------------------------------------------------------


class ReplyCorruptor:
    """A TCP proxy bridge -> controller whose controller->bridge direction a test can corrupt.

    ``mode`` for Modbus: ``pass``, ``cut`` (the connection is closed instead of replying),
    ``short`` (FC03/FC23 replies lose their last two registers,
    with MBAP length and byte count kept consistent), ``exception:N`` (every reply becomes
    exception N of its function), ``garbage`` (random bytes instead of the frame). For the MTS
    stub (line protocol): ``pass``, ``garbage-line`` (every reply line is replaced).
    """

    def __init__(self, upstream: int, modbus: bool) -> None:
        self.upstream = upstream
        self.modbus = modbus
        self.mode = "pass"
        self.port = 0
        self._loop = asyncio.new_event_loop()
        self._ready = threading.Event()
        self._thread = threading.Thread(target=self._main, daemon=True)

    def __enter__(self) -> ReplyCorruptor:
        self._thread.start()
        assert self._ready.wait(10)
        return self

    def __exit__(self, *exc: object) -> None:
        self._loop.call_soon_threadsafe(self._loop.stop)
        self._thread.join(10)

    def _main(self) -> None:
        asyncio.set_event_loop(self._loop)

        async def start() -> None:
            server = await asyncio.start_server(self._client, "127.0.0.1", 0)
            self.port = server.sockets[0].getsockname()[1]

        self._loop.run_until_complete(start())
        self._ready.set()
        self._loop.run_forever()

    async def _client(self, reader: asyncio.StreamReader, writer: asyncio.StreamWriter) -> None:
        up_r, up_w = await asyncio.open_connection("127.0.0.1", self.upstream)

        async def forward() -> None:
            with contextlib.suppress(OSError):
                while data := await reader.read(65536):
                    up_w.write(data)
                    await up_w.drain()
            up_w.close()

        task = asyncio.get_running_loop().create_task(forward())
        with contextlib.suppress(OSError, asyncio.IncompleteReadError):
            while True:
                if self.modbus:
                    head = await up_r.readexactly(7)
                    pdu = await up_r.readexactly(struct.unpack(">H", head[4:6])[0] - 1)
                    if self.mode == "cut":  # the link breaks: the reply never arrives
                        break
                    out = self._modbus(head, pdu)
                else:
                    out = self._line(await up_r.readline())
                    if not out:
                        break
                writer.write(out)
                await writer.drain()
        task.cancel()
        writer.close()

    def _modbus(self, head: bytes, pdu: bytes) -> bytes:
        fc = pdu[0]
        if self.mode == "short" and fc in (3, 4, 23) and len(pdu) > 6:
            pdu = bytes([fc, pdu[1] - 4]) + pdu[2:-4]
        elif self.mode.startswith("exception:"):
            pdu = bytes([fc | 0x80, int(self.mode.split(":")[1])])
        elif self.mode == "garbage":
            return os.urandom(len(head) + len(pdu))
        return head[:4] + struct.pack(">H", len(pdu) + 1) + head[6:7] + pdu

    def _line(self, line: bytes) -> bytes:
        if self.mode == "garbage-line" and line:
            return b"\x00\xff%%% not a reply at all\n"
        if self.mode == "truncated" and line.startswith(b"OK "):
            return b" ".join(line.split()[:2]) + b"\n"  # OK and its first key=value only
        return line


@pytest.mark.parametrize(("mode", "expected"), [
    ("short", "registers, expected 12"),
    ("exception:4", "Modbus exception 04 SERVER_DEVICE_FAILURE"),
    ("exception:6", "Modbus exception 06 SERVER_DEVICE_BUSY"),
    ("exception:11", "Modbus exception 11 GATEWAY_TARGET_NO_RESPONSE"),
    ("garbage", "link lost"),
])
def test_bad_modbus_replies_hold_with_a_clear_reason(tmp_path: Path, mode: str,
                                                     expected: str) -> None:
    (port,) = free_ports(1)
    with sim_actuator("modbus", port), ReplyCorruptor(port, modbus=True) as proxy, \
            RunningBridge(bridge_toml("modbus", proxy.port, recovery=NO_RECOVERY), tmp_path) as b:
        with GenericClientLink("127.0.0.1", b.ports["act"], 1, data_size=1,
                               timeout=10.0) as link:
            drive(link, range(1, 4))
            proxy.mode = mode
            t0 = time.monotonic()
            link.set_trial((0.2,), time=0.04)
            assert math.isnan(link.force()[0])  # HOLD: told to stop
            assert time.monotonic() - t0 < TIMEOUT + 1.0
            state, reason = site_state(b)
            assert state == "HOLD", reason
            assert f"modbus controller 127.0.0.1:{proxy.port}" in reason
            assert expected in reason, reason
            link.commit()
        proxy.mode = "pass"
        # never a crash: the bridge serves the next session through the healed link
        with GenericClientLink("127.0.0.1", b.ports["act"], 1, data_size=1,
                               timeout=10.0) as link:
            assert drive(link, range(1, 3)) == pytest.approx([-K * 0.05, K * 0.1], rel=1e-6)
            assert site_state(b) == ("RUNNING", "")


@pytest.mark.parametrize(("mode", "expected"), [
    ("garbage-line", "malformed reply to 'STATUS'"),
    ("truncated", "reply lacks a numeric 'heartbeat'"),
])
def test_bad_mts_lines_hold_with_a_clear_reason(tmp_path: Path, mode: str,
                                                expected: str) -> None:
    (port,) = free_ports(1)
    with sim_actuator("mts", port), ReplyCorruptor(port, modbus=False) as proxy, \
            RunningBridge(bridge_toml("mts", proxy.port, recovery=NO_RECOVERY), tmp_path) as b:
        with GenericClientLink("127.0.0.1", b.ports["act"], 1, data_size=1,
                               timeout=10.0) as link:
            drive(link, range(1, 4))
            proxy.mode = mode
            link.set_trial((0.2,), time=0.04)
            assert math.isnan(link.force()[0])  # HOLD: told to stop
            state, reason = site_state(b)
            assert state == "HOLD"
            assert f"mts controller 127.0.0.1:{proxy.port}" in reason and expected in reason
            link.commit()
        proxy.mode = "pass"
        with GenericClientLink("127.0.0.1", b.ports["act"], 1, data_size=1,
                               timeout=10.0) as link:
            assert drive(link, range(1, 3)) == [-K * 0.05, K * 0.1]


def test_controller_killed_mid_move_the_move_is_not_resent(tmp_path: Path) -> None:
    """A 0.4 s ramp in real time; the controller dies 0.15 s into it."""
    (port,) = free_ports(1)
    toml = bridge_toml("modbus", port, recovery=NO_RECOVERY, ramp_time=0.4)
    with sim_actuator("modbus", port, "--time-scale", "1.0") as proc, \
            RunningBridge(toml, tmp_path) as b, \
            GenericClientLink("127.0.0.1", b.ports["act"], 1, data_size=1, timeout=10.0) as link:
        drive(link, range(1, 3))
        link.set_trial((0.5,), time=0.03)
        time.sleep(0.15)
        proc.kill()
        proc.wait(5)
        assert math.isnan(link.force()[0])  # HOLD: told to stop
        state, reason = site_state(b)
        assert state == "HOLD"
        assert "move to 0.5 mm" in reason and "it is not retried" in reason, reason
        link.commit()
        with sim_actuator("modbus", port):
            for i in range(4, 8):
                link.set_trial((0.1 * i,), time=0.01 * i)
                link.force()
                link.commit()
            assert modbus_registers(port)["sequence"] == 0  # nothing re-sent, nothing new


def test_link_cut_while_the_controller_lives_leaves_its_command_unchanged(
        tmp_path: Path) -> None:
    """The controller keeps running; only the bridge's link breaks. During HOLD it must keep
    the last good command: same target, no further move (the bridge may engage its interlock,
    which is not motion)."""
    (port,) = free_ports(1)
    with sim_actuator("modbus", port), ReplyCorruptor(port, modbus=True) as proxy, \
            RunningBridge(bridge_toml("modbus", proxy.port, recovery=NO_RECOVERY), tmp_path) as b, \
            GenericClientLink("127.0.0.1", b.ports["act"], 1, data_size=1, timeout=10.0) as link:
        drive(link, range(1, 6))
        last = modbus_registers(port)
        assert last["sequence"] == 5 and last["target"] == pytest.approx(-0.25)
        proxy.mode = "cut"
        link.set_trial((0.3,), time=0.06)
        link.force()
        state, reason = site_state(b)
        assert state == "HOLD" and "link lost" in reason, reason
        proxy.mode = "pass"  # the link could be re-established now; the site still holds
        for i in range(7, 12):
            link.set_trial((0.05 * i,), time=0.01 * i)
            link.force()
            link.commit()
        now = modbus_registers(port)
        assert now["target"] == last["target"] and now["sequence"] == last["sequence"]
        assert now["state"] in (2, 4)  # DONE, or INTERLOCK engaged by the bridge's hold


def _ctl(action: str, run_dir: Path) -> subprocess.CompletedProcess[str]:
    return subprocess.run(
        [sys.executable, "-m", "fresco_bridge.cli", "ctl", action, "--site", "act",
         "--run-dir", str(run_dir)], capture_output=True, text=True, timeout=30)


def _drop(link: GenericClientLink) -> None:
    """Close a link the bridge already closed (no DIE: the session is gone)."""
    if link.sock is not None:
        link.sock.close()
        link.sock = None


def test_controller_gone_for_good_the_operator_aborts_the_session_cleanly(
        tmp_path: Path) -> None:
    """The other way out of a controller loss without recovery: it does not come back, the
    operator aborts (``fresco-bridge ctl abort``); the held session's answers are NaN (so the
    integrator stops and sends DIE), the record says why, no new session is accepted until the
    operator resumes."""
    (port,) = free_ports(1)
    with sim_actuator("modbus", port) as proc, \
            RunningBridge(bridge_toml("modbus", port, recovery=NO_RECOVERY), tmp_path) as b:
        run_dir = b.run_dir
        link = GenericClientLink("127.0.0.1", b.ports["act"], 1, data_size=1, timeout=10.0)
        link.connect()
        drive(link, range(1, 4))
        proc.kill()
        proc.wait(5)
        link.set_trial((0.2,), time=0.04)
        assert math.isnan(link.force()[0])  # HOLD: told to stop
        assert site_state(b)[0] == "HOLD"
        r = _ctl("abort", run_dir)
        assert r.returncode == 0, r.stdout + r.stderr
        assert site_state(b)[0] == "FAULT"
        link.set_trial((0.25,), time=0.05)
        assert math.isnan(link.force()[0])  # told to stop: NaN, never a stale force
        link.close()  # the integrator stops and sends DIE
        deadline = time.monotonic() + 10
        while b.call(lambda: b.bridge.sites["act"].peer):
            assert time.monotonic() < deadline, "the aborted session never closed"
            time.sleep(0.01)
        assert site_state(b)[0] == "FAULT"
        refused = GenericClientLink("127.0.0.1", b.ports["act"], 1, data_size=1, timeout=5.0)
        with pytest.raises(ConnectionError):  # closed (LinkError) or reset by the bridge
            refused.connect()
            refused.force()  # FAULT: new sessions are refused until an operator resumes
        _drop(refused)
        with sim_actuator("modbus", port):
            r = _ctl("resume", run_dir)
            assert r.returncode == 0, r.stdout + r.stderr
            with GenericClientLink("127.0.0.1", b.ports["act"], 1, data_size=1,
                                   timeout=10.0) as link2:
                assert drive(link2, range(1, 3)) == pytest.approx([-K * 0.05, K * 0.1],
                                                                  rel=1e-6)
            wait_idle(b)
    events = [r.get("event") for r in read_record(run_dir) if r.get("kind") == "event"]
    # the HOLD already told the integrator to stop (NaN); the abort then ends it for good
    assert events.index("hold") < events.index("integrator-stop") < events.index("abort") \
        < events.index("resume")
    assert events.count("integrator-stop") == 1


# -- controller recovery (bridge.controller_recovery > 0) ------------------------------------


def wait_recovering(b: BridgeThread, timeout: float = 10.0) -> None:
    """Until the site waits for its lost controller inside the integrator's request."""
    deadline = time.monotonic() + timeout
    while b.call(lambda: b.bridge.sites["act"].guard.recovering_since) is None:
        assert time.monotonic() < deadline, site_state(b)
        time.sleep(0.01)


def site_events(run_dir: Path) -> list[dict[str, object]]:
    return [r for r in read_record(run_dir) if r.get("kind") == "event"]


@pytest.mark.parametrize("protocol", ["modbus", "mts"])
def test_controller_killed_and_back_within_the_window_the_same_session_goes_on(
        tmp_path: Path, protocol: str) -> None:
    """The controller process dies between steps and is restarted (a fresh rig at 0 mm) while
    the integrator's step waits: the step is answered with the force of the restarted rig at
    the commanded position, sent once after the link was verified, and the run goes on."""
    (port,) = free_ports(1)
    with sim_actuator(protocol, port) as proc, \
            RunningBridge(bridge_toml(protocol, port, recovery=20.0), tmp_path) as b:
        run_dir = b.run_dir
        with GenericClientLink("127.0.0.1", b.ports["act"], 1, data_size=1,
                               timeout=30.0) as link:
            drive(link, range(1, 11))
            proc.kill()
            proc.wait(5)
            link.set_trial((0.55,), time=0.11)  # no reply: the bridge holds and waits
            wait_recovering(b)
            assert site_state(b)[0] == "HOLD"
            status = _ctl("status", run_dir)
            assert "waits for the lost controller to answer again" in status.stdout, status
            time.sleep(0.5)  # a few probes fail meanwhile
            with sim_actuator(protocol, port):
                force = link.force()[0]  # the same request, answered with fresh data
                assert force == pytest.approx(K * 0.55, rel=1e-6)
                assert site_state(b) == ("RUNNING", "")
                if protocol == "modbus":
                    regs = modbus_registers(port)  # the restarted controller got one move
                    assert regs["sequence"] == 1 and regs["target"] == pytest.approx(0.55)
                link.commit()
                later = drive(link, range(12, 20))
                assert later == pytest.approx([K * 0.05 * i * (-1) ** i for i in range(12, 20)],
                                              rel=1e-6)
                if protocol == "modbus":
                    assert modbus_registers(port)["sequence"] == 9
        wait_idle(b)
    steps = committed_steps(run_dir)
    assert [(s.session, s.step) for s in steps] == [(1, i) for i in range(1, 20)]
    kinds = [str(e.get("event")) for e in site_events(run_dir)]
    assert "recovery-failed" not in kinds
    hold = kinds.index("hold")
    assert kinds[hold:hold + 2] == ["hold", "recovering"]
    assert kinds.index("recovered") > hold and kinds.count("hold") == 1
    recovered = next(e for e in site_events(run_dir) if e.get("event") == "recovered")
    assert recovered["from"] == "HOLD" and recovered["to"] == "RUNNING"
    assert "the same setpoint [0.55] mm is sent once" in str(recovered["reason"])
    assert float(str(recovered["elapsed"])) >= 0.5


@pytest.mark.parametrize("fault", ["killed", "link-cut"])
def test_controller_not_back_within_the_window_the_session_ends_cleanly(
        tmp_path: Path, fault: str) -> None:
    """Killed for good, or alive behind a link that stays cut: after controller_recovery the
    integrator is told to stop (NaN answers instead of stale forces; it sends DIE), the
    actuator's command is the last good one, and the next session is served once it is back."""
    window = 1.5
    (port,) = free_ports(1)
    with contextlib.ExitStack() as stack:
        proc = stack.enter_context(sim_actuator("modbus", port))
        proxy = stack.enter_context(ReplyCorruptor(port, modbus=True))
        b = stack.enter_context(RunningBridge(
            bridge_toml("modbus", proxy.port, recovery=window), tmp_path))
        run_dir = b.run_dir
        link = GenericClientLink("127.0.0.1", b.ports["act"], 1, data_size=1, timeout=30.0)
        link.connect()
        drive(link, range(1, 6))
        last = modbus_registers(port)
        assert last["sequence"] == 5 and last["target"] == pytest.approx(-0.25)
        if fault == "killed":
            proc.kill()
            proc.wait(5)
        else:
            proxy.mode = "cut"
        t0 = time.monotonic()
        link.set_trial((0.3,), time=0.06)
        assert math.isnan(link.force()[0])
        elapsed = time.monotonic() - t0
        assert window <= elapsed < window + TIMEOUT + 2.0, elapsed
        link.set_trial((0.35,), time=0.07)  # and so on until the integrator gives up
        assert math.isnan(link.force()[0])
        assert all(math.isnan(v) for row in link.matrix(Action.GET_TANGENT_STIFF) for v in row)
        link.close()  # DIE
        wait_idle(b)
        if fault == "link-cut":  # the live controller kept its last good command
            now = modbus_registers(port)
            assert now["target"] == last["target"] and now["sequence"] == last["sequence"]
            assert now["state"] in (2, 4)  # DONE, or INTERLOCK engaged by the bridge's hold
            proxy.mode = "pass"
        else:
            stack.enter_context(sim_actuator("modbus", port))
        with GenericClientLink("127.0.0.1", b.ports["act"], 1, data_size=1,
                               timeout=10.0) as link2:
            assert drive(link2, range(1, 3)) == pytest.approx([-K * 0.05, K * 0.1], rel=1e-6)
        wait_idle(b)
    events = site_events(run_dir)
    kinds = [str(e.get("event")) for e in events]
    assert kinds.index("hold") < kinds.index("recovering") < kinds.index("recovery-failed")
    assert "recovered" not in kinds
    failed = next(e for e in events if e.get("event") == "recovery-failed")
    assert f"within controller_recovery {window:g} s" in str(failed["reason"])
    assert "modbus controller" in str(failed["reason"])
    stop = next(e for e in events if e.get("event") == "integrator-stop")
    assert "controller_recovery" in str(stop["reason"])
    close = next(e for e in events if e.get("event") == "session-close" and e.get("from") == "HOLD")
    assert close["to"] == "IDLE" and "DIE" in str(close["reason"])
    assert [s.session for s in committed_steps(run_dir)] == [1] * 5 + [2] * 2


def test_a_controller_fault_is_not_recovered(tmp_path: Path) -> None:
    """A command beyond the stroke latches STROKE_LIMIT in the controller: it answers, so this
    is no link loss; the site holds at once (NaN answers, as without recovery)."""
    (port,) = free_ports(1)
    with sim_actuator("modbus", port), \
            RunningBridge(bridge_toml("modbus", port, recovery=20.0), tmp_path) as b, \
            GenericClientLink("127.0.0.1", b.ports["act"], 1, data_size=1, timeout=30.0) as link:
        drive(link, range(1, 4))
        t0 = time.monotonic()
        link.set_trial((150.0,), time=0.04)  # the rig's half stroke is 100 mm
        assert math.isnan(link.force()[0])  # HOLD: told to stop
        assert time.monotonic() - t0 < TIMEOUT
        state, reason = site_state(b)
        assert state == "HOLD" and "STROKE_LIMIT" in reason, reason
        assert b.call(lambda: b.bridge.sites["act"].guard.recovering_since) is None
        link.commit()
        run_dir = b.run_dir
    kinds = [str(e.get("event")) for e in site_events(run_dir)]
    assert "hold" in kinds and "recovering" not in kinds and "recovered" not in kinds


def test_operator_abort_ends_a_recovery_at_once(tmp_path: Path) -> None:
    (port,) = free_ports(1)
    with sim_actuator("modbus", port) as proc, \
            RunningBridge(bridge_toml("modbus", port, recovery=60.0), tmp_path) as b:
        run_dir = b.run_dir
        link = GenericClientLink("127.0.0.1", b.ports["act"], 1, data_size=1, timeout=30.0)
        link.connect()
        drive(link, range(1, 4))
        proc.kill()
        proc.wait(5)
        link.set_trial((0.2,), time=0.04)
        wait_recovering(b)
        t0 = time.monotonic()
        r = _ctl("abort", run_dir)
        assert r.returncode == 0, r.stdout + r.stderr
        assert math.isnan(link.force()[0])  # the waiting request: told to stop at once
        assert time.monotonic() - t0 < 10.0  # not the 60 s window
        link.close()
        assert site_state(b)[0] == "FAULT"
        assert b.call(lambda: b.bridge.sites["act"].guard.recovering_since) is None
        with sim_actuator("modbus", port) as back:
            r = _ctl("resume", run_dir)
            assert r.returncode == 0, r.stdout + r.stderr
            assert modbus_registers(port)["sequence"] == 0  # nothing was sent to it
            with GenericClientLink("127.0.0.1", b.ports["act"], 1, data_size=1,
                                   timeout=10.0) as link2:
                assert drive(link2, range(1, 3)) == pytest.approx([-K * 0.05, K * 0.1],
                                                                  rel=1e-6)
            wait_idle(b)
            assert back.poll() is None
    kinds = [str(e.get("event")) for e in site_events(run_dir)]
    assert kinds.index("hold") < kinds.index("recovering") < kinds.index("abort")
    assert "recovered" not in kinds and "recovery-failed" not in kinds


def test_client_gone_during_recovery_ends_it_and_sends_nothing(tmp_path: Path) -> None:
    """The integrator vanishes while its step waits for the controller: the wait is cancelled
    at once (its command must never reach a controller that comes back later)."""
    (port,) = free_ports(1)
    with sim_actuator("modbus", port) as proc, \
            RunningBridge(bridge_toml("modbus", port, recovery=60.0), tmp_path) as b:
        link = GenericClientLink("127.0.0.1", b.ports["act"], 1, data_size=1, timeout=30.0)
        link.connect()
        drive(link, range(1, 4))
        proc.kill()
        proc.wait(5)
        link.set_trial((0.2,), time=0.04)
        wait_recovering(b)
        _drop(link)  # no DIE: the process is gone
        wait_idle(b, timeout=5.0)
        with sim_actuator("modbus", port):
            time.sleep(0.5)
            assert modbus_registers(port)["sequence"] == 0
        run_dir = b.run_dir
    kinds = [str(e.get("event")) for e in site_events(run_dir)]
    assert "recovering" in kinds and "recovered" not in kinds


def test_hung_controller_that_wakes_up_within_the_window_is_recovered(tmp_path: Path) -> None:
    """SIGSTOP: the controller accepts TCP but never answers (the call misses its deadline);
    SIGCONT within the window: the same request is answered, no move was lost or doubled."""
    (port,) = free_ports(1)
    with sim_actuator("modbus", port) as proc, \
            RunningBridge(bridge_toml("modbus", port, recovery=20.0), tmp_path) as b, \
            GenericClientLink("127.0.0.1", b.ports["act"], 1, data_size=1, timeout=30.0) as link:
        drive(link, range(1, 6))
        os.kill(proc.pid, signal.SIGSTOP)
        link.set_trial((0.3,), time=0.06)
        wait_recovering(b)
        time.sleep(TIMEOUT + 0.5)  # past a probe's deadline at least once
        os.kill(proc.pid, signal.SIGCONT)
        assert link.force()[0] == pytest.approx(K * 0.3, rel=1e-6)
        assert site_state(b) == ("RUNNING", "")
        link.commit()
        assert drive(link, range(7, 9)) == pytest.approx([-K * 0.35, K * 0.4], rel=1e-6)
        regs = modbus_registers(port)
        assert regs["target"] == pytest.approx(0.4) and regs["state"] == 2  # DONE, released
        run_dir = b.run_dir
    events = site_events(run_dir)
    kinds = [str(e.get("event")) for e in events]
    assert kinds.index("hold") < kinds.index("recovering") < kinds.index("recovered")
    hold = next(e for e in events if e.get("event") == "hold")
    assert any(w in str(hold["reason"]) for w in ("No response", "did not answer")), hold
    assert [s.step for s in committed_steps(run_dir)] == list(range(1, 9))


def test_recovery_does_not_jump_a_restarted_actuator_past_the_increment_limit(
        tmp_path: Path) -> None:
    """The restarted rig is at 0 mm, the integrator's step wants 0.55 mm: the increment limit
    (0.2 mm) is checked against the measured position, not the last command (0.5 mm), so the
    setpoint is not re-sent and the integrator is told to stop, with the reason."""
    (port,) = free_ports(1)
    limits = "[[sites.limits]]\ndisp_increment = 0.2\n"
    with sim_actuator("modbus", port) as proc, \
            RunningBridge(bridge_toml("modbus", port, recovery=20.0) + limits, tmp_path) as b:
        run_dir = b.run_dir
        link = GenericClientLink("127.0.0.1", b.ports["act"], 1, data_size=1, timeout=30.0)
        link.connect()
        for i in range(1, 11):  # a slow ramp to 0.5 mm, every increment 0.05 mm
            link.set_trial((0.05 * i,), time=0.01 * i)
            assert link.force()[0] == pytest.approx(K * 0.05 * i, rel=1e-6)
            link.commit()
        proc.kill()
        proc.wait(5)
        link.set_trial((0.55,), time=0.11)
        wait_recovering(b)
        with sim_actuator("modbus", port):
            assert math.isnan(link.force()[0])  # told to stop
            link.close()
            wait_idle(b)
            assert modbus_registers(port)["sequence"] == 0  # the jump was never commanded
    failed = next(e for e in site_events(run_dir) if e.get("event") == "recovery-failed")
    reason = str(failed["reason"])
    assert "actuator at [0.0] mm" in reason and "re-sending [0.55] mm" in reason, reason
    assert "increment" in reason and "not sent" in reason, reason


@pytest.mark.opensees
def test_opensees_run_survives_a_controller_restart_with_correct_physics(tmp_path: Path) -> None:
    """A real OpenSeesPy genericClient (static load ramp on the specimen, ``Linear``): the
    controller process is killed mid-run (mostly mid-ramp: 20 ms real-time ramps) and restarted;
    the run completes in the same session and every step equals the pure-OpenSees reference
    within the float32 register resolution (a stale force would be off by a whole step)."""
    nsteps, load = 120, 68.0 * 1.2  # u goes to 1.2 mm
    params = {"load": load, "nsteps": nsteps, "algorithm": ["Linear"]}
    (port,) = free_ports(1)
    with sim_actuator("modbus", port, "--time-scale", "1.0") as proc, \
            RunningBridge(bridge_toml("modbus", port, recovery=20.0, ramp_time=0.02),
                          tmp_path) as b:
        run_dir = b.run_dir
        client = subprocess.Popen(
            [sys.executable, str(OPENSEES_SCRIPT), "static_1dof",
             json.dumps({**params, "port": b.ports["act"]})],
            env=opensees_env(), stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
        try:
            deadline = time.monotonic() + 60
            while b.call(lambda: b.bridge.sites["act"].step) < 30:
                assert time.monotonic() < deadline and client.poll() is None
                time.sleep(0.005)
            proc.kill()
            proc.wait(5)
            wait_recovering(b)
            time.sleep(0.3)
            with sim_actuator("modbus", port, "--time-scale", "1.0"):
                out, err = client.communicate(timeout=120)
        finally:
            if client.poll() is None:
                client.kill()
                client.wait(10)
        wait_idle(b)
    assert client.returncode == 0, err[-2000:]
    got = json.loads(next(ln for ln in out.splitlines() if ln.startswith("RESULT "))[7:])
    ref = run_opensees("static_1dof", port=None, material=["Elastic", 1, 68.0], **params)
    assert got["u"] == pytest.approx(ref["u"], rel=1e-5)
    assert got["force"] == pytest.approx(ref["force"], rel=1e-5)
    kinds = [str(e.get("event")) for e in site_events(run_dir)]
    assert kinds.index("hold") < kinds.index("recovering") < kinds.index("recovered")
    assert "recovery-failed" not in kinds
    assert {s.session for s in committed_steps(run_dir)} == {1}
    assert len(committed_steps(run_dir)) == nsteps


@pytest.mark.opensees
def test_opensees_stops_by_itself_instead_of_running_on_frozen_forces(tmp_path: Path) -> None:
    """Killed for good: after controller_recovery the bridge answers NaN, so the real OpenSeesPy
    client stops on its own — its analysis fails or ends in NaN, never a plausible result built
    on frozen forces — and its exit closes the session. (Closing the connection instead would
    not stop it: OpenFresco's ``TCP_Socket::recvVector`` ignores recv's 0/-1 and OpenSees spins
    in its receive loop forever; see docs/safety.md.)"""
    window = 1.5
    (port,) = free_ports(1)
    with sim_actuator("modbus", port, "--time-scale", "1.0") as proc, \
            RunningBridge(bridge_toml("modbus", port, recovery=window, ramp_time=0.02),
                          tmp_path) as b:
        run_dir = b.run_dir
        client = subprocess.Popen(
            [sys.executable, str(OPENSEES_SCRIPT), "static_1dof",
             json.dumps({"load": 68.0, "nsteps": 120, "algorithm": ["Linear"],
                         "port": b.ports["act"]})],
            env=opensees_env(), stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
        try:
            deadline = time.monotonic() + 60
            while b.call(lambda: b.bridge.sites["act"].step) < 30:
                assert time.monotonic() < deadline and client.poll() is None
                time.sleep(0.005)
            proc.kill()
            t0 = time.monotonic()
            wait_recovering(b)
            out, _ = client.communicate(timeout=window + TIMEOUT + 60)  # no kill: it stops
            assert time.monotonic() - t0 >= window
        finally:
            if client.poll() is None:
                client.kill()
                client.communicate(timeout=10)
        wait_idle(b)  # the client's exit closed the session
        result = [ln for ln in out.splitlines() if ln.startswith("RESULT ")]
        if client.returncode == 0:  # Linear ran to the end: on NaN, unmistakably
            u = json.loads(result[-1][len("RESULT "):])["u"]
            assert all(math.isfinite(v) for v in u[:29]) and math.isnan(u[-1]), u
        else:
            assert not result  # the analysis failed: no result at all
        with sim_actuator("modbus", port), \
                GenericClientLink("127.0.0.1", b.ports["act"], 1, data_size=1,
                                  timeout=10.0) as link:  # the bridge serves the next session
            assert drive(link, range(1, 3)) == pytest.approx([-K * 0.05, K * 0.1], rel=1e-6)
        wait_idle(b)
    events = site_events(run_dir)
    failed = [e for e in events if e.get("event") == "recovery-failed"]
    assert len(failed) == 1 and "controller_recovery 1.5 s" in str(failed[0]["reason"])
    assert "recovered" not in [e.get("event") for e in events]
    session1 = [s for s in committed_steps(run_dir) if s.session == 1]
    assert 30 <= len(session1) < 120
