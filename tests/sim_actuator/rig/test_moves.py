"""The composed rig: ramp-and-hold moves, exactness with ideal stages, capacities, determinism."""

from __future__ import annotations

import math
from typing import Any

import pytest

from sim_actuator.config import build_rig, parse_rig_config
from sim_actuator.models import make_model
from sim_actuator.rig import FaultCode, MoveOutcome, Rig, RigBusyError, RigCommandError, RigFault

BILINEAR = {"kind": "bilinear", "params": {"k0": 68.0, "fy": 35.0, "alpha": 0.008}}
BOUC_WEN = {
    "kind": "bouc-wen",
    "params": {"k0": 20.0, "fy": 10.0, "alpha": 0.05, "n": 2.0, "beta": 0.5, "gamma": 0.5},
}
TARGETS = [0.3, 1.2, -0.8, 2.5, -2.5, 0.0, 0.0, 1.0]


def _rig(**overrides: Any) -> Rig:
    data: dict[str, Any] = {"specimen": BILINEAR, "settle_time": 0.05, "default_ramp_time": 0.1}
    data.update(overrides)
    return build_rig(parse_rig_config(data))


@pytest.mark.parametrize(
    "specimen",
    [{"kind": "elastic", "params": {"k": 12.0}}, BILINEAR, BOUC_WEN],
    ids=["elastic", "bilinear", "bouc-wen"],
)
def test_ideal_rig_equals_the_bare_model_exactly(specimen: dict[str, Any]) -> None:
    rig = _rig(specimen=specimen)
    bare = make_model(specimen["kind"], **specimen["params"])
    assert rig.is_kinematic
    for i, target in enumerate(TARGETS, start=1):
        m = rig.execute(target, ramp_time=0.2)
        force, _ = bare.set_trial(target)
        bare.commit()
        assert (m.displacement, m.force) == (target, force)  # bit-exact
        assert m.time == pytest.approx(i * 0.25, abs=1e-12)  # ramp + settle, simulated
        assert m.command == target


def test_substep_path_reaches_the_bare_bilinear_result() -> None:
    """A delay shorter than the settle time: the piston ends on the target and the specimen,
    committed at every substep along the monotone path, agrees with one bilinear increment."""
    rig = _rig(actuator={"delay": 0.02})
    assert not rig.is_kinematic
    bare = make_model(**BILINEAR["params"], kind="bilinear")
    for target in TARGETS:
        m = rig.execute(target, ramp_time=0.1)
        force, _ = bare.set_trial(target)
        bare.commit()
        assert m.displacement == target
        assert m.force == pytest.approx(force, abs=1e-9)


def test_delay_longer_than_settle_measures_the_reference_one_delay_earlier() -> None:
    ramp, settle, delay = 0.1, 0.01, 0.03
    rig = _rig(settle_time=settle, actuator={"delay": delay},
               specimen={"kind": "elastic", "params": {"k": 5.0}})
    m = rig.execute(2.0, ramp_time=ramp)
    expected = 2.0 * (ramp + settle - delay) / ramp  # linear ramp from 0, sampled at t - delay
    assert m.displacement == pytest.approx(expected, abs=1e-12)
    assert m.force == pytest.approx(5.0 * expected, abs=1e-11)


def test_first_order_servo_step_move_in_the_rig() -> None:
    tau, settle = 0.02, 0.03
    rig = _rig(settle_time=settle, actuator={"servo": {"kind": "first_order", "tau": tau}},
               specimen={"kind": "elastic", "params": {"k": 5.0}})
    m = rig.execute(1.5, ramp_time=0.0)
    assert m.displacement == pytest.approx(1.5 * (1.0 - math.exp(-settle / tau)), abs=1e-12)


def test_amplitude_error_scales_the_measured_displacement() -> None:
    rig = _rig(actuator={"amplitude": 0.9}, specimen={"kind": "elastic", "params": {"k": 5.0}})
    m = rig.execute(2.0)
    assert m.displacement == pytest.approx(1.8, abs=1e-12)
    assert m.force == pytest.approx(9.0, abs=1e-11)


def test_compliant_frame_lowers_the_measured_stiffness() -> None:
    k, kf = 12.0, 30.0
    rig = _rig(effects={"frame": {"stiffness": kf}},
               specimen={"kind": "elastic", "params": {"k": k}})
    m = rig.execute(2.0)
    assert m.force / m.displacement == pytest.approx(k * kf / (k + kf), rel=1e-10)
    assert m.specimen_displacement == pytest.approx(2.0 * kf / (k + kf), rel=1e-10)


def test_external_lvdt_reads_the_specimen_displacement() -> None:
    k, kf = 12.0, 30.0
    rig = _rig(effects={"frame": {"stiffness": kf}}, sensors={"lvdt": {"location": "specimen"}},
               specimen={"kind": "elastic", "params": {"k": k}})
    m = rig.execute(2.0)
    assert m.displacement == pytest.approx(2.0 * kf / (k + kf), rel=1e-10)
    assert m.force / m.displacement == pytest.approx(k, rel=1e-10)


def test_stroke_limit_faults_without_motion_until_reset() -> None:
    rig = _rig(actuator={"stroke": 10.0})
    before = rig.execute(1.0)
    with pytest.raises(RigFault, match="beyond the actuator stroke") as info:
        rig.execute(10.5)
    assert info.value.code is FaultCode.STROKE_LIMIT
    assert rig.fault is FaultCode.STROKE_LIMIT
    assert rig.time == before.time
    assert rig.state.specimen_displacement == 1.0
    with pytest.raises(RigFault, match="latched"):
        rig.execute(2.0)
    rig.reset_fault()
    assert rig.execute(-10.0).displacement == -10.0  # the limit itself is allowed


def test_amplified_end_point_beyond_stroke_is_refused() -> None:
    rig = _rig(actuator={"stroke": 10.0, "amplitude": 1.1})
    with pytest.raises(RigFault, match="beyond the stroke"):
        rig.begin_move(9.5)


def test_force_capacity_trips_within_one_substep_and_holds() -> None:
    k, capacity = 10.0, 50.0
    rig = _rig(actuator={"force_capacity": capacity},
               specimen={"kind": "elastic", "params": {"k": k}})
    with pytest.raises(RigFault) as info:
        rig.execute(10.0, ramp_time=1.0)  # 10 mm/s: 0.01 mm per substep
    assert info.value.code is FaultCode.FORCE_LIMIT
    m = info.value.measurement
    assert m is not None
    assert capacity < m.force <= capacity + k * 0.01 + 1e-9
    assert m.time == pytest.approx(m.displacement / 10.0, abs=1e-12)  # tripped mid-ramp
    held = rig.measure()
    assert (held.displacement, held.force) == (m.displacement, m.force)
    rig.reset_fault()
    back = rig.execute(0.0, ramp_time=0.1)  # bumpless: the next move starts at the trip point
    assert back.force == 0.0


def test_bad_commands_are_refused_without_latching() -> None:
    rig = _rig()
    with pytest.raises(RigCommandError, match="finite"):
        rig.execute(math.nan)
    with pytest.raises(RigCommandError, match="ramp time"):
        rig.execute(1.0, ramp_time=-0.5)
    with pytest.raises(RigCommandError, match="ramp time"):
        rig.execute(1.0, ramp_time=1e6)
    assert rig.fault is FaultCode.NONE
    assert rig.time == 0.0


def test_chunked_stepping_is_identical_to_one_go() -> None:
    config = {"actuator": {"delay": 0.013, "servo": {"kind": "second_order",
                                                     "natural_frequency": 12.0, "damping": 0.4}},
              "effects": {"friction": {"coulomb": 0.4}, "backlash": {"gap": 0.02},
                          "frame": {"stiffness": 900.0}}}
    a, b = _rig(**config), _rig(**config)
    for target in TARGETS:
        ma = a.execute(target, 0.1)
        move = b.begin_move(target, 0.1)
        with pytest.raises(RigBusyError):
            b.begin_move(target, 0.1)
        while not move.advance(7):
            pass
        assert move.outcome is MoveOutcome.DONE
        assert move.measurement == ma


def test_noise_is_seeded_and_bias_is_exact() -> None:
    noisy = {"sensors": {"lvdt": {"noise_std": 0.01, "bias": 0.5},
                         "load_cell": {"noise_std": 0.1}}}
    a, b = _rig(seed=4, **noisy), _rig(seed=4, **noisy)
    c = _rig(seed=5, **noisy)
    ra = [a.execute(t) for t in TARGETS]
    assert ra == [b.execute(t) for t in TARGETS]
    assert ra != [c.execute(t) for t in TARGETS]
    biased = _rig(sensors={"lvdt": {"bias": 0.5}, "load_cell": {"bias": -2.0}})
    m = biased.execute(1.0)
    assert (m.displacement, m.force) == (1.5, m.load_cell_force - 2.0)


def test_abort_holds_position_without_fault() -> None:
    rig = _rig(actuator={"servo": {"kind": "first_order", "tau": 0.01}})
    move = rig.begin_move(2.0, ramp_time=1.0)
    move.advance(300)
    move.abort()
    assert move.outcome is MoveOutcome.ABORTED
    assert rig.fault is FaultCode.NONE
    held = rig.position
    assert 0.4 < held < 0.7  # about 0.6 mm along the 2 mm/s ramp, minus the lag
    assert rig.reference == held
    nxt = rig.execute(held, ramp_time=0.0)  # a move to where it stopped goes nowhere
    assert nxt.actuator_displacement == pytest.approx(held, abs=1e-12)
