"""Limits on a real bridge over real sockets: each limit under each policy, sub-stepping, force
limits, and an integrator killed mid-step. What reaches the controller is observed with a spy on
the real in-process specimen's ``set_ctrl``; ``pause`` is resumed through the real control socket.
"""

from __future__ import annotations

import itertools
import math
import subprocess
import sys
import threading
import time
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import pytest

from fresco_bridge.cli import main as cli_main
from fresco_bridge.daemon import BridgeThread
from fresco_bridge.integrator.link import GenericClientLink
from fresco_bridge.record import read_record
from fresco_bridge.record.export import committed_steps
from fresco_bridge.sites import SiteState
from protocol import Action
from tests.support.bridge import RunningBridge, run_opensees
from tests.support.opensees_frame import frame_config, frame_params, rel_diff
from tests.support.spied_bridge import (
    BEYOND,
    LIMITS,
    WITHIN,
    K,
    config,
    first_step,
    good_session,
    refused,
    spy,
    state,
    wait_for,
)

CLAMPED = {"absolute": 1.0, "increment": 0.9, "velocity": 0.9}


def events(bridge: BridgeThread, kind: str) -> list[dict[str, Any]]:
    return [r for r in read_record(bridge.run_dir) if r.get("event") == kind]


@pytest.fixture
def run_root(tmp_path: Path) -> Path:
    return tmp_path


@pytest.mark.parametrize("kind", list(LIMITS))
def test_reject_holds_and_never_forwards(run_root: Path, kind: str) -> None:
    with RunningBridge(config(LIMITS[kind], "reject"), run_root) as bridge:
        sent = spy(bridge)
        with GenericClientLink("127.0.0.1", bridge.ports["spec"], 1, data_size=1) as link:
            first_step(link)
            link.set_trial((BEYOND[kind],), time=0.2)
            # answered (no hang), never from the rejected command: NaN, so the integrator stops
            assert math.isnan(link.force()[0])
            assert state(bridge) is SiteState.HOLD
            link.set_trial((0.45,), time=0.3)  # nothing at all is forwarded in HOLD
            assert math.isnan(link.force()[0])
        assert sent == [(WITHIN,)]
        (limit,) = events(bridge, "limit")
        assert (limit["limit"], limit["policy"], limit["action"]) == (kind, "reject", "reject")
        assert limit["signal"] == "ctrl disp[1]"
        (hold,) = events(bridge, "hold")
        assert "not forwarded" in hold["reason"] and kind in hold["reason"]
        wait_for(lambda: state(bridge) is SiteState.IDLE, "IDLE after the session")
        good_session(bridge.ports["spec"])  # the next client is served


@pytest.mark.parametrize("kind", list(LIMITS))
def test_clamp_forwards_the_clamped_command_and_records_every_hit(run_root: Path,
                                                                  kind: str) -> None:
    with RunningBridge(config(LIMITS[kind], "clamp"), run_root) as bridge:
        sent = spy(bridge)
        with GenericClientLink("127.0.0.1", bridge.ports["spec"], 1, data_size=1) as link:
            first_step(link)
            link.set_trial((BEYOND[kind],), time=0.2)
            # the integrator sees what the specimen really did: the force at the clamped stroke
            assert link.force()[0] == pytest.approx(K * CLAMPED[kind])
            link.commit()
            assert state(bridge) is SiteState.RUNNING
        assert sent == [(WITHIN,), (pytest.approx(CLAMPED[kind]),)]
        hits = events(bridge, "limit")
        assert [(h["limit"], h["action"]) for h in hits] == [(kind, "clamp")]
        steps = [s for s in committed_steps(bridge.run_dir) if s.site == "spec"]
        assert [s.cmd_disp[0] for s in steps] == pytest.approx([WITHIN, CLAMPED[kind]])


def _resume_via_cli(bridge: BridgeThread, capsys: pytest.CaptureFixture[str]) -> str:
    assert cli_main(["ctl", "resume", "--site", "spec", "--run-dir", str(bridge.run_dir)]) == 0
    return capsys.readouterr().out


@pytest.mark.parametrize("kind", ["increment", "velocity"])
def test_pause_waits_for_ctl_resume_then_forwards(run_root: Path, kind: str,
                                                  capsys: pytest.CaptureFixture[str]) -> None:
    with RunningBridge(config(LIMITS[kind], "pause"), run_root) as bridge:
        sent = spy(bridge)
        link = GenericClientLink("127.0.0.1", bridge.ports["spec"], 1, data_size=1,
                                 timeout=30.0).connect()
        first_step(link)
        replies: list[float] = []
        link.set_trial((BEYOND[kind],), time=0.2)
        waiter = threading.Thread(target=lambda: replies.append(link.force()[0]))
        waiter.start()
        wait_for(lambda: state(bridge) is SiteState.PAUSED, "PAUSED")
        time.sleep(0.2)
        assert replies == [] and sent == [(WITHIN,)]  # the integrator waits, nothing moved
        assert cli_main(["ctl", "status", "--run-dir", str(bridge.run_dir)]) == 0
        status = capsys.readouterr().out
        assert "PAUSED" in status and "waiting for an operator" in status and kind in status
        out = _resume_via_cli(bridge, capsys)
        assert "PAUSED → RUNNING" in out
        waiter.join(10)
        assert replies == [pytest.approx(K * BEYOND[kind])]  # approved: forwarded as asked
        assert sent == [(WITHIN,), (BEYOND[kind],)]
        link.commit()
        link.close()
        kinds = [r.get("event") for r in read_record(bridge.run_dir) if r["kind"] == "event"]
        assert kinds.index("limit") < kinds.index("pause") < kinds.index("resume")


def test_pause_on_an_absolute_limit_is_never_forwarded_even_after_resume(
    run_root: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    with RunningBridge(config(LIMITS["absolute"], "pause"), run_root) as bridge:
        sent = spy(bridge)
        link = GenericClientLink("127.0.0.1", bridge.ports["spec"], 1, data_size=1,
                                 timeout=30.0).connect()
        first_step(link)
        replies: list[float] = []
        link.set_trial((1.3,), time=0.2)
        waiter = threading.Thread(target=lambda: replies.append(link.force()[0]))
        waiter.start()
        wait_for(lambda: state(bridge) is SiteState.PAUSED, "PAUSED")
        _resume_via_cli(bridge, capsys)
        waiter.join(10)
        assert len(replies) == 1 and math.isnan(replies[0]) and sent == [(WITHIN,)]
        assert state(bridge) is SiteState.HOLD
        link.close()
        assert "absolute limit" in events(bridge, "hold")[0]["reason"]


def test_substeps_reach_the_controller_in_order(run_root: Path) -> None:
    limits = "disp_min = -5.0\ndisp_max = 5.0\nvelocity = 2.0\nstep_time = 0.1\n" \
             "max_substeps = 8\n"
    with RunningBridge(config(limits, "reject"), run_root) as bridge:
        sent = spy(bridge)
        with GenericClientLink("127.0.0.1", bridge.ports["spec"], 1, data_size=1) as link:
            link.set_trial((0.15,), time=0.1)  # within 0.2 mm per step
            assert link.force()[0] == pytest.approx(K * 0.15)
            link.commit()
            link.set_trial((0.95,), time=0.2)  # 0.8 mm: 4 sub-commands of 0.2 mm
            assert link.force()[0] == pytest.approx(K * 0.95)
            link.commit()
            link.set_trial((2.95,), time=0.3)  # 2 mm = 10 sub-steps > 8: rejected
            assert math.isnan(link.force()[0])  # HOLD: told to stop
        assert [c[0] for c in sent] == pytest.approx([0.15, 0.35, 0.55, 0.75, 0.95])
        assert sent[-1] == (0.95,)  # the last sub-command is exactly the target
        (sub,) = events(bridge, "substep")
        assert sub["substeps"] == 4
        assert [h["limit"] for h in events(bridge, "limit")] == ["velocity"]


def test_force_limit_holds_and_keeps_the_measurement_in_the_record(run_root: Path) -> None:
    with RunningBridge(config("force_min = -5.0\nforce_max = 5.0\n", "reject"),
                       run_root) as bridge:
        with GenericClientLink("127.0.0.1", bridge.ports["spec"], 1, data_size=1) as link:
            first_step(link)  # 4 kN
            link.set_trial((0.6,), time=0.2)  # 6 kN measured: beyond the daq limit
            assert math.isnan(link.force()[0])  # HOLD: told to stop
            assert state(bridge) is SiteState.HOLD
        (hit,) = events(bridge, "limit")
        assert (hit["limit"], hit["signal"], hit["value"]) == ("force", "daq force[1]", 6.0)
        daqs = [r for r in read_record(bridge.run_dir) if r["kind"] == "daq"]
        assert daqs[-1]["force"] == [pytest.approx(6.0)]


KILLED_CLIENT = """
import sys, time
from fresco_bridge.integrator.link import GenericClientLink
link = GenericClientLink("127.0.0.1", int(sys.argv[1]), 1, data_size=1).connect()
for i in range(1, 4):
    link.set_trial((0.1 * i,), time=0.1 * i)
    link.force()
    link.commit()
link.set_trial((0.35,), time=0.4)
link.force()
print("MID-STEP", flush=True)
time.sleep(60)
"""


@pytest.mark.opensees
def test_integrator_killed_mid_step_holds_then_idles_and_the_next_client_is_served(
    run_root: Path,
) -> None:
    with RunningBridge(config(LIMITS["absolute"], "reject"), run_root) as bridge:
        proc = subprocess.Popen([sys.executable, "-c", KILLED_CLIENT, str(bridge.ports["spec"])],
                                stdout=subprocess.PIPE, text=True)
        try:
            assert proc.stdout is not None and proc.stdout.readline().strip() == "MID-STEP"
            proc.kill()
        finally:
            proc.wait(10)
        wait_for(lambda: state(bridge) is SiteState.IDLE, "IDLE after the lost integrator")
        records = list(read_record(bridge.run_dir))  # every line parses: the record is intact
        (hold,) = [r for r in records if r.get("event") == "hold"]
        assert hold["cause"] == "integrator-lost" and "uncommitted command at step 4" in \
            hold["reason"]
        close = [r for r in records if r.get("event") == "session-close"][-1]
        assert (close["from"], close["to"]) == ("HOLD", "IDLE")
        steps = [s for s in committed_steps(bridge.run_dir) if s.site == "spec"]
        assert [s.step for s in steps] == [1, 2, 3]
        # a real OpenSees genericClient is served next (within the ±1 mm absolute limits)
        result = run_opensees("static_1dof", port=bridge.ports["spec"], load=8.0, nsteps=4)
        assert result["u"] == pytest.approx([0.2, 0.4, 0.6, 0.8])
        assert state(bridge) is SiteState.IDLE


@pytest.fixture
def paused_link(run_root: Path) -> Iterator[tuple[BridgeThread, GenericClientLink]]:
    with RunningBridge(config(LIMITS["absolute"], "reject"), run_root) as bridge:
        link = GenericClientLink("127.0.0.1", bridge.ports["spec"], 1, data_size=1,
                                 timeout=30.0).connect()
        first_step(link)
        yield bridge, link
        link.close()


def test_operator_pause_holds_the_next_trial_until_resume(
    paused_link: tuple[BridgeThread, GenericClientLink], capsys: pytest.CaptureFixture[str]
) -> None:
    bridge, link = paused_link
    sent = spy(bridge)
    assert cli_main(["ctl", "pause", "--run-dir", str(bridge.run_dir)]) == 0
    assert state(bridge) is SiteState.PAUSED
    replies: list[float] = []
    link.set_trial((0.5,), time=0.2)
    waiter = threading.Thread(target=lambda: replies.append(link.force()[0]))
    waiter.start()
    wait_for(lambda: bridge.call(lambda: bridge.bridge.sites["spec"].pending) is not None,
             "the command to wait")
    assert sent == [] and replies == []
    _resume_via_cli(bridge, capsys)
    waiter.join(10)
    assert replies == [pytest.approx(5.0)] and sent == [(0.5,)]


def test_abort_ends_the_session_refuses_new_ones_until_resume(
    paused_link: tuple[BridgeThread, GenericClientLink], capsys: pytest.CaptureFixture[str]
) -> None:
    bridge, link = paused_link
    assert cli_main(["ctl", "abort", "--site", "spec", "--run-dir", str(bridge.run_dir)]) == 0
    assert state(bridge) is SiteState.FAULT
    link.set_trial((0.5,), time=0.2)
    assert math.isnan(link.force()[0])  # told to stop: NaN, never a stale force
    assert all(math.isnan(v) for row in link.matrix(Action.GET_TANGENT_STIFF) for v in row)
    link.close()  # the integrator stops and sends DIE
    wait_for(lambda: bridge.call(lambda: bridge.bridge.sites["spec"].peer) == "",
             "the aborted session to end")
    assert refused(bridge.ports["spec"])  # while in FAULT
    assert cli_main(["ctl", "resume", "--run-dir", str(bridge.run_dir)]) == 0
    assert "FAULT → IDLE" in capsys.readouterr().out
    good_session(bridge.ports["spec"])
    kinds = [r.get("event") for r in read_record(bridge.run_dir) if r["kind"] == "event"]
    assert kinds[:7] == ["session-open", "abort", "integrator-stop", "session-close", "refused",
                         "resume", "session-open"]


@pytest.mark.opensees
def test_limits_that_are_not_hit_leave_a_real_opensees_run_unchanged(tmp_path: Path) -> None:
    """Two-story frame in real OpenSeesPy: with limits at 1.5× what the run needs (absolute,
    increment and velocity on both actuators), the bridge is still invisible (1e-9)."""
    ref_params: dict[str, Any] = frame_params(ports=None)
    ref = run_opensees("frame2", **ref_params)["runs"][0]
    strokes = {"story1": ref["u2"],
               "story2": [b - a for a, b in zip(ref["u2"], ref["u3"], strict=True)]}
    toml = frame_config()
    for name, stroke in strokes.items():
        peak = max(abs(x) for x in stroke)
        step = max(abs(b - a) for a, b in itertools.pairwise([0.0, *stroke]))
        block = (f"[[sites.limits]]\ndisp_min = {-1.5 * peak}\ndisp_max = {1.5 * peak}\n"
                 f"disp_increment = {1.5 * step}\nvelocity = {1.5 * step / 0.01}\n")
        head = f'name = "{name}"\n'
        at = toml.index(head)
        nxt = toml.find("[[sites]]", at)
        toml = toml[:nxt] + block + toml[nxt:] if nxt != -1 else toml + block
    with RunningBridge(toml, tmp_path) as bridge:
        params: dict[str, Any] = frame_params(
            ports=[bridge.ports["story1"], bridge.ports["story2"]])
        got = run_opensees("frame2", **params)["runs"][0]
        assert all(len(s.cfg.limits) == 1 for s in bridge.bridge.sites.values())
        run_dir = bridge.run_dir
    assert rel_diff(got["u2"], ref["u2"]) <= 1e-9
    assert rel_diff(got["u3"], ref["u3"]) <= 1e-9
    assert not [r for r in read_record(run_dir) if r.get("event") in ("limit", "hold")]


def test_pause_and_resume_over_udp(run_root: Path, capsys: pytest.CaptureFixture[str]) -> None:
    toml = config(LIMITS["increment"], "pause").replace("port = 0\n",
                                                        'port = 0\ntransport = "udp"\n')
    with RunningBridge(toml, run_root) as bridge:
        sent = spy(bridge)
        link = GenericClientLink("127.0.0.1", bridge.ports["spec"], 1, data_size=1,
                                 transport="udp", timeout=30.0).connect()
        first_step(link)
        replies: list[float] = []
        link.set_trial((1.3,), time=0.2)
        waiter = threading.Thread(target=lambda: replies.append(link.force()[0]))
        waiter.start()
        wait_for(lambda: state(bridge) is SiteState.PAUSED, "PAUSED")
        time.sleep(0.2)
        assert replies == [] and sent == [(WITHIN,)]
        _resume_via_cli(bridge, capsys)
        waiter.join(10)
        assert replies == [pytest.approx(K * 1.3)] and sent == [(WITHIN,), (1.3,)]
        link.commit()
        link.close()


def test_a_finite_trial_whose_setup_transform_overflows_is_never_forwarded(
    run_root: Path,
) -> None:
    toml = config(LIMITS["absolute"], "clamp").replace(
        "port = 0\n", 'port = 0\ndofs = 2\nsetup = "OneActuator"\n')
    with RunningBridge(toml, run_root) as bridge:
        sent = spy(bridge)
        with GenericClientLink("127.0.0.1", bridge.ports["spec"], 2, data_size=2) as link:
            link.set_trial((0.0, 0.4), time=0.1)
            assert link.force()[1] == pytest.approx(K * 0.4)
            link.commit()
            link.set_trial((-1e308, 1e308), time=0.2)  # stroke u_j - u_i = inf
            assert all(math.isnan(f) for f in link.force())  # HOLD: told to stop
            assert state(bridge) is SiteState.HOLD
        assert sent == [(0.4,)]
        assert "non-finite ctrl" in events(bridge, "hold")[0]["reason"]
