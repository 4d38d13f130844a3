"""A real bridge run through the ``rig`` controller with a known effect, diagnosed end to end.

The bridge serves a site whose controller is the simulated lab with fixture friction; a client
speaking the OpenFresco protocol drives it step by step; ``fresco-bridge diagnose`` reads the
run directory the bridge wrote and must name friction and its size, blind.
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from fresco_bridge.cli import main
from fresco_bridge.diagnosis.synth import command_history
from fresco_bridge.integrator.link import GenericClientLink
from tests.support.bridge import RunningBridge

DT = 0.01
COULOMB = 1.5  # kN, 6 % of fy

RIG = f"""
name = "friction-rig"
seed = 5
substep_rate = 1000.0
settle_time = 0.0
default_ramp_time = {DT}
[specimen]
kind = "bouc-wen"
params = {{ k0 = 10.0, fy = 25.0, alpha = 0.05, n = 2.0, beta = 0.6, gamma = 0.4 }}
[effects.friction]
coulomb = {COULOMB}
[sensors.lvdt]
noise_std = 0.005
[sensors.load_cell]
noise_std = 0.05
"""


def test_friction_in_a_bridge_run_is_named_and_sized(tmp_path: Path,
                                                     capsys: pytest.CaptureFixture[str]) -> None:
    rig = tmp_path / "rig.toml"
    rig.write_text(RIG)
    config = f"""
[[sites]]
name = "specimen"
port = 0
[sites.controller]
kind = "rig"
file = "{rig}"
ramp_time = {DT}
stiffness = 10.0
"""
    commands = command_history(np.random.default_rng(11), 900, DT, 12.0)
    with RunningBridge(config, tmp_path / "runs") as bridge, \
            GenericClientLink("127.0.0.1", bridge.ports["specimen"], 1, data_size=1) as link:
        for i, c in enumerate(commands, 1):
            link.set_trial((float(c),), time=DT * i)
            link.force()
            link.commit()
        run_dir = bridge.run_dir
    out = tmp_path / "diagnosis.json"
    rc = main(["diagnose", str(run_dir), "--json", str(out), "--no-progress"])
    assert rc == 0, capsys.readouterr().err
    doc = json.loads(out.read_text())
    assert doc["record"]["samples"] == 900
    assert doc["verdict"]["effect"] == "friction", doc["verdict"]
    friction = next(e for e in doc["effects"] if e["name"] == "friction")
    assert friction["params"]["coulomb"]["value"] == pytest.approx(COULOMB, rel=0.2)
    assert friction["shrink_pct"] > 50.0
