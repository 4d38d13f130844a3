"""The pure limit logic: absolute, increment and velocity limits under each policy, sub-stepping,
daq (force) limits, and the ``[[sites.limits]]`` configuration."""

from __future__ import annotations

import itertools
import math

import pytest
from hypothesis import given
from hypothesis import strategies as st

from fresco_bridge.config import ConfigError, parse_config
from fresco_bridge.safety import ControlPointLimits, Limiter, split
from tests.support.paths import EXAMPLES


def one(**kw: object) -> Limiter:
    return Limiter([ControlPointLimits(actuator=0, **kw)], 1)  # type: ignore[arg-type]


def test_within_every_limit_is_forwarded_as_is_without_a_verdict() -> None:
    lim = one(disp_min=-10.0, disp_max=10.0, disp_increment=1.0, velocity=100.0)
    assert lim.check_ctrl((5.0,), (4.5,), 0.01) is None
    assert lim.check_ctrl((10.0,), (9.5,), 0.01) is None  # the bound itself is allowed


@pytest.mark.parametrize("policy", ["reject", "pause"])
@pytest.mark.parametrize("value,bound", [(10.5, 10.0), (-12.0, -10.0)])
def test_absolute_limit_rejects_or_pauses_without_commands(
    policy: str, value: float, bound: float
) -> None:
    v = one(disp_min=-10.0, disp_max=10.0, policy=policy).check_ctrl((value,), None, 0.0)
    assert v is not None and v.action == policy and v.commands == ()
    (hit,) = v.hits
    assert (hit.limit, hit.value, hit.bound, hit.actuator) == ("absolute", value, bound, 0)
    assert "ctrl disp[1]" in hit.describe() and f"{bound:g} mm" in hit.describe()


def test_absolute_limit_clamps_to_the_bound() -> None:
    v = one(disp_min=-10.0, disp_max=10.0, policy="clamp").check_ctrl((13.0,), None, 0.0)
    assert v is not None and v.action == "clamp" and v.commands == ((10.0,),)


def test_increment_limit_against_the_last_command_sent() -> None:
    lim = one(disp_increment=1.0, policy="clamp")
    v = lim.check_ctrl((3.5,), (2.0,), 0.01)
    assert v is not None and v.commands == ((3.0,),)
    assert v.hits[0].limit == "increment" and v.hits[0].value == pytest.approx(1.5)
    v = lim.check_ctrl((-1.0,), (2.0,), 0.01)
    assert v is not None and v.commands == ((1.0,),)
    assert one(disp_increment=1.0).check_ctrl((3.5,), (2.0,), 0.01).action == "reject"  # type: ignore[union-attr]
    assert lim.check_ctrl((3.5,), None, 0.01) is None  # no reference: nothing to compare


def test_velocity_uses_the_trial_dt_or_the_configured_step_time() -> None:
    lim = one(velocity=10.0, policy="clamp")  # 10 mm/s
    assert lim.check_ctrl((0.1,), (0.0,), 0.01) is None  # exactly 10 mm/s
    v = lim.check_ctrl((0.5,), (0.0,), 0.01)
    assert v is not None and v.hits[0].limit == "velocity"
    assert v.hits[0].value == pytest.approx(50.0) and v.commands[0][0] == pytest.approx(0.1)
    fixed = one(velocity=10.0, step_time=0.1)  # the lab's ramp time wins over the trial dt
    assert fixed.check_ctrl((0.5,), (0.0,), 0.01) is None
    assert fixed.check_ctrl((1.5,), (0.0,), 0.01).action == "reject"  # type: ignore[union-attr]


def test_velocity_without_any_dt_is_a_violation_naming_step_time() -> None:
    v = one(velocity=10.0).check_ctrl((0.5,), (0.0,), 0.0)
    assert v is not None and v.action == "reject" and math.isnan(v.hits[0].value)
    assert "set step_time" in v.describe()
    assert one(velocity=10.0).check_ctrl((0.0,), (0.0,), 0.0) is None  # no motion: fine
    clamp = one(velocity=10.0, policy="clamp").check_ctrl((0.5,), (0.0,), 0.0)
    assert clamp is not None and clamp.action == "reject"  # nothing to clamp to without dt
    assert one(velocity=10.0, policy="pause").check_ctrl((0.5,), (0.0,), 0.0).action == "pause"  # type: ignore[union-attr]


def test_substeps_split_a_fast_command_into_equal_steps_ending_exactly_on_target() -> None:
    lim = one(disp_min=-50.0, disp_max=50.0, velocity=10.0, step_time=0.1, max_substeps=10)
    v = lim.check_ctrl((3.3,), (0.0,), 0.0)  # 3.3 mm, 1 mm per sub-step → 4 sub-commands
    assert v is not None and v.action == "substep" and v.hits == ()
    assert [c[0] for c in v.commands] == pytest.approx([0.825, 1.65, 2.475, 3.3])
    assert v.commands[-1] == (3.3,)
    # more sub-steps than allowed → the policy applies
    assert lim.check_ctrl((10.5,), (0.0,), 0.0).action == "reject"  # type: ignore[union-attr]
    # beyond the absolute limit → never sub-stepped into
    assert lim.check_ctrl((50.5,), (49.0,), 0.0).action == "reject"  # type: ignore[union-attr]


def test_pause_approved_by_the_operator_waives_increment_and_velocity_but_not_absolute() -> None:
    lim = one(disp_max=10.0, disp_increment=1.0, velocity=10.0, step_time=0.01, policy="pause")
    assert lim.check_ctrl((5.0,), (0.0,), 0.0).action == "pause"  # type: ignore[union-attr]
    assert lim.check_ctrl((5.0,), (0.0,), 0.0, approved=True) is None
    v = lim.check_ctrl((11.0,), (9.5,), 0.0, approved=True)
    assert v is not None and v.action == "reject" and v.hits[0].limit == "absolute"


def test_the_most_severe_policy_of_all_control_points_wins() -> None:
    lim = Limiter([ControlPointLimits(0, disp_max=1.0, policy="clamp"),
                   ControlPointLimits(2, disp_max=1.0, policy="pause")], 3)
    v = lim.check_ctrl((2.0, 99.0, 0.5), None, 0.0)
    assert v is not None and v.action == "clamp" and v.commands == ((1.0, 99.0, 0.5),)
    v = lim.check_ctrl((2.0, 99.0, 3.0), None, 0.0)
    assert v is not None and v.action == "pause" and len(v.hits) == 2


def test_substeps_move_every_actuator_together() -> None:
    lim = Limiter([ControlPointLimits(0, velocity=1.0, step_time=1.0, max_substeps=5)], 2)
    v = lim.check_ctrl((3.0, 6.0), (0.0, 0.0), 0.0)
    assert v is not None and v.commands == ((1.0, 2.0), (2.0, 4.0), (3.0, 6.0))


def test_daq_force_limits() -> None:
    lim = one(force_min=-5.0, force_max=20.0)
    assert lim.has_daq and not lim.has_ctrl
    assert lim.check_daq((19.9,)) is None
    hit = lim.check_daq((20.5,))
    assert hit is not None and (hit.limit, hit.bound, hit.policy) == ("force", 20.0, "reject")
    assert "daq force[1]" in hit.describe() and "kN" in hit.describe()
    assert lim.check_daq((-6.0,)).bound == -5.0  # type: ignore[union-attr]


def test_limiter_refuses_actuators_the_setup_does_not_have() -> None:
    with pytest.raises(ValueError, match="actuator 3"):
        Limiter([ControlPointLimits(2, disp_max=1.0)], 2)
    with pytest.raises(ValueError, match="two limit entries"):
        Limiter([ControlPointLimits(0, disp_max=1.0), ControlPointLimits(0, disp_min=0.0)], 1)


finite = st.floats(min_value=-100.0, max_value=100.0, allow_nan=False)
positive = st.floats(min_value=0.01, max_value=10.0)


@given(c=finite, p=st.floats(min_value=-20.0, max_value=20.0), inc=positive, vel=positive,
       dt=st.floats(min_value=0.001, max_value=1.0))
def test_clamped_commands_always_satisfy_every_limit(
    c: float, p: float, inc: float, vel: float, dt: float
) -> None:
    lim = one(disp_min=-20.0, disp_max=20.0, disp_increment=inc, velocity=vel, policy="clamp")
    v = lim.check_ctrl((c,), (p,), dt)
    out = c if v is None else v.commands[-1][0]
    assert v is None or v.action == "clamp"
    eps = 1e-9
    assert -20.0 - eps <= out <= 20.0 + eps
    assert abs(out - p) <= inc + eps
    assert abs(out - p) <= vel * dt * (1 + 1e-9) + eps


@given(c=st.floats(min_value=-20.0, max_value=20.0), p=st.floats(min_value=-20.0, max_value=20.0),
       vel=positive, dt=st.floats(min_value=0.01, max_value=1.0))
def test_substeps_are_each_within_the_velocity_limit(
    c: float, p: float, vel: float, dt: float
) -> None:
    lim = one(disp_min=-20.0, disp_max=20.0, velocity=vel, max_substeps=1000)
    v = lim.check_ctrl((c,), (p,), dt)
    if v is None:
        assert abs(c - p) <= vel * dt
        return
    if v.action == "reject":  # needs more than 1000 sub-steps
        assert abs(c - p) / (vel * dt) > 1000
        return
    path = [p, *(cmd[0] for cmd in v.commands)]
    assert path[-1] == c
    assert all(abs(b - a) <= vel * dt * (1 + 1e-9) for a, b in itertools.pairwise(path))
    assert len(v.commands) == math.ceil(abs(c - p) / (vel * dt))


def test_split_is_exact_at_the_end() -> None:
    assert split((0.0,), (0.3,), 3)[-1] == (0.3,)


# -- configuration ------------------------------------------------------------------------------
SITE = """
[[sites]]
name = "s"
port = 0
dofs = 2
setup = "OneActuator"
"""


def cfg(limits: str) -> str:
    return SITE + "[[sites.limits]]\n" + limits


def test_limits_config_defaults_to_no_limits_and_maps_to_control_points() -> None:
    assert parse_config(SITE).sites[0].limits == []
    lab = parse_config(cfg('disp_min = -5.0\ndisp_max = 5.0\npolicy = "clamp"\n'))
    (lim,) = lab.sites[0].limits
    cp = lim.to_limits()
    assert (cp.actuator, cp.disp_min, cp.disp_max, cp.policy) == (0, -5.0, 5.0, "clamp")
    assert cp.disp_increment == math.inf and cp.force_max == math.inf


@pytest.mark.parametrize(
    ("limits", "message"),
    [
        ("disp_min = 5.0\ndisp_max = -5.0\n", "disp_min (5.0 mm) must be below disp_max"),
        ("force_min = 1.0\nforce_max = 1.0\n", "force_min (1.0 kN) must be below force_max"),
        ("disp_increment = 0.0\n", "sites[0].limits[0].disp_increment: Input should be greater"),
        ("velocity = -1.0\n", "sites[0].limits[0].velocity"),
        ("disp_max = 1.0\nlimit = 3\n", "sites[0].limits[0].limit: unknown key"),
        ("policy = \"warn\"\ndisp_max = 1.0\n", "sites[0].limits[0].policy"),
        ("actuator = 2\ndisp_max = 1.0\n", "actuator 2 does not exist"),
        ("policy = \"clamp\"\n", "set no limit"),
        ("disp_max = 1.0\nmax_substeps = 4\n", "max_substeps needs a velocity limit"),
        ("velocity = 1.0\nmax_substeps = 1\n", "0 (off) or at least 2"),
        ("disp_max = 1.0\nstep_time = 0.1\n", "step_time is only used by the velocity"),
    ],
)
def test_bad_limits_are_refused_with_file_key_and_reason(limits: str, message: str) -> None:
    with pytest.raises(ConfigError) as err:
        parse_config(cfg(limits), "lab.toml")
    assert "lab.toml" in str(err.value) and message in str(err.value), str(err.value)


def test_one_limits_table_per_actuator() -> None:
    text = SITE.replace('dofs = 2\nsetup = "OneActuator"', "dofs = 2") + (
        "[[sites.limits]]\nactuator = 2\ndisp_max = 1.0\n"
        "[[sites.limits]]\nactuator = 2\ndisp_min = -1.0\n")
    with pytest.raises(ConfigError, match=r"repeated: \[2\]"):
        parse_config(text)


@pytest.mark.parametrize(
    ("telemetry", "message"),
    [
        ('accept_commands = true\ncommand_token = "0123456789abcdef"\n', "mqtt_host is not set"),
        ('mqtt_host = "127.0.0.1"\naccept_commands = true\ncommand_token = "0123456789abcdef"\n',
         "broker credentials"),
        ('mqtt_host = "127.0.0.1"\naccept_commands = true\nusername = "u"\npassword = "p"\n'
         'command_token = "short"\n', "command_token of at least 16"),
    ],
)
def test_mqtt_commands_are_refused_at_config_time_without_credentials_and_token(
    telemetry: str, message: str
) -> None:
    with pytest.raises(ConfigError, match=message):
        parse_config("[telemetry]\n" + telemetry + SITE)


def test_the_commented_limits_example_in_examples_lab_toml_is_valid() -> None:
    """Uncommenting the documented ``[[sites.limits]]`` block gives a valid configuration."""
    path = EXAMPLES / "lab.toml"
    lines = path.read_text(encoding="utf-8").splitlines()
    start = lines.index("# [[sites.limits]]")
    block = []
    for line in lines[start:]:
        if not line.startswith("#"):
            break
        block.append(line[2:] if not line.startswith("#  ") else "")
    text = "\n".join(lines[:start] + block + lines[start + len(block):])
    lab = parse_config(text, str(path))
    (lim,) = lab.sites[0].limits
    assert (lim.disp_max, lim.velocity, lim.max_substeps, lim.force_max) == (40.0, 20.0, 10, 150.0)


def test_a_single_limits_table_is_accepted_for_a_one_actuator_site() -> None:
    lab = parse_config(SITE + "[sites.limits]\ndisp_max = 3.0\n")
    (lim,) = lab.sites[0].limits
    assert (lim.actuator, lim.disp_max) == (1, 3.0)
