"""examples/opensees_generic_tcp.py as its docstring runs it: two ``sim-actuator serve --protocol
generic-tcp`` servers, a bridge serving examples/generic_tcp.toml (on free ports), the OpenSeesPy
frame; every step of both stories served through the GenericTCP servers."""

from __future__ import annotations

import re
from pathlib import Path

import pytest

from fresco_bridge.updating.histories import read_history
from tests.e2e.test_examples import run_example
from tests.support.bridge import RunningBridge
from tests.support.controller import sim_actuator
from tests.support.net import free_ports
from tests.support.paths import EXAMPLES, REPO

STEPS = 150


@pytest.mark.opensees
def test_the_generic_tcp_example_runs_as_written(tmp_path: Path) -> None:
    pytest.importorskip("openseespy")
    text = (EXAMPLES / "generic_tcp.toml").read_text(encoding="utf-8")
    commands = re.findall(r"(?m)^#   \.venv/bin/sim-actuator serve (.*) --port (\d+) (.*)$", text)
    assert [port for _, port, _ in commands] == ["5022", "5023"]
    ports = free_ports(2)
    for (_, port, _), free in zip(commands, ports, strict=True):
        text = text.replace(f"port = {port}\n", f"port = {free}\n")
    text, sites = re.subn(r"(?m)^port = 809\d", "port = 0", text)
    assert sites == 2
    with sim_actuator("generic-tcp", ports[0], *commands[0][2].split()), \
            sim_actuator("generic-tcp", ports[1], *commands[1][2].split()), \
            RunningBridge(text, tmp_path, base=REPO) as bridge:
        proc = run_example("opensees_generic_tcp.py", "--steps", str(STEPS), "--ports",
                           str(bridge.ports["damper"]), str(bridge.ports["story2"]))
        run_dir = bridge.run_dir
    assert proc.returncode == 0, f"stdout: {proc.stdout[-2000:]}\nstderr: {proc.stderr[-2000:]}"
    found = re.search(r"peak story-1 drift ([0-9.]+) mm", proc.stdout)
    assert found is not None and float(found[1]) > 0.1
    for site in ("damper", "story2"):
        history = read_history(run_dir, site=site)
        assert history.disp.size == STEPS
        assert history.force is not None and float(abs(history.force).max()) > 0.0
