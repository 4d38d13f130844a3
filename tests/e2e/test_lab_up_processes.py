"""``fresco-bridge lab up`` as a process supervisor: start order, readiness, the integrator
one-shot, stop in reverse order, failures named, and no orphans even when it is killed."""

from __future__ import annotations

import json
import re
import signal
import socket
import time
from pathlib import Path

import pytest

from fresco_bridge.record.export import committed_steps
from tests.support.lab import lab_up, pid_alive


def _started_order(output: str) -> list[str]:
    return [ln.split(":")[1].strip() for ln in output.splitlines()
            if ln.startswith("lab: ") and ln.endswith(")") and "started (pid" in ln]


_STOPPED = re.compile(r"lab: ([\w-]+): (had finished|had exited|stopped by lab up|killed) ")


def _stopped_order(output: str) -> list[str]:
    return [m.group(1) for m in map(_STOPPED.match, output.splitlines()) if m]


def test_with_integrator_runs_to_the_end_and_stops_in_reverse_order(tmp_path: Path) -> None:
    runs = tmp_path / "runs"
    with lab_up(runs, "--with-integrator", extra_env={"LAB_DURATION": "1.5"}) as lab:
        rc = lab.proc.wait(120)
    out = lab.output()
    assert rc == 0, out
    started = _started_order(out)
    assert started[-2:] == ["bridge", "integrator"], out
    assert set(started[:2]) == {"mosquitto", "sim-actuator"}, out
    assert _stopped_order(out) == started[::-1], out
    assert "one-shot services finished" in out
    # stopped on purpose is said so, never as a bare signal status that reads as a failure
    assert "lab: integrator: had finished (status 0)" in out
    assert "lab: bridge: stopped by lab up (SIGTERM), as intended" in out
    assert "status -15" not in out and "in another terminal" not in out, out
    summary = json.loads(next(ln for ln in out.splitlines()
                              if "integrator: {" in ln).split("integrator: ", 2)[-1])
    assert summary["steps"] == 150  # time steps; step 0 (the initial state) is committed too
    assert summary["peak_damper_force_kN"] > 0.0
    assert "telemetry: connected to MQTT 127.0.0.1" in out  # the bridge found the lab's broker
    (run_dir,) = [p for p in runs.iterdir() if p.is_dir()]
    damper = [s for s in committed_steps(run_dir) if s.site == "damper"]
    assert len(damper) == 151
    assert not any(pid_alive(p) for p in lab.pids.values())
    lines = out.splitlines()
    assert lines[-2:] == [f"lab: run record: {run_dir}",
                          f"lab: next: fresco-bridge runs show {run_dir}  (then: fresco-bridge "
                          f"report {run_dir})"], out


def test_sigterm_stops_everything(tmp_path: Path) -> None:
    with lab_up(tmp_path / "runs") as lab:
        lab.wait_ready()
        pids = dict(lab.pids)
        assert all(pid_alive(p) for p in pids.values())
        assert lab.stop(signal.SIGTERM) == 0, lab.output()
    out = lab.output()
    assert _stopped_order(out) == _started_order(out)[::-1]
    assert ("lab: next: in another terminal, `fresco-bridge lab integrate --port "
            f"{lab.port('LAB_BRIDGE_PORT')}` drives site damper; Ctrl-C here stops the lab") in out
    assert "lab: bridge: stopped by lab up (SIGTERM), as intended" in out, out
    assert "lab: run record: " in out and "status -15" not in out, out
    assert not any(pid_alive(p) for p in pids.values())


def test_killed_lab_up_leaves_no_orphans(tmp_path: Path) -> None:
    with lab_up(tmp_path / "runs") as lab:
        lab.wait_ready()
        pids = dict(lab.pids)
        lab.proc.kill()  # SIGKILL: no cleanup code runs in lab up
        lab.proc.wait(10)
        deadline = time.monotonic() + 15
        while any(pid_alive(p) for p in pids.values()) and time.monotonic() < deadline:
            time.sleep(0.05)
        alive = {n: p for n, p in pids.items() if pid_alive(p)}
    assert not alive, f"orphans left: {alive}"


def test_a_service_that_cannot_start_is_named_and_the_rest_is_stopped(tmp_path: Path) -> None:
    with socket.socket() as busy:
        busy.bind(("127.0.0.1", 0))
        busy.listen()
        port = busy.getsockname()[1]
        # the controller port is taken: sim-actuator exits 1 before it is ready. (mosquitto
        # gets a free port; a taken broker port would be reused, see below.)
        with lab_up(tmp_path / "runs", extra_env={"LAB_CONTROLLER_PORT": str(port)}) as lab:
            rc = lab.proc.wait(60)
    out = lab.output()
    assert rc == 2, out
    assert f"service sim-actuator: 127.0.0.1:{port} is already in use by another process" in out
    assert "bridge: started" not in out and "sim-actuator: started" not in out
    started = _started_order(out)
    assert _stopped_order(out)[: len(started)] == started[::-1]


def test_a_broker_already_running_is_reused(tmp_path: Path) -> None:
    with socket.socket() as broker:
        broker.bind(("127.0.0.1", 0))
        broker.listen()
        port = broker.getsockname()[1]
        with lab_up(tmp_path / "runs", extra_env={"LAB_MQTT_PORT": str(port)}) as lab:
            lab.wait_ready()
            assert "mosquitto" not in lab.pids
            assert lab.stop() == 0
    assert f"mosquitto: already served on 127.0.0.1:{port}, reusing it" in lab.output()


def test_ready_deadline_names_what_it_waited_for(tmp_path: Path,
                                                 capsys: pytest.CaptureFixture[str]) -> None:
    compose = tmp_path / "compose.yaml"
    compose.write_text(
        "services:\n"
        "  sleeper:\n"
        "    image: x\n"
        "    x-local:\n"
        "      command: [sleep, '30']\n"
        "      ready: 127.0.0.1:9\n")
    from fresco_bridge.cli import main

    t0 = time.monotonic()
    rc = main(["lab", "up", "--compose", str(compose), "--ready-timeout", "0.5",
               "--runs", str(tmp_path / "runs")])
    assert rc == 2
    assert time.monotonic() - t0 < 15
    err = capsys.readouterr().err
    assert "service sleeper: not ready within 0.5 s (waiting for port 127.0.0.1:9)" in err


def test_a_service_dying_before_it_is_ready_is_named(tmp_path: Path,
                                                     capsys: pytest.CaptureFixture[str]) -> None:
    compose = tmp_path / "compose.yaml"
    compose.write_text(
        "services:\n"
        "  broken:\n"
        "    image: x\n"
        "    x-local:\n"
        "      command: [sim-actuator, serve, --protocol, modbus, --port, '0', --preset, nope]\n"
        "      ready_line: sim-actuator ready\n")
    from fresco_bridge.cli import main

    rc = main(["lab", "up", "--compose", str(compose), "--runs", str(tmp_path / "runs")])
    assert rc == 2
    err = capsys.readouterr().err
    assert "service broken exited with status 2" in err and "(before it was ready)" in err
    assert "nope" in err  # the service's own last words are shown


def test_a_missing_program_is_named(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    compose = tmp_path / "compose.yaml"
    compose.write_text(
        "services:\n"
        "  broker:\n"
        "    image: x\n"
        "    x-local:\n"
        "      command: [no-such-broker-binary, -p, '1']\n"
        "      ready: 127.0.0.1:9\n")
    from fresco_bridge.cli import main

    assert main(["lab", "up", "--compose", str(compose), "--runs", str(tmp_path / "r")]) == 2
    err = capsys.readouterr().err
    assert "service broker exited with status 127" in err
    assert "cannot start 'no-such-broker-binary'" in err


def test_integrator_names_an_unreachable_bridge(capsys: pytest.CaptureFixture[str]) -> None:
    with socket.socket() as sock:
        sock.bind(("127.0.0.1", 0))
        port = sock.getsockname()[1]  # nobody listens once the block ends
    from fresco_bridge.cli import main

    t0 = time.monotonic()
    rc = main(["lab", "integrate", "--port", str(port), "--connect-timeout", "0.5",
               "--duration", "1"])
    assert rc == 2 and time.monotonic() - t0 < 5
    assert f"bridge 127.0.0.1:{port} not reachable within 0.5 s" in capsys.readouterr().err


def test_an_optional_service_that_is_not_installed_is_skipped(
        tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    compose = tmp_path / "compose.yaml"
    compose.write_text(
        "services:\n"
        "  broker:\n"
        "    image: x\n"
        "    x-local:\n"
        "      command: [no-such-broker-binary]\n"
        "      optional: true\n"
        "  job:\n"
        "    image: x\n"
        "    depends_on: [broker]\n"
        "    x-local:\n"
        "      command: [sim-actuator, presets]\n"
        "      oneshot: true\n")
    from fresco_bridge.cli import main

    assert main(["lab", "up", "--compose", str(compose), "--runs", str(tmp_path / "r")]) == 0
    out = capsys.readouterr().out
    assert "broker: 'no-such-broker-binary' is not installed; skipped" in out
    assert "ideal-bilinear" in out  # the dependent one-shot ran
