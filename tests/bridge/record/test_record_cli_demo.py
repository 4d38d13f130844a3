"""Run record durability and export, config errors, the CLI, the demo, and the site protocol."""

from __future__ import annotations

import csv
import json
import os
import signal
import socket
import subprocess
import sys
from pathlib import Path

import pytest

from fresco_bridge.cli import main as cli_main
from fresco_bridge.config import ConfigError, parse_config
from fresco_bridge.demo import run_demo
from fresco_bridge.integrator.link import GenericClientLink
from fresco_bridge.record import export_csv
from fresco_bridge.record.export import committed_steps
from protocol import (
    NEED_DATA,
    DaqReceived,
    DieReplyReceived,
    OpenReplyReceived,
    ProbeReplyReceived,
    ShadowSession,
    Signals,
    SignalSizes,
)
from tests.support.bridge import RunningBridge
from tests.support.paths import EXAMPLES

SERVE_TOML = """
[bridge]
run_name = "kill9"
[record]
fsync = "background"
[[sites]]
name = "spring"
port = {port}
dofs = 1
[sites.controller]
model = "bilinear"
params = {{ k0 = 100.0, fy = 20.0, alpha = 0.02 }}
"""


def _free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return int(s.getsockname()[1])


def test_kill_minus_9_loses_no_committed_step(tmp_path: Path) -> None:
    cfg = tmp_path / "lab.toml"
    port = _free_port()
    cfg.write_text(SERVE_TOML.format(port=port))
    proc = subprocess.Popen(
        [sys.executable, "-m", "fresco_bridge.cli", "serve", "--config", str(cfg)],
        cwd=tmp_path, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
    )
    try:
        assert proc.stdout is not None
        assert proc.stdout.readline().startswith("fresco-bridge ready")
        link = GenericClientLink("127.0.0.1", port, 1, data_size=1).connect()
        for i in range(1, 201):
            link.set_trial((0.002 * i,), time=0.01 * i)
            link.force()
            link.commit()
        link.force()  # the reply proves commit 200 was processed
        os.kill(proc.pid, signal.SIGKILL)
        proc.wait(10)
    finally:
        if proc.poll() is None:
            proc.kill()
    (run_dir,) = (tmp_path / "runs").iterdir()
    steps = committed_steps(run_dir)
    assert [s.step for s in steps] == list(range(1, 201))
    assert steps[-1].cmd_disp == (pytest.approx(0.4),)
    assert (run_dir / "config.toml").read_text() == cfg.read_text()
    assert json.loads((run_dir / "run.json").read_text())["units"]["disp"] == "mm"


def test_csv_export_columns_single_and_multi_dof(tmp_path: Path) -> None:
    toml = """
[[sites]]
name = "one"
port = 0
[sites.controller]
model = "elastic"
params = { k = 2.0 }
[[sites]]
name = "two"
port = 0
dofs = 2
[sites.controller]
model = "elastic"
params = { k = 3.0 }
"""
    with RunningBridge(toml, tmp_path) as b:
        with GenericClientLink("127.0.0.1", b.ports["two"], 2) as link:
            for i in range(3):
                link.set_trial((0.1 * i, -0.2 * i), time=0.5 * i)
                link.force()
                link.commit()
        run_dir = b.run_dir
    out = tmp_path / "two.csv"
    assert export_csv(run_dir, out, site="two") == 3
    rows = list(csv.reader(out.open()))
    assert rows[0] == ["time", "step", "site", "cmd_disp_1", "cmd_disp_2", "meas_disp_1",
                       "meas_disp_2", "meas_force_1", "meas_force_2", "session"]
    last = rows[-1]
    assert float(last[0]) == 1.0 and last[1] == "3" and last[2] == "two"
    assert [float(x) for x in last[3:9]] == pytest.approx([0.2, -0.4, 0.2, -0.4, 0.6, -1.2])
    # the CLI export writes the same file for the whole run
    assert cli_main(["export", str(run_dir), "-o", str(tmp_path / "all.csv")]) == 0
    assert (tmp_path / "all.csv").read_text().splitlines()[0].startswith("time,step,site")


def test_config_errors_name_file_key_and_reason(tmp_path: Path, capsys) -> None:  # type: ignore[no-untyped-def]
    bad = tmp_path / "lab.toml"
    bad.write_text('[[sites]]\nname = "a"\nport = 8090\nprotcol = "element"\n'
                   '[sites.controller]\nmodel = "bilnear"\n')
    assert cli_main(["check", "--config", str(bad)]) == 2
    err = capsys.readouterr().err
    assert str(bad) in err and "Traceback" not in err
    assert "sites[0].protcol: unknown key" in err
    assert "sites[0].controller.model" in err and "'bilnear'" in err
    with pytest.raises(ConfigError, match=r"sites\[0\].controller: .*fy must be > 0"):
        parse_config('[[sites]]\nname = "a"\nport = 1\n[sites.controller]\n'
                     'params = { k0 = 1.0, fy = -3.0, alpha = 0.1 }\n', "x.toml")
    with pytest.raises(ConfigError, match=r"x\.toml: not valid TOML"):
        parse_config("[[sites]\n", "x.toml")
    with pytest.raises(ConfigError, match="damping must be a 2×2 matrix"):
        parse_config('[[sites]]\nname = "a"\nport = 1\ndofs = 2\ndamping = [[1.0]]\n', "x.toml")
    assert cli_main(["check", "--config", str(tmp_path / "missing.toml")]) == 2
    assert "cannot read" in capsys.readouterr().err


def test_example_config_is_valid() -> None:
    example = EXAMPLES / "lab.toml"
    assert cli_main(["check", "--config", str(example)]) == 0


def test_demo_runs_end_to_end_and_the_damper_yields(tmp_path: Path) -> None:
    summary = run_demo(runs=tmp_path)
    run_dir = Path(summary["run_dir"])
    for name in summary["files"]:
        assert (run_dir / name).is_file(), name
    assert summary["steps"] == 2000
    assert summary["committed_steps_in_record"] == 2001  # step 0 (initial state) + 2000
    assert summary["damper_ductility"] > 3.0
    assert summary["periods_s_with_damper"][0] == pytest.approx(0.379, abs=0.002)
    assert (run_dir / "hysteresis.png").read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    steps = committed_steps(run_dir)
    assert max(abs(s.meas_force[0]) for s in steps) == pytest.approx(
        max(abs(f) for f in summary["peak_damper_force_kN"]), rel=1e-3)


@pytest.mark.parametrize("transport", ["tcp", "udp"])
def test_site_protocol_shadow_client_through_bridge(tmp_path: Path, transport: str) -> None:
    """A ShadowExpSite (our sans-IO shadow on a real socket) against the bridge's actor."""
    toml = f"""
[[sites]]
name = "actor"
port = 0
transport = "{transport}"
protocol = "site"
dofs = 2
actor_tag = 9
[sites.controller]
model = "elastic"
params = {{ k = 100.0 }}
"""
    with RunningBridge(toml, tmp_path) as b:
        port = b.ports["actor"]
        shadow = ShadowSession(transport, shadow_tag=7)  # type: ignore[arg-type]
        if transport == "tcp":
            sock = socket.create_connection(("127.0.0.1", port), timeout=5)
        else:
            sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
            sock.settimeout(5)
            sock.connect(("127.0.0.1", port))
            sock.send(b"a")
            assert sock.recv(8) == b"b"

        def send(data: bytes) -> None:
            if transport == "tcp":
                sock.sendall(data)
            else:
                from protocol import chunk_datagrams

                for c in chunk_datagrams(data):
                    sock.send(c)

        def event():  # type: ignore[no-untyped-def]
            while True:
                ev = shadow.next_event()
                if ev is not NEED_DATA:
                    return ev
                shadow.receive_data(sock.recv(65536))

        if transport == "tcp":
            send(shadow.send_probe())
            assert isinstance(event(), ProbeReplyReceived)
        send(shadow.send_open())
        reply = event()
        assert isinstance(reply, OpenReplyReceived)
        assert (reply.actor_tag, reply.version) == (9, 2.8)
        trial_sizes = SignalSizes(2, 2, 2, 0, 1)
        out_sizes = SignalSizes(2, 0, 0, 2, 1)
        send(shadow.send_setup(256, trial_sizes, out_sizes))
        for i in range(1, 4):
            d = (0.01 * i, 0.02 * i)
            send(shadow.send_trial(Signals(disp=d, vel=(0.1, 0.2), accel=(-1.0, -2.0),
                                           time=(0.1 * i,))))
            send(shadow.send_daq_request())
            daq = event()
            assert isinstance(daq, DaqReceived)
            assert daq.out.disp == pytest.approx(d)
            assert daq.out.force == pytest.approx([100 * x for x in d])
            assert daq.out.time == pytest.approx((0.1 * i,))
            send(shadow.send_commit((0.1 * i,)))  # the shadow adds it: time slot doubles
        send(shadow.send_die())
        die = event()
        assert isinstance(die, DieReplyReceived) and die.actor_tag == 9
        sock.close()
        run_dir = b.run_dir
    steps = committed_steps(run_dir)
    assert [s.time for s in steps] == pytest.approx([0.1, 0.2, 0.3])  # time from code 3


def test_serve_on_a_port_in_use_names_the_site_and_leaves_no_empty_run(tmp_path: Path) -> None:
    with socket.socket() as taken:
        taken.bind(("127.0.0.1", 0))
        taken.listen()
        port = taken.getsockname()[1]
        runs = tmp_path / "runs"
        cfg = tmp_path / "lab.toml"
        cfg.write_text(f'[bridge]\nrun_dir = "{runs}"\n[[sites]]\nname = "free"\nport = 0\n'
                       f'[[sites]]\nname = "damper"\nport = {port}\n')
        proc = subprocess.run([sys.executable, "-m", "fresco_bridge.cli", "serve", "--config",
                               str(cfg)], capture_output=True, text=True, timeout=60)
    assert proc.returncode == 1
    last = proc.stderr.strip().splitlines()[-1]
    assert last.startswith(f"error: site damper: cannot listen on TCP 127.0.0.1:{port}: ")
    assert "Traceback" not in proc.stderr
    assert not runs.exists() or not any(runs.iterdir())  # a failed start is not a run
