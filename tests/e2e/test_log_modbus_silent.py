"""A Modbus controller whose server stops answering (the `sim-actuator serve` process stopped
with SIGSTOP: its connection stays open, nothing comes back) under a real ``fresco-bridge
serve``: the site holds and probes, pymodbus times out again and again, and the log gains at
most one warning or error line per cause per interval, one line each, and no hex frame."""

from __future__ import annotations

import itertools
import re
import signal
import subprocess
import sys
import textwrap
import time
from collections import defaultdict
from pathlib import Path

from fresco_bridge.integrator.link import GenericClientLink
from fresco_bridge.logs import LOG_INTERVAL

FRESCO_BRIDGE = str(Path(sys.executable).parent / "fresco-bridge")
LINE = re.compile(r"(\d{4}-\d\d-\d\d \d\d:\d\d:\d\d,\d{3}) (DEBUG|INFO|WARNING|ERROR|CRITICAL) +"
                  r"([\w.]+): (.*)$")
HEX = re.compile(r"0x[0-9a-fA-F]{1,2}\b|>>>>>")
SILENT_FOR = 25.0


def _cause(logger: str, message: str) -> str:
    """What the rate limit groups by, as a reader sees it: the logger and the words."""
    words = re.sub(r"\[\d+ more line\(s\) like this one dropped in \d+ s\]", "", message)
    return logger + ": " + re.sub(r"[-+]?\d+(\.\d+)?", "#", words)


def test_a_silent_modbus_server_gives_one_line_per_cause_per_interval(tmp_path: Path) -> None:
    sim = subprocess.Popen([sys.executable, "-m", "sim_actuator.cli", "serve", "--protocol",
                            "modbus", "--port", "0", "--preset", "ideal-elastic"],
                           stdout=subprocess.PIPE, stderr=subprocess.DEVNULL, text=True)
    bridge: subprocess.Popen[str] | None = None
    log = tmp_path / "serve.log"
    try:
        assert sim.stdout is not None
        ready = sim.stdout.readline()
        assert ready.startswith("sim-actuator ready"), ready
        modbus_port = int(ready.split("port=")[1].split()[0])
        cfg = tmp_path / "lab.toml"
        cfg.write_text(textwrap.dedent(f"""
            [bridge]
            run_dir = "{tmp_path / 'runs'}"
            controller_timeout = 1.0
            controller_recovery = 15.0
            [[sites]]
            name = "act"
            port = 0
            [sites.controller]
            kind = "modbus"
            port = {modbus_port}
            stiffness = 68.0
            request_timeout = 0.2
            """), encoding="utf-8")
        with log.open("w") as err:
            bridge = subprocess.Popen([FRESCO_BRIDGE, "serve", "--config", str(cfg)],
                                      stdout=subprocess.PIPE, stderr=err, text=True)
        assert bridge.stdout is not None
        ready = bridge.stdout.readline()
        assert ready.startswith("fresco-bridge ready:"), log.read_text()
        port = int(ready.split("act=")[1].split(",")[0].strip())
        with GenericClientLink("127.0.0.1", port, 1, data_size=1, timeout=120.0) as link:
            for i in range(1, 6):
                link.set_trial((0.01 * i,), time=0.01 * i)
                assert abs(link.force()[0] - 68.0 * 0.01 * i) < 1e-3
                link.commit()
            sim.send_signal(signal.SIGSTOP)  # the server stops answering, its socket open
            silent_since = time.monotonic()
            link.set_trial((0.06,), time=0.06)
            link.force()  # the site waits out its recovery or answers NaN
        while time.monotonic() - silent_since < SILENT_FOR:
            # integrators retrying: each is refused while the site holds, or waits and stops
            try:
                with GenericClientLink("127.0.0.1", port, 1, data_size=1, timeout=5.0) as again:
                    again.set_trial((0.06,), time=0.06)
                    again.force()
            except (OSError, ValueError, RuntimeError):
                pass
            time.sleep(0.5)
        sim.send_signal(signal.SIGCONT)  # it answers again, late answers first
        deadline = time.monotonic() + 30.0
        while True:  # the site recovers (an operator's resume, if it held) and serves again
            subprocess.run([FRESCO_BRIDGE, "ctl", "resume", "--runs", str(tmp_path / "runs")],
                           capture_output=True, timeout=30)
            try:
                with GenericClientLink("127.0.0.1", port, 1, data_size=1, timeout=5.0) as link:
                    link.set_trial((0.02,), time=0.02)
                    if abs(link.force()[0] - 68.0 * 0.02) < 1e-3:
                        link.commit()
                        break
            except (OSError, ValueError, RuntimeError):
                pass
            assert time.monotonic() < deadline, log.read_text()
            time.sleep(0.5)
        assert bridge.poll() is None
    finally:
        if bridge is not None:
            bridge.terminate()
            bridge.wait(30)
        sim.send_signal(signal.SIGCONT)
        sim.terminate()
        sim.wait(30)
    text = log.read_text(encoding="utf-8")
    lines = text.splitlines()
    # stopped while the last client's DIE may still be in flight: the CLI's one exit line
    # ("interrupted: …, the run is recorded as interrupted") may close stderr; it is no log line
    if lines and lines[-1].startswith("interrupted: "):
        lines = lines[:-1]
    assert all(LINE.match(ln) for ln in lines), [ln for ln in lines if not LINE.match(ln)][:5]
    assert not HEX.search(text), [ln for ln in lines if HEX.search(ln)][:5]
    assert "Traceback" not in text
    seen: dict[str, list[float]] = defaultdict(list)
    for ln in lines:
        m = LINE.match(ln)
        assert m is not None
        stamp, level, logger, message = m.groups()
        if level in ("WARNING", "ERROR", "CRITICAL"):
            t = time.mktime(time.strptime(stamp[:19], "%Y-%m-%d %H:%M:%S")) + \
                int(stamp[20:]) / 1000
            seen[_cause(logger, message)].append(t)
    assert seen, text  # the silence was noticed
    too_often = {cause: times for cause, times in seen.items()
                 if any(b - a < LOG_INTERVAL - 0.01 for a, b in itertools.pairwise(times))}
    assert too_often == {}, text
