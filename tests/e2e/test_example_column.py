"""examples/opensees_column_three_actuators.py as its docstring runs it: a bridge serving
examples/column_three_actuators.toml (on a free port), the OpenSeesPy column; every step served
through ``ThreeActuators2d`` with exact geometry on three coupled rigs, and without a bridge
one line and exit 1."""

from __future__ import annotations

import re
from pathlib import Path

import numpy as np
import pytest

from fresco_bridge.record import read_record
from tests.e2e.test_examples import run_example
from tests.support.bridge import RunningBridge
from tests.support.net import free_ports
from tests.support.paths import EXAMPLES, REPO

SCRIPT = "opensees_column_three_actuators.py"
CONFIG = "column_three_actuators.toml"
STEPS = 150


@pytest.mark.opensees
def test_the_three_actuator_column_example_runs_as_written(tmp_path: Path) -> None:
    pytest.importorskip("openseespy")
    text, sites = re.subn(r"(?m)^port = 8096", "port = 0",
                          (EXAMPLES / CONFIG).read_text(encoding="utf-8"))
    assert sites == 1
    with RunningBridge(text, tmp_path, base=REPO) as bridge:
        proc = run_example(SCRIPT, "--steps", str(STEPS), "--port", str(bridge.ports["column"]))
        site = bridge.bridge.sites["column"]
        geometry = site.setup.specimen_geometry()
        run_dir = bridge.run_dir
    assert proc.returncode == 0, f"stdout: {proc.stdout[-2000:]}\nstderr: {proc.stderr[-2000:]}"
    shortening = re.search(r"axial load 150 kN: shortening ([0-9.]+) mm", proc.stdout)
    assert shortening is not None and float(shortening[1]) == pytest.approx(150.0 / 400.0,
                                                                          rel=0.05)
    found = re.search(r"peak drift ([0-9.]+) mm, peak shear ([0-9.]+) kN", proc.stdout)
    assert found is not None and float(found[1]) > 0.1  # the record's first 1.5 s moved it
    assert float(found[2]) > 1.0
    records = list(read_record(run_dir))
    commits = [r for r in records if r["kind"] == "commit"]
    assert len(commits) >= 10 + STEPS  # the axial load's steps and the record's, each committed
    assert not [r for r in records if r.get("event") == "hold"]
    assert geometry is not None
    ctrls = [r["ctrl"] for r in records if r["kind"] == "trial"]
    trials = [r["trial"] for r in records if r["kind"] == "trial"]
    assert all(len(c) == 3 for c in ctrls)
    # the exact strokes: the platform state behind each command is the trial (nlGeom)
    for trial, ctrl in zip(trials[-50:], ctrls[-50:], strict=True):
        q, _ = geometry.state(ctrl)
        np.testing.assert_allclose(q, trial, rtol=1e-9, atol=1e-9)
    daqs = [r for r in records if r["kind"] == "daq"]
    assert min(f for d in daqs[-50:] for f in d["force"][1:]) < -50.0  # the verticals carry it


def test_without_a_bridge_the_column_example_says_so_and_exits_1() -> None:
    (port,) = free_ports(1)
    proc = run_example(SCRIPT, "--steps", "5", "--port", str(port))
    assert proc.returncode == 1, proc.stderr
    (line,) = proc.stderr.strip().splitlines()
    assert line.startswith(f"{SCRIPT}: no bridge is listening on 127.0.0.1:{port}")
    assert line.endswith(f"(start it first: .venv/bin/fresco-bridge serve --config "
                         f"examples/{CONFIG})")
