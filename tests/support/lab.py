"""Run ``fresco-bridge lab up`` (the docker compose topology as local processes) from tests."""

from __future__ import annotations

import contextlib
import os
import re
import signal
import subprocess
import sys
import threading
import time
import tomllib
from collections.abc import Iterator
from dataclasses import dataclass, field
from pathlib import Path

from fresco_bridge.lab import Topology, dump_toml, localize_bridge_config
from tests.support.net import free_ports
from tests.support.paths import DOCKER, REPO

COMPOSE = DOCKER / "compose.yaml"
PORT_VARS = ("LAB_BRIDGE_PORT", "LAB_STORY2_PORT", "LAB_CONTROLLER_PORT", "LAB_MQTT_PORT")


def pid_alive(pgid: int) -> bool:
    """Any live (not zombie) process in the process group ``pgid`` (a lab service's group:
    the guard and the service under it)."""
    for stat in Path("/proc").glob("[0-9]*/stat"):
        with contextlib.suppress(OSError):
            fields = stat.read_text().rsplit(")", 1)[1].split()
            if int(fields[2]) == pgid and fields[0] != "Z":
                return True
    return False


@dataclass
class LabUp:
    """A running ``fresco-bridge lab up``: its process, the env (ports) and its output."""

    proc: subprocess.Popen[str]
    env: dict[str, str]
    runs: Path
    lines: list[str] = field(default_factory=list)
    pids: dict[str, int] = field(default_factory=dict)
    _ready: threading.Event = field(default_factory=threading.Event)

    def port(self, var: str) -> int:
        return int(self.env[var])

    def pump(self) -> None:
        assert self.proc.stdout is not None
        for line in self.proc.stdout:
            self.lines.append(line.rstrip("\n"))
            m = re.match(r"lab: ready: (.*)$", line.strip())
            if m:
                self.pids = {k: int(v) for k, v in (kv.split("=") for kv in m.group(1).split())}
                self._ready.set()
        self._ready.set()

    def wait_ready(self, timeout: float = 60.0) -> None:
        if not self._ready.wait(timeout) or not self.pids:
            raise AssertionError("lab up did not get ready:\n" + self.output())

    def output(self) -> str:
        return "\n".join(self.lines[-60:])

    def stop(self, signum: int = signal.SIGINT, timeout: float = 60.0) -> int:
        if self.proc.poll() is None:
            self.proc.send_signal(signum)
        try:
            return self.proc.wait(timeout)
        except subprocess.TimeoutExpired:
            self.proc.kill()
            raise AssertionError("lab up did not stop:\n" + self.output()) from None


@contextlib.contextmanager
def lab_up(runs: Path, *args: str, extra_env: dict[str, str] | None = None
           ) -> Iterator[LabUp]:
    """``fresco-bridge lab up ARGS`` on free ports; always stopped (and checked) at the end."""
    env = dict(os.environ)
    env.update(zip(PORT_VARS, map(str, free_ports(len(PORT_VARS))), strict=True))
    env.update(extra_env or {})
    proc = subprocess.Popen(
        [sys.executable, "-m", "fresco_bridge.cli", "lab", "up", "--compose", str(COMPOSE),
         "--runs", str(runs), *args],
        stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True, env=env, cwd=REPO,
    )
    lab = LabUp(proc, env, runs)
    pump = threading.Thread(target=lab.pump, daemon=True)
    pump.start()
    try:
        yield lab
    finally:
        lab.stop()
        pump.join(10)
        deadline = time.monotonic() + 10
        while any(pid_alive(p) for p in lab.pids.values()) and time.monotonic() < deadline:
            time.sleep(0.05)


def reference_config(lab: LabUp, runs: Path) -> str:
    """The lab's bridge config with the damper served in-process (``sim``) by the rig's model.

    Same sites, setup and ports layout as the lab (localized from docker/lab.toml); the
    specimen model and parameters are read from docker/rig.toml, the rig the lab serves.
    """
    topo = Topology.load(COMPOSE, env=lab.env)
    text = localize_bridge_config((DOCKER / "lab.toml").read_text(), "docker/lab.toml", topo,
                                  "bridge", runs)
    cfg = tomllib.loads(text)
    rig = tomllib.loads((DOCKER / "rig.toml").read_text())
    for site in cfg["sites"]:
        site["port"] = 0
        if site["name"] == "damper":
            site["controller"] = {"kind": "sim", "model": rig["specimen"]["kind"],
                                  "params": rig["specimen"]["params"]}
    cfg["telemetry"] = {}
    return dump_toml(cfg)
