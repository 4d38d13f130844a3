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
from tests.support.column import L1, L2, LINEAR_T, three_actuators_2d

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

K_BASIC = (10.0, 200.0, 5.0e5)  # shear kN/mm, axial kN/mm, rotation kN·mm/rad
COLUMN_PLATFORM = f"""
[sites.controller.platform]
specimen = [{{ kind = "elastic", params = {{ k = {K_BASIC[0]} }} }},
            {{ kind = "elastic", params = {{ k = {K_BASIC[1]} }} }},
            {{ kind = "elastic", params = {{ k = {K_BASIC[2]} }} }}]
"""


def _column_toml(preset_name: str, nl_geom: bool = False) -> str:
    return f"""
[[sites]]
name = "col"
port = 0
dofs = 3
{three_actuators_2d(nl_geom)}[sites.controller]
kind = "rig"
preset = "{preset_name}"
ramp_time = {RAMP}
{COLUMN_PLATFORM}"""


def _k_actuators() -> list[list[float]]:
    """J(0)⁻ᵀ K J(0)⁻¹: the actuator stiffness of the column (linear geometry)."""
    import numpy as np

    t_inv = np.linalg.inv(np.array(LINEAR_T))
    k: list[list[float]] = (t_inv.T @ np.diag(K_BASIC) @ t_inv).tolist()
    return k


def test_three_actuators_loading_one_platform_feel_each_other(tmp_path: Path) -> None:
    """The setup's platform is the specimen's: the element sees its own diagonal stiffness,
    and each actuator's force carries the others' moves."""
    k = _k_actuators()
    with RunningBridge(_column_toml("ideal-elastic"), tmp_path) as b, \
            GenericClientLink("127.0.0.1", b.ports["col"], 3, data_size=16) as link:
        for i, x in enumerate([(0.0, 1.0, 0.0), (0.5, 1.0, 1.2e-3), (-0.3, 0.2, 1e-4)], 1):
            link.set_trial(x, time=0.01 * i)
            forces = link.force()
            link.commit()
            assert forces == pytest.approx([kb * v for kb, v in zip(K_BASIC, x, strict=True)],
                                           rel=1e-12, abs=1e-9)
        run_dir = b.run_dir
    records = list(read_record(run_dir))
    ctrls = [r["ctrl"] for r in records if r["kind"] == "trial"]
    daqs = [r for r in records if r["kind"] == "daq"]
    for ctrl, daq in zip(ctrls, daqs, strict=True):
        expected = [sum(k[r][c] * ctrl[c] for c in range(3)) for r in range(3)]
        assert daq["force"] == pytest.approx(expected, rel=1e-12, abs=1e-9)
    assert abs(daqs[0]["force"][0]) < 1e-9 and daqs[0]["force"][1] == \
        pytest.approx(daqs[0]["force"][2] * L2 / L1)  # v alone: the beam shares it


def test_the_platform_is_loaded_through_the_exact_geometry_under_nl_geom(
        tmp_path: Path) -> None:
    """``nlGeom``: strokes are the exact ones of the rotated beam, and the element still sees
    its specimen (p = K q) to rounding at rotations of a few hundredths of a radian (as far
    as the actuators' force capacity lets this stiff column go)."""
    import numpy as np

    trials = [(0.4 * i, -0.1 * i, 0.002 * i) for i in range(1, 13)]  # to θ = 0.024 rad
    with RunningBridge(_column_toml("ideal-elastic", nl_geom=True), tmp_path) as b, \
            GenericClientLink("127.0.0.1", b.ports["col"], 3, data_size=16) as link:
        for i, x in enumerate(trials, 1):
            link.set_trial(x, time=0.01 * i)
            forces = link.force()
            link.commit()
            assert forces == pytest.approx([kb * v for kb, v in zip(K_BASIC, x, strict=True)],
                                           rel=1e-9)
        run_dir = b.run_dir
    ctrls = [r["ctrl"] for r in read_record(run_dir) if r["kind"] == "trial"]
    linear = np.array(LINEAR_T) @ np.array(trials[-1])
    assert np.max(np.abs(np.array(ctrls[-1]) - linear)) > 0.01  # the exact strokes, not J(0)·q


def test_servo_lag_on_every_actuator_keeps_the_platform_in_equilibrium(tmp_path: Path) -> None:
    import numpy as np

    t = np.array(LINEAR_T)
    with RunningBridge(_column_toml("servo-hydraulic"), tmp_path) as b, \
            GenericClientLink("127.0.0.1", b.ports["col"], 3, data_size=16) as link:
        site = b.bridge.sites["col"]
        for i, x in enumerate([(0.0, 1.0, 0.0), (0.5, 1.0, 1.2e-3), (-0.3, 0.2, 1e-4)], 1):
            link.set_trial(x, time=0.01 * i)
            forces = link.force()
            link.commit()
            measured = b.call(lambda: site.daq.disp)
            q = np.linalg.solve(t, np.array(measured))
            assert np.max(np.abs(q - np.array(x))) > 1e-6  # the lag
            assert forces == pytest.approx((np.array(K_BASIC) * q).tolist(), rel=1e-9,
                                           abs=1e-6)


def test_a_platform_that_does_not_fit_is_a_config_error() -> None:
    two_laws = _column_toml("ideal-elastic").replace(
        f""",
            {{ kind = "elastic", params = {{ k = {K_BASIC[2]} }} }}]""", "]")
    with pytest.raises(ConfigError, match=r"platform specimen has 2 law\(s\); the setup's "
                                          r"platform has 3 DOF\(s\) driven by 3 actuator"):
        parse_config(two_laws)
    no_platform = _column_toml("ideal-elastic").replace(
        'kind = "ThreeActuators2d"', 'kind = "NoTransformation"')
    no_platform = "\n".join(line for line in no_platform.splitlines()
                            if not line.startswith(("La", "L1", "L2", "nlGeom")))
    with pytest.raises(ConfigError, match=r"this setup has none \(use a planar setup"):
        parse_config(no_platform)
    with pytest.raises(ConfigError, match=r"lab-realistic\) has load-path effects"):
        parse_config(_column_toml("lab-realistic"))
