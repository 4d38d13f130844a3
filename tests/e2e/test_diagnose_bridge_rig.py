"""Real bridge runs through the ``rig`` controller with a known effect, diagnosed end to end.

The bridge serves a site whose controller is the simulated lab with one effect (fixture
friction, or OpenFresco's end-point undershoot on the actuator); a client speaking the
OpenFresco protocol drives it step by step; ``fresco-bridge diagnose`` reads the run directory
the bridge wrote and must name the effect and its size, blind.
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from benchmarks.diagnosis.synth import command_history
from fresco_bridge.cli import main
from fresco_bridge.integrator.link import GenericClientLink
from tests.support.bridge import RunningBridge

DT = 0.01
COULOMB = 1.5  # kN, 6 % of fy
UNDERSHOOT = 0.3  # mm, 2.5 % of the peak command

RIG = """
name = "effect-rig"
seed = 5
substep_rate = 1000.0
settle_time = 0.0
default_ramp_time = {dt}
[specimen]
kind = "bouc-wen"
params = {{ k0 = 10.0, fy = 25.0, alpha = 0.05, n = 2.0, beta = 0.6, gamma = 0.4 }}
{effect}
[sensors.lvdt]
noise_std = 0.005
[sensors.load_cell]
noise_std = 0.05
"""
CASES = {
    "friction": (f"[effects.friction]\ncoulomb = {COULOMB}", "coulomb", COULOMB),
    "actuator_undershoot": (f"[actuator]\nundershoot = {UNDERSHOOT}", "undershoot", UNDERSHOOT),
}


@pytest.mark.parametrize("effect", sorted(CASES))
def test_an_effect_in_a_bridge_run_is_named_and_sized(effect: str, tmp_path: Path,
                                                      capsys: pytest.CaptureFixture[str]) -> None:
    section, parameter, truth = CASES[effect]
    rig = tmp_path / "rig.toml"
    rig.write_text(RIG.format(dt=DT, effect=section))
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
    assert doc["verdict"]["effect"] == effect, doc["verdict"]
    winner = next(e for e in doc["effects"] if e["name"] == effect)
    assert winner["params"][parameter]["value"] == pytest.approx(truth, rel=0.2)
    assert winner["params"][parameter]["flag"] is None
    assert winner["shrink_pct"] > 50.0
