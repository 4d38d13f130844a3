"""``fresco-bridge ctl status|pause|resume|abort`` end to end against a ``fresco-bridge serve``
subprocess: real processes, the real control socket, a real integrator link."""

from __future__ import annotations

import json
import math
import signal
import subprocess
import sys
import textwrap
import threading
import time
from pathlib import Path

import pytest

from fresco_bridge.integrator.link import GenericClientLink
from fresco_bridge.record import read_record

FRESCO_BRIDGE = str(Path(sys.executable).parent / "fresco-bridge")
K = 10.0


def _config(runs: Path) -> str:
    return textwrap.dedent(f"""
        [bridge]
        run_dir = "{runs}"
        run_name = "ctl"
        [[sites]]
        name = "spec"
        port = 0
        [sites.controller]
        model = "elastic"
        params = {{ k = {K} }}
        [[sites.limits]]
        disp_min = -2.0
        disp_max = 2.0
        [[sites]]
        name = "other"
        port = 0
        [sites.controller]
        model = "elastic"
        params = {{ k = 1.0 }}
        """)


class Ctl:
    def __init__(self, runs: Path) -> None:
        self.runs = runs

    def __call__(self, *args: str) -> subprocess.CompletedProcess[str]:
        return subprocess.run([FRESCO_BRIDGE, "ctl", *args, "--runs", str(self.runs)],
                              capture_output=True, text=True, timeout=60)


def _wait_for(predicate, what: str, timeout: float = 20.0) -> None:  # type: ignore[no-untyped-def]
    deadline = time.monotonic() + timeout
    while not predicate():
        assert time.monotonic() < deadline, f"timed out waiting for {what}"
        time.sleep(0.05)


def test_ctl_against_a_running_fresco_bridge_serve(tmp_path: Path) -> None:
    runs = tmp_path / "runs"
    cfg = tmp_path / "lab.toml"
    cfg.write_text(_config(runs), encoding="utf-8")
    log = (tmp_path / "serve.log").open("w")
    proc = subprocess.Popen([FRESCO_BRIDGE, "serve", "--config", str(cfg)],
                            stdout=subprocess.PIPE, stderr=log, text=True)
    try:
        assert proc.stdout is not None
        ready = proc.stdout.readline()
        assert ready.startswith("fresco-bridge ready:"), ready
        ports = dict(item.strip().split("=") for item in ready.split(":", 1)[1].split(","))
        port = int(ports["spec"])
        ctl = Ctl(runs)

        r = ctl("status")
        assert r.returncode == 0, r.stderr
        assert "spec: IDLE" in r.stdout and "other: IDLE" in r.stdout
        assert "limits actuator 1: disp [-2.0, 2.0] mm, policy reject" in r.stdout
        assert "no limits configured" in r.stdout  # site other

        r = ctl("pause", "--site", "spec")
        assert r.returncode == 0 and "spec: ok: site spec PAUSED" in r.stdout
        link = GenericClientLink("127.0.0.1", port, 1, data_size=1, timeout=60.0).connect()
        replies: list[float] = []
        link.set_trial((0.3,), time=0.1)
        waiter = threading.Thread(target=lambda: replies.append(link.force()[0]))
        waiter.start()
        _wait_for(lambda: "waiting for an operator" in ctl("status", "--site", "spec").stdout,
                  "the command to wait for the operator")
        assert replies == []
        status = json.loads(ctl("status", "--site", "spec", "--json").stdout)
        (spec,) = status["sites"]
        assert spec["state"] == "PAUSED" and spec["pending"] == [0.3]
        assert spec["peer"].startswith("127.0.0.1:")

        r = ctl("resume", "--site", "spec")
        assert r.returncode == 0 and "PAUSED → RUNNING" in r.stdout
        waiter.join(20)
        assert replies == [pytest.approx(K * 0.3)]
        link.commit()

        r = ctl("resume", "--site", "spec")  # nothing to resume: refused, exit 1
        assert r.returncode == 1 and "REFUSED" in r.stdout and "not paused" in r.stdout
        r = ctl("pause", "--site", "nope")
        assert r.returncode == 1 and "no site 'nope'" in r.stdout

        status = json.loads(ctl("status", "--json").stdout)
        spec = next(s for s in status["sites"] if s["site"] == "spec")
        assert (spec["state"], spec["step"], spec["ctrl"]) == ("RUNNING", 1, [0.3])
        assert spec["daq_force"] == [pytest.approx(K * 0.3)]

        r = ctl("abort", "--site", "spec")
        assert r.returncode == 0 and "RUNNING → FAULT" in r.stdout
        link.set_trial((0.4,), time=0.2)
        assert math.isnan(link.force()[0])  # told to stop: NaN, never a stale force
        link.close()  # the integrator stops: DIE
        r = ctl("status", "--site", "spec")
        assert "spec: FAULT (operator abort (control socket))" in r.stdout
        _wait_for(lambda: "client" not in ctl("status", "--site", "spec").stdout.splitlines()[0],
                  "the aborted session to end")
        r = ctl("resume", "--site", "spec")
        assert r.returncode == 0 and "FAULT → IDLE" in r.stdout
        with GenericClientLink("127.0.0.1", port, 1, data_size=1) as again:
            again.set_trial((0.1,), time=0.1)
            assert again.force()[0] == pytest.approx(K * 0.1)
            again.commit()
    finally:
        proc.send_signal(signal.SIGTERM)
        rc = proc.wait(30)
        log.close()
    assert rc == 0, (tmp_path / "serve.log").read_text()
    (run_dir,) = [p for p in runs.iterdir() if p.is_dir()]
    events = [r for r in read_record(run_dir) if r["kind"] == "event" and r["site"] == "spec"]
    ops = [(e["event"], e["reason"]) for e in events if e["event"] in ("pause", "resume", "abort")]
    assert ops == [("pause", "operator pause (control socket)"),
                   ("resume", "operator resume (control socket)"),
                   ("abort", "operator abort (control socket)"),
                   ("resume", "operator resume (control socket)")]
    # the socket is gone with the bridge: ctl says so and exits 2
    r = Ctl(runs)("status")
    assert r.returncode == 2 and "no control socket" in r.stderr


@pytest.mark.parametrize(("args", "says"), [
    (("--timeout", "-1"), "--timeout -1: must be a finite number of seconds above 0"),
    (("--timeout", "nan"), "--timeout nan: must be a finite number"),
    (("--timeout", "inf"), "--timeout inf: must be a finite number"),
    (("--timeout", "0"), "--timeout 0: must be a finite number"),
    (("--timeout", "1e400"), "--timeout 1e400: must be a finite number"),
    (("--timeout", "soon"), "--timeout soon: not a number of seconds"),
    (("--socket", "/etc/passwd"), "--socket /etc/passwd: is a regular file, not a socket"),
    (("--socket", "/"), "--socket /: is a directory, not a socket"),
    (("--socket", "/nonexistent/c.sock"), "--socket /nonexistent/c.sock: No such file"),
    (("--run-dir", "/etc/passwd"), "--run-dir /etc/passwd: is not a directory"),
    (("--site", "a\x1b[2J"), "--site a\\x1b[2J: not a site name"),
    (("--site", ""), "--site : not a site name"),
    (("reboot",), "ctl reboot: not an action; expected one of status, pause, resume, abort"),
])
def test_each_bad_argument_is_one_line_and_exit_2(tmp_path: Path, args: tuple[str, ...],
                                                  says: str) -> None:
    """A live socket is there (``--socket`` names it unless the argument under test does), so
    the argument, not a missing bridge, is what is refused."""
    import socket

    live = tmp_path / "c.sock"
    with socket.socket(socket.AF_UNIX, socket.SOCK_STREAM) as server:
        server.bind(str(live))
        server.listen()
        where = () if "--socket" in args or "--run-dir" in args else ("--socket", str(live))
        action = () if args[0] == "reboot" else ("status",)
        r = subprocess.run([FRESCO_BRIDGE, "ctl", *action, *where, *args],
                           capture_output=True, text=True, timeout=60)
    assert r.returncode == 2
    assert r.stdout == ""
    assert r.stderr.count("\n") == 1 and r.stderr.startswith(f"error: {says}"), r.stderr
