"""Rig descriptions: TOML loading, presets, and clear errors for bad input."""

from __future__ import annotations

import itertools
from pathlib import Path

import pytest

from sim_actuator.config import (
    PRESETS,
    RigConfigError,
    build_rig,
    load_rig_config,
    parse_rig_config,
    preset,
)

RIG_TOML = """
name = "bench"
seed = 3
substep_rate = 2000.0
settle_time = 0.02

[specimen]
kind = "bilinear"
params = { k0 = 68.0, fy = 35.0, alpha = 0.008 }

[actuator]
stroke = 50.0
force_capacity = 250.0
delay = 0.01
servo = { kind = "second_order", natural_frequency = 20.0, damping = 0.7 }

[effects.friction]
coulomb = 0.2

[effects.frame]
stiffness = 1500.0

[sensors.load_cell]
noise_std = 0.01
"""


def test_toml_rig_loads_and_builds(tmp_path: Path) -> None:
    path = tmp_path / "rig.toml"
    path.write_text(RIG_TOML, encoding="utf-8")
    config = load_rig_config(path)
    assert config.name == "bench"
    assert config.actuator.servo.kind == "second_order"
    rig = build_rig(config)
    assert rig.dt == 1.0 / 2000.0
    assert rig.actuator.stroke == 50.0
    m = rig.execute(1.0, ramp_time=0.05)
    assert m.time == pytest.approx(0.07, abs=1e-12)


@pytest.mark.parametrize("name", sorted(PRESETS))
def test_every_preset_builds_and_moves(name: str) -> None:
    rig = build_rig(preset(name))
    m = rig.execute(0.5, ramp_time=0.05)
    assert m.displacement == pytest.approx(0.5, abs=0.05)


def test_the_bwbn_damper_preset_degrades_and_pinches() -> None:
    """Cycles at ±6 mm (4 × yield): the peak force falls cycle after cycle (strength
    degradation) and the force near zero displacement shrinks (pinching)."""
    rig = build_rig(preset("damper-bwbn"))
    peaks, near_zero = [], []
    for _ in range(4):
        peaks.append(rig.execute(6.0, ramp_time=0.5).force)
        rig.execute(-6.0, ramp_time=0.5)
        near_zero.append(abs(rig.execute(0.0, ramp_time=0.25).force))
    assert all(b < a for a, b in itertools.pairwise(peaks)), peaks
    assert peaks[-1] < 0.97 * peaks[0]
    assert near_zero[-1] < near_zero[0], near_zero


@pytest.mark.parametrize(
    ("data", "fragments"),
    [
        ({}, ["specimen: Field required"]),
        ({"specimen": {"kind": "steel02"}}, ["specimen.kind"]),
        ({"specimen": {"kind": "bilinear", "params": {"k0": 1.0, "fy": 1.0}}},
         ["missing required parameter(s) alpha"]),
        ({"specimen": {"kind": "elastic", "params": {"k": 1.0}}, "actuator": {"stroke": -2}},
         ["actuator.stroke", "greater than 0", "(got -2)"]),
        ({"specimen": {"kind": "elastic", "params": {"k": 1.0}}, "actuater": {}},
         ["actuater: Extra inputs are not permitted"]),
        ({"specimen": {"kind": "elastic", "params": {"k": 1.0}},
          "actuator": {"servo": {"kind": "first_order"}}},
         ["actuator.servo.first_order.tau: Field required"]),
        ({"specimen": {"kind": "elastic", "params": {"k": 1.0}},
          "default_ramp_time": 100.0, "max_ramp_time": 10.0},
         ["default_ramp_time 100.0 s exceeds max_ramp_time 10.0 s"]),
        ({"specimen": {"kind": "elastic", "params": {"k": 1.0}},
          "effects": {"friction": {"coulomb": float("inf")}}},
         ["effects.friction.coulomb"]),
    ],
)
def test_bad_descriptions_name_the_field(data: dict[str, object], fragments: list[str]) -> None:
    with pytest.raises(RigConfigError) as info:
        parse_rig_config(data, source="t.toml")
    message = str(info.value)
    assert message.startswith("t.toml: invalid rig description")
    for fragment in fragments:
        assert fragment in message


def test_unreadable_and_malformed_files_name_the_file(tmp_path: Path) -> None:
    missing = tmp_path / "nope.toml"
    with pytest.raises(RigConfigError, match=r"nope\.toml: cannot read"):
        load_rig_config(missing)
    bad = tmp_path / "bad.toml"
    bad.write_text("specimen = {kind = ", encoding="utf-8")
    with pytest.raises(RigConfigError, match=r"bad\.toml: not valid TOML"):
        load_rig_config(bad)


def test_unknown_preset_lists_the_known_ones() -> None:
    with pytest.raises(RigConfigError, match=r"known presets: .*ideal-bilinear"):
        preset("does-not-exist")
