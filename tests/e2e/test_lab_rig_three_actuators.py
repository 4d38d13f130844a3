"""A three-actuator ``rig`` site driven by a real OpenSeesPy process for a few hundred steps.

The column top's three DOFs (u, v, theta) are one genericClient element; the site's setup is
``NoTransformation`` (one actuator per DOF: the linear stand-in for ``ThreeActuators2d``), and
each actuator is its own simulated rig — its own servo, effects, sensors and specimen. Every
measured value equals an independent rig of that channel driven with the commands the bridge
recorded (exact: same models, same noise streams). A displacement limit on actuator 2 trips
at a step of the run: the site HOLDs, OpenSees is answered NaN, and no actuator moves again.
"""

from __future__ import annotations

from pathlib import Path

import pytest

from fresco_bridge.config import ConfigError, parse_config
from fresco_bridge.record import read_record
from sim_actuator.config import build_rig, channel_config, preset
from tests.support.bridge import RunningBridge, run_opensees

PRESETS = ("servo-hydraulic", "lab-realistic", "ideal-elastic")
RAMP = 0.02
LIMIT = 0.5  # mm, actuator 2 (the vertical one): reached after about 240 steps


def toml(limit: float | None = LIMIT) -> str:
    channels = "".join(f'[[sites.controller.channels]]\npreset = "{p}"\n' for p in PRESETS)
    limits = "" if limit is None else f"""
[[sites.limits]]
actuator = 2
disp_min = -{limit}
disp_max = {limit}
policy = "reject"
"""
    return f"""
[[sites]]
name = "col"
port = 0
dofs = 3
setup = "NoTransformation"
[sites.controller]
kind = "rig"
ramp_time = {RAMP}
stiffness = 68.0
{channels}{limits}"""


def test_three_rigs_under_opensees_until_a_limit_on_one_holds_all_three(tmp_path: Path) -> None:
    with RunningBridge(toml(), tmp_path) as b:
        result = run_opensees(
            "column3", timeout=300, port=b.ports["col"], nsteps=400, dt=0.01,
            masses=[0.05, 0.05, 0.05],
            excitation=[[2000.0, 1.5, 0.0], [150.0, 2.0, 1.0], [2.0, 1.0, 0.0]])
        site = b.bridge.sites["col"]
        rigs = b.call(lambda: list(site.controller.rigs))  # type: ignore[attr-defined]
        run_dir = b.run_dir
    failed_at = result["failed_at"]
    assert failed_at is not None and 150 <= failed_at <= 400, failed_at  # a few hundred steps
    records = list(read_record(run_dir))
    # each measurement with the command it answers; the site moves only for a new command
    answered: list[tuple[tuple[float, ...], dict[str, list[float]]]] = []
    last_ctrl: tuple[float, ...] = ()
    for r in records:
        if r["kind"] == "trial":
            last_ctrl = tuple(r["ctrl"])
        elif r["kind"] == "daq":
            answered.append((last_ctrl, r))
    moves = [c for i, (c, _) in enumerate(answered) if i == 0 or c != answered[i - 1][0]]
    assert len(moves) >= failed_at - 2
    # every measurement is its channel's own rig (effects and noise included) at the command
    for channel, name in enumerate(PRESETS):
        reference = build_rig(channel_config(preset(name), channel))
        latest = None
        for i, (ctrl, daq) in enumerate(answered):
            if i == 0 or ctrl != answered[i - 1][0]:
                latest = reference.execute(ctrl[channel], RAMP)
            assert latest is not None
            assert (daq["disp"][channel], daq["force"][channel]) == \
                (latest.displacement, latest.force)
        assert rigs[channel].command == moves[-1][channel]  # held: nothing moved after
    commands = moves
    daqs = [d for _, d in answered]
    assert max(abs(c[1]) for c in commands) <= LIMIT  # the tripping command was never sent
    assert any(abs(d["disp"][0] - c[0]) > 1e-3 for d, c in zip(daqs, commands, strict=True))
    holds = [r for r in records if r["kind"] == "event" and r.get("event") == "hold"]
    assert len(holds) == 1 and "ctrl disp[2]" in str(holds[0]["reason"])  # actuator 2
    commits = [r for r in records if r["kind"] == "commit"]
    assert holds[0]["step"] == len(commits) >= 150  # a few hundred steps, then held


def test_a_channel_table_per_actuator_or_a_config_error() -> None:
    two = toml(limit=None).replace('[[sites.controller.channels]]\npreset = "ideal-elastic"\n',
                                   "")
    with pytest.raises(ConfigError, match=r"sites\[0\]: .*controller rig has 2 "
                                          r"\[\[sites.controller.channels\]\] table\(s\); this "
                                          r"site needs one per actuator: 3"):
        parse_config(two)
    both = toml(limit=None).replace('kind = "rig"\n', 'kind = "rig"\npreset = "ideal"\n')
    with pytest.raises(ConfigError, match="not both"):
        parse_config(both)


PLATFORM = """
[sites.controller.platform]
geometry = [[1.0, 0.0, 0.0], [0.0, 1.0, -400.0], [0.0, 1.0, 600.0]]
specimen = [{ kind = "bilinear", params = { k0 = 20.0, fy = 15.0, alpha = 0.05 } },
            { kind = "elastic", params = { k = 40.0 } },
            { kind = "elastic", params = { k = 8.0e6 } }]
"""


def test_a_column_of_three_coupled_actuators_under_opensees_holds_all_three(
        tmp_path: Path) -> None:
    """The three rigs (servo dynamics each) load one column (a platform specimen): every
    measurement is in the platform's equilibrium, and the limit on actuator 2 holds all."""
    import numpy as np

    presets = ("servo-hydraulic", "servo-hydraulic", "ideal-elastic")
    uncoupled = "".join(f'[[sites.controller.channels]]\npreset = "{p}"\n' for p in PRESETS)
    coupled = "".join(f'[[sites.controller.channels]]\npreset = "{p}"\n' for p in presets)
    # actuator 2 reaches 1.4 mm after about 210 steps
    text = toml(limit=1.4).replace(uncoupled, coupled + PLATFORM)
    with RunningBridge(text, tmp_path) as b:
        result = run_opensees(
            "column3", timeout=300, port=b.ports["col"], nsteps=400, dt=0.01,
            masses=[0.05, 0.05, 0.05],
            excitation=[[2000.0, 1.5, 0.0], [150.0, 2.0, 1.0], [2.0, 1.0, 0.0]])
        site = b.bridge.sites["col"]
        ctl = site.controller
        rigs, platform = b.call(lambda: (list(ctl.rigs), ctl.platform))  # type: ignore[attr-defined]
        run_dir = b.run_dir
    records = list(read_record(run_dir))
    holds = [r for r in records if r["kind"] == "event" and r.get("event") == "hold"]
    commits = [r for r in records if r["kind"] == "commit"]
    assert result["failed_at"] is not None and len(holds) == 1, result["failed_at"]
    assert "ctrl disp[2]" in str(holds[0]["reason"]) and len(commits) >= 150
    ctrls = [tuple(r["ctrl"]) for r in records if r["kind"] == "trial"]
    last_sent = ctrls[-2]  # the last trial is the refused one
    assert [r.command for r in rigs] == list(last_sent)  # held: nothing moved after
    t = np.array([[1.0, 0, 0], [0, 1.0, -400.0], [0, 1.0, 600.0]])
    for d in (r for r in records if r["kind"] == "daq"):
        x, f = np.array(d["disp"]), np.array(d["force"])
        q = np.linalg.solve(t, x)
        # the platform's equilibrium T'f = p(q) on its elastic DOFs (axial, rotation)
        np.testing.assert_allclose((t.T @ f)[1:], [40.0 * q[1], 8.0e6 * q[2]], rtol=1e-9,
                                   atol=1e-6)
    last_measured = [r for r in records if r["kind"] == "daq"][-1]["disp"]
    assert platform.strokes == pytest.approx(last_measured, abs=1e-12)  # where it was held
