"""An updatable site served to a real OpenSeesPy genericClient: the two-story frame with its
story-1 damper on an experimental site (the in-process sim law) and its story-2 damper on an
updatable site learning from it in a worker process, causality ``previous-step``."""

from __future__ import annotations

import math
import os
import signal
import threading
import time
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from fresco_bridge.record.export import committed_steps
from fresco_bridge.report.html import write_report
from fresco_bridge.runs import load_run
from fresco_bridge.updating.histories import read_history
from fresco_bridge.updating.registry import make_updater
from fresco_bridge.updating.replay import replay
from tests.support.bridge import RunningBridge, run_opensees
from tests.support.controller import sim_actuator
from tests.support.net import free_ports
from tests.support.opensees_frame import BILINEAR, frame_params, rel_diff
from tests.support.twins import learners_of

pytest.importorskip("openseespy")

STORY2 = {"k0": 15.0, "fy": 10.0, "alpha": 0.05}
NSTEPS = 150


def _params(d: dict[str, float]) -> str:
    return "{ " + ", ".join(f"{k} = {v!r}" for k, v in d.items()) + " }"


def frame_toml(twin: str) -> str:
    """story1: the tested damper (sim bilinear); story2: the updatable site ``twin`` (TOML)."""
    return (
        '[bridge]\nrun_name = "twin"\n'
        '[[sites]]\nname = "story1"\nport = 0\ndofs = 2\nsetup = "OneActuator"\n'
        f'[sites.controller]\nmodel = "bilinear"\nparams = {_params(BILINEAR)}\n'
        '[[sites]]\nname = "story2"\nport = 0\ndofs = 2\nsetup = "OneActuator"\n'
        'kind = "updatable"\nlearns_from = "story1"\n' + twin
    )


def run_frame(toml: str, tmp_path: Path, **extra: Any) -> tuple[dict[str, Any], Path]:
    with RunningBridge(toml, tmp_path) as bridge:
        ports = [bridge.ports["story1"], bridge.ports["story2"]]
        result = run_opensees("frame2", **frame_params(ports=ports, nsteps=NSTEPS, **extra))
        # OpenSees' last commit and DIE need no reply: let the bridge handle them before it
        # stops (a twin's last step may still be with its learner)
        end = time.monotonic() + 30
        while bridge.call(lambda: any(s.busy for s in bridge.bridge.sites.values())):
            assert time.monotonic() < end, "the sessions did not end after the client's DIE"
            time.sleep(0.02)
        run_dir = bridge.run_dir
    return result["runs"][0], run_dir


def test_twin_none_with_the_true_law_equals_pure_opensees(tmp_path: Path) -> None:
    toml = frame_toml(f'updater = "none"\n[sites.updater_options]\nmodel = "bilinear"\n'
                      f'params = {_params(STORY2)}\n')
    served, _ = run_frame(toml, tmp_path)
    story2 = ["Steel01", 2, STORY2["fy"], STORY2["k0"], STORY2["alpha"]]
    pure = run_opensees("frame2", **frame_params(nsteps=NSTEPS, story2=story2))["runs"][0]
    assert max(abs(x) for x in pure["u3"]) > 0.5  # the frame moved (story 1 yields)
    assert rel_diff(served["u2"], pure["u2"]) < 1e-9
    assert rel_diff(served["u3"], pure["u3"]) < 1e-9


def write_offline_csv(path: Path, n: int = 400) -> Path:
    """A short conventional test of the tested law: a growing sine, as ``time,disp,force``."""
    from sim_actuator.models import make_model

    law = make_model("bilinear", **BILINEAR)
    lines = ["time,disp,force"]
    for i in range(n):
        d = 3.0 * (i / n) * np.sin(2 * np.pi * i / 50)
        f, _ = law.set_trial(float(d))
        law.commit()
        lines.append(f"{0.01 * (i + 1)!r},{float(d)!r},{f!r}")
    path.write_text("\n".join(lines) + "\n")
    return path


def test_twin_online_improved_equals_the_in_process_previous_step_coupling(
        tmp_path: Path) -> None:
    offline = write_offline_csv(tmp_path / "char-test.csv")
    toml = frame_toml(f'updater = "online_improved"\noffline = "{offline}"\n')
    served, run_dir = run_frame(toml, tmp_path)
    assert all(np.isfinite(served["u3"])) and max(abs(x) for x in served["u3"]) < 100.0
    source = read_history(run_dir, site="story1")
    twin = read_history(run_dir, site="story2")
    assert source.disp.size == twin.disp.size == NSTEPS
    data = read_history(offline)
    updater = make_updater("online_improved", offline=(data.disp, data.force))
    expected = replay(updater, source.disp, source.force, twin.disp, lag=True).force_pred
    assert twin.force is not None
    scale = float(np.max(np.abs(expected)))
    assert scale > 1.0
    assert float(np.max(np.abs(twin.force - expected))) / scale < 1e-9
    # the record's update lines: each twin step learned through the source's step before it,
    # and the report draws them (from the run directory alone)
    updates = load_run(run_dir).updates
    assert [(u["site"], u["step"], u["through"]) for u in updates] == [
        ("story2", k, k - 1) for k in range(1, NSTEPS + 1)]
    assert all(math.isfinite(u["secs"]) and u["secs"] >= 0.0 for u in updates)
    # online_improved's one-step error on the source step learned, from twin step 2 on
    assert "err" not in updates[0]
    errors = [u["err"] for u in updates[1:]]
    assert all(math.isfinite(e) and e >= 0.0 for e in errors) and max(errors) > 0.0
    assert '<section id="updating-story2">' in write_report(run_dir).read_text()


def _wait(what: str, check: Any, deadline: float = 60.0) -> None:
    """Poll ``check()`` until true; fail naming ``what`` past ``deadline`` s."""
    end = time.monotonic() + deadline
    while not check():
        if time.monotonic() > end:
            raise AssertionError(f"{what}: not within {deadline:g} s")
        time.sleep(0.01)


class PauseAt:
    """A step listener of the source site that pauses it at a chosen step (deterministic
    mid-run: the integrator's next trial to the source waits for the operator)."""

    def __init__(self, site: Any, step: int) -> None:
        self.site, self.step = site, step

    def step_committed(self, step: Any) -> None:
        if step.step == self.step:
            self.site.operator_pause("test")


def test_worker_killed_mid_run_holds_the_twin_and_spares_the_source(tmp_path: Path) -> None:
    toml = frame_toml('updater = "none"\non_learner_loss = "hold"\n'
                      f'[sites.updater_options]\nmodel = "bilinear"\nparams = {_params(STORY2)}\n')
    with RunningBridge(toml, tmp_path) as bridge:
        sites = bridge.bridge.sites
        learner = learners_of(bridge)["story1"]
        bridge.call(lambda: sites["story1"].add_listener(PauseAt(sites["story1"], 40)))
        ports = [bridge.ports["story1"], bridge.ports["story2"]]
        failure: list[BaseException] = []

        def frame() -> None:
            try:
                run_opensees("frame2", **frame_params(ports=ports, nsteps=NSTEPS))
            except BaseException as exc:  # the NaN answers stop OpenSees: expected
                failure.append(exc)

        client = threading.Thread(target=frame, daemon=True)
        client.start()
        _wait("source paused at step 40", lambda: bridge.call(
            lambda: str(sites["story1"].state)) == "PAUSED")
        old_pid = learner.pid
        assert old_pid is not None
        os.kill(old_pid, signal.SIGKILL)
        _wait("twin site HOLD", lambda: bridge.call(lambda: str(sites["story2"].state)) == "HOLD")
        bridge.call(lambda: sites["story1"].operator_resume("test"))
        client.join(120)
        assert not client.is_alive()
        assert failure, "OpenSees finished although its twin was in HOLD"
        _wait("learner live again", lambda: bridge.call(lambda: learner.state) == "live")
        status = bridge.call(lambda: sites["story2"].status())
        source = bridge.call(lambda: sites["story1"].status())
        run_dir = bridge.run_dir
    assert learner.pid is None  # the worker was stopped with the bridge
    assert status["learner_losses"] == 1 and status["worker_pid"] != old_pid
    assert status["holds"] == 1 and status["learner"] == "live"
    events = load_run(run_dir).events
    holds = {e["site"]: e["reason"] for e in events if e["event"] == "hold"}
    kinds = [(e["site"], e["event"]) for e in events]
    assert ("story2", "learner-lost") in kinds and ("story2", "learner-restored") in kinds
    assert "learner of story1 lost" in holds["story2"]
    # The source is never touched by the loss: OpenSees turns the twin's NaN into NaN trials
    # for every element, and the source's NaN stop refuses to forward them (its HOLD is the
    # integrator's, its actuator keeps the last finite command).
    assert source["step"] == 40 and all(np.isfinite(source["ctrl"]))
    # an update line for each twin step the learner answered, none for the held one
    run = load_run(run_dir)
    answered = [s for s in run.steps if s.site == "story2" and np.isfinite(s.meas_force[0])]
    assert [u["step"] for u in run.updates] == [s.step for s in answered]
    assert "story1" not in holds or "non-finite trial" in holds["story1"]


def test_worker_killed_mid_run_freezes_the_twin_and_the_run_goes_on(tmp_path: Path) -> None:
    """``freeze``: from the snapshot of twin step 50 (learned through source step 50) the twin
    answers with frozen parameters until a new worker has caught up, then live again; the
    frame runs to the end, no site HOLDs. The worker is killed while the source is paused
    after step 60, and the source pauses again after step 80 until the new worker is live:
    twin steps 61-80 are frozen, 81 on live."""
    pytest.importorskip("filterpy")
    toml = frame_toml('updater = "online_ukf"\non_learner_loss = "freeze"\n')
    with RunningBridge(toml, tmp_path) as bridge:
        sites = bridge.bridge.sites
        learner = learners_of(bridge)["story1"]
        bridge.call(lambda: sites["story1"].add_listener(PauseAt(sites["story1"], 60)))
        bridge.call(lambda: sites["story1"].add_listener(PauseAt(sites["story1"], 80)))
        ports = [bridge.ports["story1"], bridge.ports["story2"]]
        result: list[dict[str, Any]] = []
        client = threading.Thread(target=lambda: result.append(run_opensees(
            "frame2", **frame_params(ports=ports, nsteps=NSTEPS))), daemon=True)
        client.start()
        _wait("source paused at step 60", lambda: bridge.call(
            lambda: str(sites["story1"].state)) == "PAUSED")
        _wait("snapshot of twin step 50", lambda: bridge.call(lambda: learner.snapshot_step) == 50)
        old_pid = learner.pid
        assert old_pid is not None
        os.kill(old_pid, signal.SIGKILL)
        _wait("twin frozen", lambda: bridge.call(
            lambda: learner.status("story2")["learner"]) in ("frozen", "live")
            and learner.losses == 1)
        bridge.call(lambda: sites["story1"].operator_resume("test"))
        _wait("source paused at step 80", lambda: bridge.call(
            lambda: (sites["story1"].step, str(sites["story1"].state))) == (80, "PAUSED"))
        _wait("learner live again", lambda: bridge.call(lambda: learner.state) == "live")
        bridge.call(lambda: sites["story1"].operator_resume("test"))
        client.join(120)
        assert result, "OpenSees did not finish with a frozen twin"
        holds = bridge.call(lambda: [sites["story1"].holds, sites["story2"].holds])
        run_dir = bridge.run_dir
    assert holds == [0, 0]
    events = [(e["site"], e["event"]) for e in load_run(run_dir).events]
    assert {("story2", "learner-lost"), ("story2", "learner-frozen"),
            ("story2", "learner-restored")} <= set(events)
    source = read_history(run_dir, site="story1")
    twin = read_history(run_dir, site="story2")
    assert twin.force is not None and twin.disp.size == NSTEPS
    live = replay(make_updater("online_ukf"), source.disp, source.force, twin.disp,
                  lag=True).force_pred
    frozen_updater = make_updater("online_ukf")
    replay(frozen_updater, source.disp[:50], source.force[:50], twin.disp[:50], lag=True)
    frozen = live.copy()  # steps 51 on with the parameters learned through step 50
    for i in range(50, NSTEPS):
        frozen[i] = frozen_updater.twin.set_trial(float(twin.disp[i]))[0]
        frozen_updater.twin.commit()
    scale = float(np.max(np.abs(live)))

    def close(a: np.ndarray, b: np.ndarray) -> bool:
        return a.size == 0 or float(np.max(np.abs(a - b))) / scale < 1e-9

    assert close(twin.force[:60], live[:60])  # live until the kill
    assert not close(frozen[60:], live[60:])  # frozen and live differ: the check can fail
    # frozen from step 61 until the new worker answered, live from then on
    switch = [k for k in range(61, NSTEPS + 1)
              if close(twin.force[60:k], frozen[60:k]) and close(twin.force[k:], live[k:])]
    assert switch == [80]


@pytest.mark.parametrize("twin_first", [True, False])
def test_same_step_in_either_opensees_element_order(tmp_path: Path, twin_first: bool) -> None:
    """Explicit Newmark (one displacement per step), the twin's element visited before or
    after its source's: the twin learns the source's step i before answering step i (the
    paper's order), as the in-process replay in that order does."""
    pytest.importorskip("filterpy")
    toml = frame_toml('updater = "online_ukf"\ncausality = "same-step"\n')
    served, run_dir = run_frame(toml, tmp_path, story2_first=twin_first, algorithm=["Linear"],
                                integrator=["NewmarkExplicit", 0.5])
    assert all(np.isfinite(served["u3"]))
    source = read_history(run_dir, site="story1")
    twin = read_history(run_dir, site="story2")
    assert twin.force is not None and twin.disp.size == NSTEPS
    expected = replay(make_updater("online_ukf"), source.disp, source.force, twin.disp,
                      lag=False).force_pred
    lagged = replay(make_updater("online_ukf"), source.disp, source.force, twin.disp,
                    lag=True).force_pred
    scale = float(np.max(np.abs(expected)))
    assert float(np.max(np.abs(twin.force - expected))) / scale < 1e-9
    assert float(np.max(np.abs(lagged - expected))) / scale > 1e-6  # the check can fail
    assert not [e for e in load_run(run_dir).events if e["event"] == "same-step-fallback"]


@pytest.mark.parametrize("protocol", ["modbus", "mts"])
def test_same_step_from_a_network_controller_source(tmp_path: Path, protocol: str) -> None:
    """The source behind a real `sim-actuator serve` process (Modbus TCP, MTS-like): the twin,
    visited first, waits for the source's command to reach the controller and learns the one
    measurement of that trial, the one the source's own force request then answers."""
    pytest.importorskip("filterpy")
    (port,) = free_ports(1)
    with sim_actuator(protocol, port):
        toml = frame_toml('updater = "online_ukf"\ncausality = "same-step"\n')
        sim = f'[sites.controller]\nmodel = "bilinear"\nparams = {_params(BILINEAR)}\n'
        toml = toml.replace(sim,
                            f'[sites.controller]\nkind = "{protocol}"\nport = {port}\n'
                            'stiffness = 68.0\n', 1)
        assert f'kind = "{protocol}"' in toml
        served, run_dir = run_frame(toml, tmp_path, story2_first=True, algorithm=["Linear"],
                                    integrator=["NewmarkExplicit", 0.5],
                                    factor=300.0)  # the stiff elastic rig stays in its limits
    assert all(np.isfinite(served["u3"]))
    source = read_history(run_dir, site="story1")
    twin = read_history(run_dir, site="story2")
    assert twin.force is not None and twin.disp.size == NSTEPS
    # each learned measurement is its own trial's (read after the command reached the rig):
    # the ideal elastic rig measures where it was sent, to float32 on the Modbus wire
    steps = [s for s in committed_steps(run_dir) if s.site == "story1"]
    assert len(steps) == NSTEPS and max(abs(s.meas_disp[0]) for s in steps) > 0.1
    assert all(abs(s.meas_disp[0] - s.cmd_disp[0]) <= 1e-5 * max(1.0, abs(s.cmd_disp[0]))
               for s in steps)
    expected = replay(make_updater("online_ukf"), source.disp, source.force, twin.disp,
                      lag=False).force_pred
    lagged = replay(make_updater("online_ukf"), source.disp, source.force, twin.disp,
                    lag=True).force_pred
    scale = float(np.max(np.abs(expected)))
    assert float(np.max(np.abs(twin.force - expected))) / scale < 1e-9
    assert float(np.max(np.abs(lagged - expected))) / scale > 1e-6  # the check can fail
    events = load_run(run_dir).events
    assert not [e for e in events if e["event"] in ("same-step-fallback", "same-step-mismatch")]
