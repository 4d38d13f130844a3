"""``kind = "rig"``: the whole simulated lab in the bridge's process, equal to the rig itself.

The bridge's answers are compared with an independent rig built from the same preset and driven
with the same commands (same seeds: noise included, equality is exact); a move beyond the
stroke is a controller error and a HOLD; bad rig choices are config errors naming the key.
"""

from __future__ import annotations

import math
from pathlib import Path

import pytest

from fresco_bridge.config import ConfigError, parse_config
from fresco_bridge.integrator.link import GenericClientLink
from fresco_bridge.record import read_record
from sim_actuator.config import build_rig, preset
from tests.support.bridge import RunningBridge

RAMP = 0.05


def _toml(controller: str) -> str:
    return f"""
[[sites]]
name = "rig"
port = 0
[sites.controller]
kind = "rig"
{controller}
"""


@pytest.mark.parametrize("name", ["lab-realistic", "damper-bwbn"])
def test_bridge_answers_equal_an_independent_rig(tmp_path: Path, name: str) -> None:
    commands = [0.5 * math.sin(0.3 * i) * (1 + 0.05 * i) for i in range(1, 41)]
    reference = build_rig(preset(name))
    expected = []
    for c in commands:
        m = reference.execute(c, RAMP)
        expected.append((m.displacement, m.force))
    toml = _toml(f'preset = "{name}"\nramp_time = {RAMP}\nstiffness = 8.0')
    forces = []
    with RunningBridge(toml, tmp_path) as b, \
            GenericClientLink("127.0.0.1", b.ports["rig"], 1, data_size=1) as link:
        for i, c in enumerate(commands, 1):
            link.set_trial((c,), time=0.01 * i)
            forces.append(link.force()[0])
            link.commit()
        run_dir = b.run_dir
    disps = [r["disp"][0] for r in read_record(run_dir) if r["kind"] == "daq"]
    got = list(zip(disps, forces, strict=True))
    assert got == expected  # exact: same model, same noise streams
    assert any(abs(d - c) > 1e-6 for (d, _), c in zip(got, commands, strict=True))  # effects on


def test_a_move_beyond_the_stroke_holds_with_the_rigs_reason(tmp_path: Path) -> None:
    with RunningBridge(_toml('preset = "ideal-elastic"'), tmp_path) as b, \
            GenericClientLink("127.0.0.1", b.ports["rig"], 1, data_size=1) as link:
        link.set_trial((0.5,), time=0.01)
        assert link.force()[0] == pytest.approx(68.0 * 0.5)
        link.commit()
        link.set_trial((500.0,), time=0.02)  # the preset's stroke is ±100 mm
        assert math.isnan(link.force()[0])
        run_dir = b.run_dir
    (hold,) = [r for r in read_record(run_dir) if r.get("event") == "hold"]
    assert "simulated rig" in hold["reason"] and "500.0" in hold["reason"]


@pytest.mark.parametrize(
    ("controller", "fragment"),
    [('preset = "no-such-rig"', "unknown rig preset 'no-such-rig'"),
     ('preset = "ideal-elastic"\nfile = "rig.toml"', "exactly one of 'preset' or 'file'"),
     ("", "exactly one of 'preset' or 'file'"),
     ('file = "/nonexistent/rig.toml"', "rig.toml")],
)
def test_bad_rig_choices_are_config_errors(controller: str, fragment: str) -> None:
    with pytest.raises(ConfigError, match="sites"):
        try:
            parse_config(_toml(controller), "lab.toml")
        except ConfigError as exc:
            assert fragment in str(exc), str(exc)
            raise


# -- several actuators loading one platform (a three-actuator column) -------------------------

COLUMN_PLATFORM = """
[sites.controller.platform]
geometry = [[1.0, 0.0, 0.0], [0.0, 1.0, -400.0], [0.0, 1.0, 600.0]]
specimen = [{ kind = "elastic", params = { k = 10.0 } },
            { kind = "elastic", params = { k = 200.0 } },
            { kind = "elastic", params = { k = 5.0e6 } }]
"""


def _column_toml(preset_name: str) -> str:
    return f"""
[[sites]]
name = "col"
port = 0
dofs = 3
setup = "NoTransformation"
[sites.controller]
kind = "rig"
preset = "{preset_name}"
ramp_time = {RAMP}
{COLUMN_PLATFORM}"""


def _k_actuators() -> list[list[float]]:
    import numpy as np

    t_inv = np.linalg.inv(np.array([[1.0, 0, 0], [0, 1.0, -400.0], [0, 1.0, 600.0]]))
    k: list[list[float]] = (t_inv.T @ np.diag([10.0, 200.0, 5.0e6]) @ t_inv).tolist()
    return k


def test_three_actuators_loading_one_platform_feel_each_other(tmp_path: Path) -> None:
    k = _k_actuators()
    with RunningBridge(_column_toml("ideal-elastic"), tmp_path) as b, \
            GenericClientLink("127.0.0.1", b.ports["col"], 3, data_size=16) as link:
        for i, x in enumerate([(0.0, 1.0, 0.0), (0.5, 1.0, 1.2), (-0.3, 0.2, 0.1)], 1):
            link.set_trial(x, time=0.01 * i)
            forces = link.force()
            link.commit()
            expected = [sum(k[r][c] * x[c] for c in range(3)) for r in range(3)]
            assert forces == pytest.approx(expected, rel=1e-12, abs=1e-9)
            if i == 1:  # actuator 2 alone moved; actuator 3 holds the platform's rotation
                assert abs(forces[2]) > 1.0


def test_servo_lag_on_every_actuator_keeps_the_platform_in_equilibrium(tmp_path: Path) -> None:
    k = _k_actuators()
    with RunningBridge(_column_toml("servo-hydraulic"), tmp_path) as b, \
            GenericClientLink("127.0.0.1", b.ports["col"], 3, data_size=16) as link:
        site = b.bridge.sites["col"]
        for i, x in enumerate([(0.0, 1.0, 0.0), (0.5, 1.0, 1.2), (-0.3, 0.2, 0.1)], 1):
            link.set_trial(x, time=0.01 * i)
            forces = link.force()
            link.commit()
            measured = b.call(lambda: site.daq.disp)
            assert any(abs(m - c) > 1e-6 for m, c in zip(measured, x, strict=True))  # the lag
            expected = [sum(k[r][c] * measured[c] for c in range(3)) for r in range(3)]
            assert forces == pytest.approx(expected, rel=1e-9, abs=1e-6)


def test_a_platform_that_does_not_fit_is_a_config_error() -> None:
    with pytest.raises(ConfigError, match=r"platform has 3 actuators; this site drives 2"):
        parse_config(_column_toml("ideal-elastic").replace("dofs = 3", "dofs = 2"))
    with pytest.raises(ConfigError, match=r"lab-realistic\) has load-path effects"):
        parse_config(_column_toml("lab-realistic"))
    with pytest.raises(ConfigError, match="singular"):
        parse_config(_column_toml("ideal-elastic").replace("-400.0", "600.0"))
