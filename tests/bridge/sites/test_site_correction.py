"""``[sites.correction]`` on an experimental site, driven through a real bridge by the
project's genericClient (the integrator's side of the wire): an in-process ``rig`` whose
reaction frame is compliant, so the specimen sits short of every command until corrected."""

from __future__ import annotations

import math
import select
import subprocess
import sys
from pathlib import Path
from typing import Any

import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from fresco_bridge.config import ConfigError, parse_config
from fresco_bridge.ctl import format_answer, request, socket_path_for
from fresco_bridge.integrator.link import GenericClientLink
from fresco_bridge.record import read_record
from fresco_bridge.record.export import committed_steps, correction_lines
from tests.bridge.sites.test_correction_loop import rig_description, toml
from tests.support.bridge import RunningBridge
from tests.support.net import free_ports

K = 8.0  # kN/mm, the specimen (``ELASTIC`` of the loop's tests)
TARGETS = [2.0, 5.0, 8.0, 3.0, -4.0]


def lab(tmp_path: Path, correction: str | None, *, frame: float = 48.0,
        limits: str = "") -> str:
    rig_file = tmp_path / "rig.toml"
    rig_file.write_text(toml(rig_description(frame={"stiffness": frame})), encoding="utf-8")
    table = "" if correction is None else f"[sites.correction]\n{correction}\n"
    return f"""
[bridge]
run_name = "correction"
[[sites]]
name = "frame"
port = 0
[sites.controller]
kind = "rig"
file = "{rig_file}"
external = "specimen"
{table}{limits}"""


def drive(config: str, tmp_path: Path, targets: list[float]
          ) -> tuple[list[tuple[float, ...]], dict[str, Any], Path, list[tuple[float, ...]]]:
    """Each target a step (trial, force, commit); the forces, the site's status, the run
    directory and every command the rig was sent."""
    forces = []
    with RunningBridge(config, tmp_path / "runs") as b:
        site = b.bridge.sites["frame"]
        controller = site.controller  # type: ignore[attr-defined]
        sent: list[tuple[float, ...]] = []
        set_ctrl_now = controller.set_ctrl_now

        def spied(command: tuple[float, ...]) -> None:
            sent.append(command)
            set_ctrl_now(command)

        controller.set_ctrl_now = spied
        with GenericClientLink("127.0.0.1", b.ports["frame"], 1, timeout=30.0) as link:
            for i, t in enumerate(targets, 1):
                link.set_trial((t,), time=0.01 * i)
                forces.append(link.force())
                link.commit()
            # ``ctl status`` over the bridge's control socket, before the session ends
            answer = request(socket_path_for(b.run_dir), "status", "frame", timeout=10.0)
            (status,) = answer["sites"]
            status["text"] = format_answer(answer)
        run_dir = b.run_dir
    return forces, status, run_dir, sent


def test_a_compliant_frame_converges_through_the_site(tmp_path: Path) -> None:
    plain, _, _, _ = drive(lab(tmp_path, None), tmp_path / "plain", TARGETS)
    # the frame (48 kN/mm) behind the specimen (8 kN/mm): the specimen gets 6/7 of a command
    assert plain[1][0] == pytest.approx(K * 5.0 * 48.0 / 56.0, rel=0.02)
    config = lab(tmp_path, 'tolerance = 0.01\nmax_correction = 2.0\nmeasured = "external"')
    forces, status, run_dir, sent = drive(config, tmp_path / "corrected", TARGETS)
    for force, target in zip(forces, TARGETS, strict=True):
        # the integrator's answer: the force at the corrected position (specimen within 0.01)
        assert abs(force[0] - K * target) <= K * 0.01 + 1e-9
    assert len(sent) > len(TARGETS)  # corrections went to the rig
    correction = status["correction"]
    assert correction["trials"] == len(TARGETS) and correction["outcome"] == "converged"
    assert 1 <= correction["corrections"] <= 3 and correction["residual"] <= 0.01
    assert status["state"] == "RUNNING"
    assert (f"correction: last trial {correction['corrections']} correction(s), residual "
            f"{correction['residual']:.4g} mm (converged); {len(TARGETS)} trial(s), at most "
            f"{correction['most']} of 5") in status["text"]
    # the record: every iteration read back, and the committed step is the corrected one
    records = list(read_record(run_dir))
    lines = correction_lines(records)
    assert [c.target for c in lines] == [(t,) for t in TARGETS]
    assert all(c.outcome == "converged" and c.residual <= 0.01 for c in lines)
    assert [c.step for c in lines] == list(range(1, len(TARGETS) + 1))
    commanded = [c for line in lines for c in line.commands]
    assert commanded == sent  # every command the rig got, in order, is in the record
    for line in lines:
        assert line.commands[0] == line.target and len(line.commands) == line.corrections + 1
        assert abs(line.measured[-1][0] - line.target[0]) <= 0.01
    steps = committed_steps(run_dir)
    assert [s.cmd_disp for s in steps] == [line.commands[-1] for line in lines]
    assert [s.meas_force for s in steps] == [pytest.approx(f) for f in forces]


def commands_per_trial(sent: list[tuple[float, ...]], targets: list[float]
                       ) -> list[list[tuple[float, ...]]]:
    """The commands sent, split at each target (the first command of each trial)."""
    trials: list[list[tuple[float, ...]]] = []
    for command in sent:
        if len(trials) < len(targets) and command == (targets[len(trials)],):
            trials.append([])
        trials[-1].append(command)
    return trials


def test_export_reads_the_iterations_back(tmp_path: Path) -> None:
    config = lab(tmp_path, 'tolerance = 0.01\nmax_correction = 2.0\nmeasured = "external"')
    _, _, run_dir, sent = drive(config, tmp_path, TARGETS[:3])
    out = tmp_path / "corrections.csv"
    done = subprocess.run([sys.executable, "-m", "fresco_bridge.cli", "export", str(run_dir),
                           "--corrections", "-o", str(out)], capture_output=True, text=True,
                          timeout=120)
    assert done.returncode == 0, done.stderr
    assert f"{len(sent)} command(s) of 3 corrected trial(s)" in done.stdout
    rows = [line.split(",") for line in out.read_text().splitlines()]
    assert rows[0] == ["session", "step", "site", "iteration", "target", "command", "measured",
                       "outcome", "corrections", "residual"]
    assert [float(r[5]) for r in rows[1:]] == [c[0] for c in sent]
    assert next(r[3] for r in rows[1:] if r[1] == "1") == "0"
    shown = subprocess.run([sys.executable, "-m", "fresco_bridge.cli", "runs", "show",
                            str(run_dir)], capture_output=True, text=True, timeout=120)
    assert shown.returncode == 0, shown.stderr
    counts = sorted(len(c) - 1 for c in commands_per_trial(sent, TARGETS[:3]))
    assert (f"displacement correction: 3 trial(s), corrections a trial median {counts[1]} max "
            f"{counts[2]}, largest residual ") in shown.stdout
    assert "0 not converged" in shown.stdout


def test_beyond_max_correction_holds_and_nothing_beyond_is_forwarded(tmp_path: Path) -> None:
    # a soft frame (as stiff as the specimen): 2 → measured 1 → 3 (1 off) → 1.5 → 3.5 (1.5 off)
    # → 1.75 → 3.75 would be 1.75 off: beyond max_correction 1.5
    config = lab(tmp_path, 'tolerance = 0.01\nmax_correction = 1.5\nmeasured = "external"',
                 frame=K)
    forces, status, run_dir, sent = drive(config, tmp_path, [2.0, 3.0, 4.0])
    assert all(math.isnan(f[0]) for f in forces)  # the integrator is told to stop
    assert sent == [(2.0,), pytest.approx((3.0,)), pytest.approx((3.5,))]
    assert all(abs(c[0] - 2.0) <= 1.5 + 1e-12 for c in sent)
    assert status["state"] == "HOLD" and "max_correction 1.5 mm" in status["reason"]
    assert status["correction"]["outcome"] == "beyond-max-correction"
    records = list(read_record(run_dir))
    assert [c.outcome for c in correction_lines(records)] == ["beyond-max-correction"]
    assert not committed_steps(run_dir)


def test_non_convergence_holds_by_default(tmp_path: Path) -> None:
    config = lab(tmp_path, 'tolerance = 0.01\nmax_correction = 10.0\nmax_iterations = 2\n'
                 'gain = 0.3\nmeasured = "external"', frame=K)
    forces, status, _, sent = drive(config, tmp_path, [4.0, 5.0])
    assert all(math.isnan(f[0]) for f in forces) and len(sent) == 3
    assert status["state"] == "HOLD" and "after the last allowed correction" in status["reason"]


def test_non_convergence_accepted_with_an_event(tmp_path: Path) -> None:
    config = lab(tmp_path, 'tolerance = 0.01\nmax_correction = 10.0\nmax_iterations = 2\n'
                 'gain = 0.3\nmeasured = "external"\npolicy = "accept-with-event"', frame=K)
    forces, status, run_dir, _ = drive(config, tmp_path, [4.0, 5.0])
    assert status["state"] == "RUNNING" and status["correction"]["unconverged"] == 2
    assert status["correction"]["warnings"] == 2  # 2 of 2 iterations: more than half
    records = list(read_record(run_dir))
    events = [r for r in records if r["kind"] == "event"]
    corrections = [e for e in events if e["event"] == "correction"]
    assert [e["outcome"] for e in corrections] == ["not-converged"] * 2
    # the warning is rate-limited: one event for the two steps
    assert [e["event"] for e in events].count("correction-warning") == 1
    # the answer is the force measured at the last position reached (not the target's)
    steps = committed_steps(run_dir)
    assert [s.meas_force for s in steps] == [pytest.approx(f) for f in forces]
    assert all(0.0 < f[0] < K * t for f, t in zip(forces, [4.0, 5.0], strict=True))


def test_a_limit_rejects_a_correction_through_the_site_gate(tmp_path: Path) -> None:
    limits = '[[sites.limits]]\ndisp_max = 4.5\npolicy = "reject"\n'
    config = lab(tmp_path, 'tolerance = 0.01\nmax_correction = 3.0\nmeasured = "external"',
                 frame=K, limits=limits)
    forces, status, _, sent = drive(config, tmp_path, [3.0])
    # 3 → measured 1.5 → 4.5 (within) → 2.25 → 5.25: rejected by the limit, not sent
    assert math.isnan(forces[0][0]) and status["state"] == "HOLD"
    assert all(c[0] <= 4.5 + 1e-12 for c in sent)
    assert status["limit_events"]


def test_the_config_checks_the_correction(tmp_path: Path) -> None:
    bad = lab(tmp_path, "tolerance = [0.01, 0.02]\nmax_correction = 1.0")
    with pytest.raises(ConfigError, match=r"correction\.tolerance: 2 value"):
        parse_config(bad, "<test>")
    no_channel = lab(tmp_path, 'tolerance = 0.01\nmax_correction = 1.0\nmeasured = "external"'
                     ).replace('external = "specimen"\n', "")
    with pytest.raises(ConfigError, match=r'measured = "external", but \[sites\.controller\] '
                       r"\(kind rig\) names no external channel"):
        parse_config(no_channel, "<test>")


def test_a_modbus_site_corrects_on_its_external_register(tmp_path: Path) -> None:
    """The network path of the site (guarded controller calls, one read per command): the
    bridge's Modbus adapter against ``sim-actuator serve`` over loopback, the specimen's
    displacement read from its external register."""
    file = tmp_path / "rig.toml"
    file.write_text(toml(rig_description(frame={"stiffness": 48.0})), encoding="utf-8")
    port = free_ports(1)[0]
    proc = subprocess.Popen(
        [sys.executable, "-m", "sim_actuator.cli", "serve", "--protocol", "modbus", "--port",
         str(port), "--rig", str(file), "--time-scale", "0"],
        stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    try:
        assert proc.stdout is not None
        ready, _, _ = select.select([proc.stdout], [], [], 30.0)
        line = proc.stdout.readline() if ready else ""
        assert line.startswith("sim-actuator ready"), line
        config = f"""
[bridge]
run_name = "correction-modbus"
[[sites]]
name = "frame"
port = 0
[sites.controller]
kind = "modbus"
port = {port}
ramp_time = 0.05
request_timeout = 2.0
external_register = 24
[sites.correction]
tolerance = 0.01
max_correction = 2.0
measured = "external"
"""
        with RunningBridge(config, tmp_path / "runs") as b, \
                GenericClientLink("127.0.0.1", b.ports["frame"], 1, timeout=30.0) as link:
            forces = []
            for i, t in enumerate((3.0, -2.0, 4.0), 1):
                link.set_trial((t,), time=0.01 * i)
                forces.append(link.force()[0])
                link.commit()
            run_dir = b.run_dir
    finally:
        proc.terminate()
        proc.wait(10)
    lines = correction_lines(read_record(run_dir))
    assert [c.outcome for c in lines] == ["converged"] * 3
    assert lines[0].measured[0][0] == pytest.approx(3.0 * 48 / 56, abs=1e-4)  # behind the frame
    assert all(c.corrections >= 1 and c.residual <= 0.01 for c in lines)
    # float32 on the wire; the force at the corrected position
    assert forces == [pytest.approx(K * t, abs=K * 0.011) for t in (3.0, -2.0, 4.0)]
    assert [s.meas_force[0] for s in committed_steps(run_dir)] == \
        [pytest.approx(f) for f in forces]


@settings(max_examples=12, deadline=None,
          suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(frame=st.floats(4.0, 200.0), targets=st.lists(st.floats(-8.0, 8.0), min_size=1,
                                                      max_size=6),
       bound=st.floats(1.0, 6.0), policy=st.sampled_from(["reject", "clamp"]),
       most=st.floats(0.0, 4.0), gain=st.floats(0.2, 1.0))
def test_no_corrected_command_outside_the_limits_whatever_the_rig(
        tmp_path: Path, frame: float, targets: list[float], bound: float, policy: str,
        most: float, gain: float) -> None:
    limits = f'[[sites.limits]]\ndisp_min = {-bound!r}\ndisp_max = {bound!r}\npolicy = "{policy}"\n'
    config = lab(tmp_path, f'tolerance = 0.01\nmax_correction = {most!r}\ngain = {gain!r}\n'
                 'measured = "external"\npolicy = "accept-with-event"', frame=frame,
                 limits=limits)
    _, _, run_dir, sent = drive(config, tmp_path / f"runs-{len(list(tmp_path.iterdir()))}",
                                targets)
    assert all(-bound <= c[0] <= bound for c in sent)
    for line in correction_lines(read_record(run_dir)):
        # every correction within max_correction of the target it corrects, unless a clamp
        # put it on a limit (the proposal was within; the command reached is the clamped one)
        assert all(abs(c[0] - line.target[0]) <= most + 1e-9 or abs(abs(c[0]) - bound) < 1e-12
                   for c in line.commands[1:])


def test_a_repeated_trial_goes_on_from_the_corrected_command(tmp_path: Path) -> None:
    """An integrator that sends the same trial again (a Newton iteration at the same
    displacement) must not move the specimen back to the uncorrected target."""
    config = lab(tmp_path, 'tolerance = 0.01\nmax_correction = 2.0\nmeasured = "external"')
    with RunningBridge(config, tmp_path / "runs") as b:
        controller = b.bridge.sites["frame"].controller  # type: ignore[attr-defined]
        sent: list[tuple[float, ...]] = []
        set_ctrl_now = controller.set_ctrl_now

        def spied(command: tuple[float, ...]) -> None:
            sent.append(command)
            set_ctrl_now(command)

        controller.set_ctrl_now = spied
        with GenericClientLink("127.0.0.1", b.ports["frame"], 1, timeout=30.0) as link:
            forces = []
            for _ in range(3):
                link.set_trial((5.0,), time=0.01)
                forces.append(link.force()[0])
            link.commit()
        run_dir = b.run_dir
    assert sent.count((5.0,)) == 1  # the target once; then only corrections
    lines = correction_lines(read_record(run_dir))
    assert len(lines) == 3 and all(c.outcome == "converged" for c in lines)
    assert lines[1].commands[0] == lines[0].commands[-1]  # went on from the corrected command
    assert lines[2].corrections == 0 and lines[1].corrections == 0
    assert forces == [pytest.approx(K * 5.0, abs=K * 0.01)] * 3
    (step,) = committed_steps(run_dir)
    assert step.cmd_disp == lines[0].commands[-1]
