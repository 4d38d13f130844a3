"""A real OpenSeesPy genericClient the bridge will not serve (its site busy with another client,
sizes the site cannot serve, a host not allowed) is told to stop: its requests are answered
with NaN, so its analysis fails at once with a message and the process ends, instead of
spinning at full CPU in its receive loop forever (what a closed connection did)."""

from __future__ import annotations

import json
import resource
import subprocess
import sys
import time
from pathlib import Path

import pytest

from fresco_bridge.integrator.link import GenericClientLink
from tests.support.bridge import OPENSEES_SCRIPT, RunningBridge, opensees_env

pytest.importorskip("openseespy")

DEADLINE = 60.0
"""s: a hung client is killed past it (it spun forever before); the test asserts far less."""
PROMPT = 15.0
"""s within which the refused analysis must have failed, on a busy shared machine (its own
start, importing OpenSeesPy, is most of it)."""


def _site(extra: str = "", dofs: int = 1) -> str:
    return ('[bridge]\nrun_name = "refused"\n[[sites]]\nname = "damper"\nport = 0\n'
            f'dofs = {dofs}\n{extra}[sites.controller]\nmodel = "bilinear"\n'
            'params = { k0 = 20.0, fy = 5.0, alpha = 0.05 }\n')


def _opensees(port: int) -> tuple[subprocess.CompletedProcess[str], float, float]:
    """The 1-DOF static ramp of ``opensees_client.py`` against ``port``: the finished process,
    its wall time and the CPU time it used (s)."""
    params = {"port": port, "load": 5.0, "nsteps": 20, "data_size": 1}
    before = resource.getrusage(resource.RUSAGE_CHILDREN)
    t0 = time.monotonic()
    proc = subprocess.run([sys.executable, str(OPENSEES_SCRIPT), "static_1dof",
                           json.dumps(params)], env=opensees_env(), capture_output=True,
                          text=True, timeout=DEADLINE)
    wall = time.monotonic() - t0
    after = resource.getrusage(resource.RUSAGE_CHILDREN)
    cpu = (after.ru_utime - before.ru_utime) + (after.ru_stime - before.ru_stime)
    return proc, wall, cpu


def _assert_told_to_stop(proc: subprocess.CompletedProcess[str], wall: float) -> None:
    assert proc.returncode != 0, proc.stdout[-2000:]
    assert "static analysis failed" in proc.stderr, proc.stderr[-2000:]
    assert wall < PROMPT, f"the refused client took {wall:.1f} s to stop"


def test_a_busy_sites_second_client_stops_at_once(tmp_path: Path) -> None:
    with RunningBridge(_site(), tmp_path) as bridge:
        port = bridge.ports["damper"]
        with GenericClientLink("127.0.0.1", port, 1, data_size=1) as first:
            first.set_trial((0.5,), time=0.01)
            first.force()  # the first client holds the site, its session under way
            proc, wall, cpu = _opensees(port)
            _assert_told_to_stop(proc, wall)
            assert cpu < PROMPT  # not a spin: a spinning client burns its whole wall time
            first.commit()
            first.set_trial((1.0,), time=0.02)  # past yield: 5 + 0.05 * 20 * (1 - 0.25)
            assert abs(first.force()[0] - 5.75) < 1e-9  # the served client never noticed
            first.commit()
        events = (bridge.run_dir / "record.jsonl").read_text()
    assert "refused client" in events


def test_a_client_of_sizes_the_site_cannot_serve_stops_at_once(tmp_path: Path) -> None:
    with RunningBridge(_site(dofs=2), tmp_path) as bridge:  # the client has one DOF
        proc, wall, _ = _opensees(bridge.ports["damper"])
    _assert_told_to_stop(proc, wall)


def test_a_host_not_allowed_stops_at_once(tmp_path: Path) -> None:
    with RunningBridge(_site('allowed_clients = ["192.0.2.1"]\n'), tmp_path) as bridge:
        proc, wall, _ = _opensees(bridge.ports["damper"])
    _assert_told_to_stop(proc, wall)
