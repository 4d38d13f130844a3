"""OpenFresco's multi-actuator setups: fixed tables against OpenFresco's own formulas, exact
round trips and virtual work under nonlinear geometry at large rotations, rates against
finite differences, linear matrices, and one served end to end through the bridge."""

from __future__ import annotations

import math
import random
import textwrap
from collections.abc import Callable
from typing import Any

import numpy as np
import pytest

from fresco_bridge.daemon import BridgeThread
from fresco_bridge.integrator.link import GenericClientLink
from fresco_bridge.setups import Setup, make_setup
from fresco_bridge.setups.kinds import parse_setup_table
from protocol import Action

LA3 = {"La1": 1000.0, "La2": 900.0, "La3": 800.0}
GEOMETRY: dict[str, dict[str, Any]] = {
    "TwoActuators2d": {"La1": 1000.0, "La2": 900.0, "L": 600.0},
    "ThreeActuators2d": {**LA3, "L1": 500.0, "L2": 400.0},
    "InvertedVBrace2d": {**LA3, "L1": 500.0, "L2": 400.0},
    "ThreeActuatorsJntOff2d": {**LA3, "L1": 150.0, "L2": 500.0, "L3": 400.0, "L4": 120.0,
                               "L5": 60.0, "L6": 70.0},
    "InvertedVBraceJntOff2d": {**LA3, "L1": 150.0, "L2": 500.0, "L3": 400.0, "L4": 120.0,
                               "L5": 60.0, "L6": 70.0},
    "ThreeActuators": {**LA3, "L1": 500.0, "L2": 400.0, "L3": 250.0, "dofH": 1, "dofV": 2,
                       "dofR": 3, "sizeTrial": 3, "sizeOut": 3},
    "ThreeActuatorsJntOff": {**LA3, "L1": 150.0, "L2": 500.0, "L3": 400.0, "L4": 120.0,
                             "L5": 60.0, "L6": 250.0, "L7": 70.0, "dofH": 1, "dofV": 2,
                             "dofR": 3, "sizeTrial": 3, "sizeOut": 3},
}
POSITION = {"TwoActuators2d": "posAct"}
TRIALS = [(12.5, -7.5, 0.05), (80.0, 35.0, -0.4), (-150.0, 60.0, 0.6)]

# OpenFresco 2.8's ES<kind>::transfTrialDisp with -nlGeom, evaluated at TRIALS with GEOMETRY
# (the InvertedVBrace setups share the ThreeActuators2d/JntOff2d formulas).
OPENFRESCO_CTRL: dict[tuple[str, str], list[tuple[float, ...]]] = {
    ("TwoActuators2d", "left"): [(12.5, -17.487183002857705), (80.0, 314.5748453153867),
                                 (-150.0, -475.6415062597429)],
    ("TwoActuators2d", "right"): [(-12.5, 17.48780797833865), (-80.0, -311.7411832482146),
                                  (150.0, 492.73395655551394)],
    ("ThreeActuators2d", "left"): [
        (13.64568510014567, -32.390304933434095, 12.58028070780199),
        (142.7940634498607, 236.0087031079097, -119.04336931557611),
        (-36.662898322590195, -219.42982704031272, 307.8927525421973)],
    ("ThreeActuators2d", "right"): [
        (-11.921138802188807, -32.390304933434095, 12.58028070780199),
        (-40.79153634451745, 236.0087031079097, -119.04336931557611),
        (252.91128027285345, -219.42982704031272, 307.8927525421973)],
    ("ThreeActuatorsJntOff2d", "left"): [
        (14.100979499462028, -32.26478868017534, 12.726941966797426),
        (167.42338466494448, 238.50896999839551, -114.91458963202228),
        (11.263288170451915, -211.23943453742686, 312.79385428433693)],
    ("ThreeActuatorsJntOff2d", "right"): [
        (-11.677176104659338, -32.26478868017534, 12.726941966797426),
        (-24.464645581081754, 238.50896999839551, -114.91458963202228),
        (290.22896974324726, -211.23943453742686, 312.79385428433693)],
    ("ThreeActuators", "left"): [
        (1.1675806042716204, -32.80179063985588, 12.1793834611683),
        (234.80772569967553, 230.9535347109752, -124.58234601746403),
        (-160.57255414245446, -234.02846222984715, 302.9514491525026)],
    ("ThreeActuators", "right"): [
        (0.5688155981620184, -32.80179063985588, 12.1793834611683),
        (-134.30121726375182, 230.9535347109752, -124.58234601746403),
        (382.40703666492027, -234.02846222984715, 302.9514491525026)],
    ("ThreeActuatorsJntOff", "left"): [
        (1.6285469936624395, -32.71944335647663, 12.27226885481116),
        (257.6363572408029, 231.3737041956183, -124.49769540182012),
        (-105.9790251945958, -233.47649536684196, 302.34259793802175)],
    ("ThreeActuatorsJntOff", "right"): [
        (0.8097336826846231, -32.71944335647663, 12.27226885481116),
        (-116.24509426880411, 231.3737041956183, -124.49769540182012),
        (416.31681948300206, -233.47649536684196, 302.34259793802175)],
}
OPENFRESCO_CTRL.update({("InvertedVBrace2d", side): OPENFRESCO_CTRL["ThreeActuators2d", side]
                        for side in ("left", "right")})
OPENFRESCO_CTRL.update({("InvertedVBraceJntOff2d", side):
                        OPENFRESCO_CTRL["ThreeActuatorsJntOff2d", side]
                        for side in ("left", "right")})

# OpenFresco's linear geometry (transfTrialDisp without -nlGeom), row by row, left position.
OPENFRESCO_LINEAR: dict[str, list[list[float]]] = {
    "TwoActuators2d": [[1, 0, 0], [1, 0, -600]],
    "ThreeActuators2d": [[1, 0, 0], [0, 1, -500], [0, 1, 400]],
    "InvertedVBrace2d": [[1, 0, 0], [0, 1, -500], [0, 1, 400]],
    "ThreeActuatorsJntOff2d": [[1, 0, 0], [0, 1, -500], [0, 1, 400]],
    "InvertedVBraceJntOff2d": [[1, 0, 0], [0, 1, -500], [0, 1, 400]],
    "ThreeActuators": [[1, 0, -250], [0, 1, -500], [0, 1, 400]],
    "ThreeActuatorsJntOff": [[1, 0, -250], [0, 1, -500], [0, 1, 400]],
}
KINDS = list(GEOMETRY)


def build(kind: str, side: str = "left", **extra: Any) -> Setup:
    table = {"kind": kind, **GEOMETRY[kind], POSITION.get(kind, "posAct1"): side, **extra}
    return make_setup(parse_setup_table(table), 3)


def driven(kind: str, u: tuple[float, ...]) -> tuple[float, ...]:
    """TwoActuators2d does not drive the vertical DOF: it reads as zero."""
    return (u[0], 0.0, u[2]) if kind == "TwoActuators2d" else u


@pytest.mark.parametrize("side", ["left", "right"])
@pytest.mark.parametrize("kind", KINDS)
def test_nonlinear_strokes_equal_openfrescos_formulas(kind: str, side: str) -> None:
    setup = build(kind, side, nlGeom=True)
    for trial, want in zip(TRIALS, OPENFRESCO_CTRL[kind, side], strict=True):
        assert setup.ctrl_disp(trial) == pytest.approx(want, rel=1e-13, abs=1e-10)


@pytest.mark.parametrize("kind", KINDS)
def test_linear_geometry_is_openfrescos_matrix(kind: str) -> None:
    setup = build(kind)
    for e in np.eye(3):
        got = setup.ctrl_disp(tuple(e))
        want = np.array(OPENFRESCO_LINEAR[kind], dtype=float) @ e
        assert got == pytest.approx(want.tolist(), abs=1e-12)
    # right: the horizontal actuators push from the other side (their rows change sign)
    flip = np.diag([-1.0, -1.0] if kind == "TwoActuators2d" else [-1.0, 1.0, 1.0])
    right = build(kind, "right")
    for e in np.eye(3):
        want = flip @ np.array(OPENFRESCO_LINEAR[kind], dtype=float) @ e
        assert right.ctrl_disp(tuple(e)) == pytest.approx(want.tolist(), abs=1e-12)


def random_trials(n: int, seed: int) -> list[tuple[float, float, float]]:
    rng = random.Random(seed)
    return [(rng.uniform(-200, 200), rng.uniform(-150, 150), rng.uniform(-0.6, 0.6))
            for _ in range(n)]


@pytest.mark.parametrize("side", ["left", "right"])
@pytest.mark.parametrize("kind", KINDS)
def test_trial_ctrl_daq_out_returns_the_trial_at_large_rotations(kind: str, side: str) -> None:
    for phi in (0.0, 90.0, -33.0):
        extra = {"phiLocX": phi} if kind not in ("ThreeActuators", "ThreeActuatorsJntOff") \
            else {}
        setup = build(kind, side, nlGeom=True, **extra)
        inverse = build(kind, side, nlGeom=True, **extra)  # never saw the trials: Newton
        for trial in random_trials(200, seed=len(kind)):
            rotated = trial
            if phi and kind == "TwoActuators2d":  # its undriven DOF is the local y
                c, s = math.cos(math.radians(phi)), math.sin(math.radians(phi))
                x = c * trial[0] - s * trial[1]
                rotated = (c * x, -s * x, trial[2])  # Rᵀ (x, 0)
            want = driven(kind, trial) if not phi else rotated
            ctrl = setup.ctrl_disp(trial)
            out = inverse.out_disp(trial, ctrl, ctrl)
            # relative to the trial's size, θ counted as the arc at 1 m (θ up to 0.6 rad)
            err = max(abs(o - w) * s for o, w, s in zip(out, want, (1, 1, 1000), strict=True))
            assert err <= 1e-12 * max(abs(w) * s for w, s in zip(want, (1, 1, 1000),
                                                                  strict=True))


@pytest.mark.parametrize("kind", KINDS)
def test_out_force_does_the_actuators_virtual_work(kind: str) -> None:
    rng = np.random.default_rng(7)
    setup = build(kind, "right", nlGeom=True, phiLocX=20.0) \
        if kind not in ("ThreeActuators", "ThreeActuatorsJntOff") else build(kind, nlGeom=True)
    for trial in random_trials(30, seed=11):
        ctrl = setup.ctrl_disp(trial)
        f = tuple(rng.uniform(-500, 500, setup.n_actuators).tolist())
        q = setup.basic_force(f, ctrl)
        delta = tuple(rng.uniform(-1, 1, 3).tolist())
        if kind == "TwoActuators2d":  # δ within the driven DOFs (the vertical one is held)
            c, s = math.cos(math.radians(20.0)), math.sin(math.radians(20.0))
            delta = (c * delta[0], -s * delta[0], delta[2])  # Rᵀ (δx, 0): local y stays zero
        d_ctrl = setup.ctrl_vel(trial, delta)  # the exact derivative of the strokes along δ
        work_out = float(np.dot(q, delta))
        work_daq = float(np.dot(f, d_ctrl))
        assert work_out == pytest.approx(work_daq, rel=1e-9, abs=1e-9 * float(np.abs(f).sum()))


@pytest.mark.parametrize("kind", KINDS)
def test_velocity_and_acceleration_are_the_strokes_derivatives(kind: str) -> None:
    setup = build(kind, nlGeom=True)
    rng = np.random.default_rng(3)
    h = 1e-5
    for trial in random_trials(10, seed=5):
        u0 = np.array(trial)
        v = rng.uniform(-50, 50, 3)
        v[2] = rng.uniform(-0.3, 0.3)
        a = rng.uniform(-500, 500, 3)
        a[2] = rng.uniform(-3, 3)

        def path(t: float, u0: Any = u0, v: Any = v, a: Any = a) -> np.ndarray:
            return np.array(setup.ctrl_disp(tuple((u0 + v * t + 0.5 * a * t * t).tolist())))

        fd_vel = (path(h) - path(-h)) / (2 * h)
        fd_acc = (path(h) - 2 * path(0.0) + path(-h)) / (h * h)
        vel = setup.ctrl_vel(trial, tuple(v.tolist()))
        acc = setup.ctrl_accel(trial, tuple(v.tolist()), tuple(a.tolist()))
        assert vel == pytest.approx(fd_vel.tolist(), rel=1e-6, abs=1e-6)
        assert acc == pytest.approx(fd_acc.tolist(), rel=1e-3, abs=5e-2)


@pytest.mark.parametrize("kind", KINDS)
def test_measured_strokes_off_the_command_are_solved_from_the_commanded_pose(kind: str) -> None:
    setup = build(kind, "right", nlGeom=True)
    for trial in random_trials(50, seed=9):
        ctrl = setup.ctrl_disp(trial)
        daq = tuple(c + 0.05 * (i - 1) for i, c in enumerate(ctrl))  # a tracking error
        out = setup.out_disp(trial, ctrl, daq)
        assert setup.ctrl_disp(out) == pytest.approx(daq, rel=1e-12, abs=1e-12)


def test_daq_velocity_under_nonlinear_geometry_falls_back_to_linear_with_a_warning(
        caplog: pytest.LogCaptureFixture) -> None:
    nl, lin = build("ThreeActuators2d", nlGeom=True), build("ThreeActuators2d")
    daq = (1.0, 2.0, -3.0)
    assert nl.out_vel(daq) == lin.out_vel(daq)
    assert nl.out_accel(daq) == lin.out_accel(daq)
    assert sum("uses linear geometry" in r.message for r in caplog.records) == 1


def test_a_platform_on_three_dofs_of_a_six_dof_element() -> None:
    table = {"kind": "ThreeActuators", **GEOMETRY["ThreeActuators"], "dofH": 2, "dofV": 1,
             "dofR": 6, "sizeTrial": 6, "sizeOut": 6, "nlGeom": True}
    setup = make_setup(parse_setup_table(table), 6)
    trial = (35.0, 80.0, 7.0, -1.0, 2.0, -0.4)
    ctrl = setup.ctrl_disp(trial)
    assert ctrl == pytest.approx(OPENFRESCO_CTRL["ThreeActuators", "left"][1], rel=1e-13)
    out = setup.out_disp(trial, ctrl, ctrl)
    assert out == pytest.approx((35.0, 80.0, 0.0, 0.0, 0.0, -0.4), rel=1e-12, abs=1e-12)
    force = setup.basic_force((1.0, 2.0, 3.0), ctrl)
    assert force[2:5] == (0.0, 0.0, 0.0)


def test_scale_factors_apply_before_and_after_the_transformation() -> None:
    table = {"kind": "OneActuator", "dir": 2, "sizeTrialOut": [3, 3],
             "trialDispFact": [1.0, -1000.0, 1.0], "ctrlDispFact": 0.5,
             "daqDispFact": 2.0, "outDispFact": 0.001, "daqForceFact": -1000.0,
             "outForceFact": [1.0, 0.01, 1.0]}
    setup = make_setup(parse_setup_table(table), 3)
    assert setup.ctrl_disp((9.0, 0.002, 9.0)) == (-1.0,)  # 0.002 m → −2 mm, × 0.5
    out = setup.out_disp((9.0, 0.002, 9.0), (-1.0,), (-1.0,))
    assert out[1] == pytest.approx(-0.002)  # daq × 2 → −2 mm, × 0.001
    assert setup.basic_force((0.003,), (-1.0,)) == pytest.approx((0.0, -0.03, 0.0))
    # stiffness in the same units: diag(outForce) Tᵀ diag(daqForce) k diag(ctrlDisp) T diag(trial)
    k = setup.basic_matrix((4.0,))
    assert k[4] == pytest.approx(0.01 * -1000.0 * 4.0 * 0.5 * -1000.0)
    with pytest.raises(ValueError, match="2 factors for a signal of 3 components"):
        make_setup(parse_setup_table({"kind": "NoTransformation", "trialDispFact": [1.0, 2.0]}),
                   3)


def test_the_aggregator_stacks_its_setups() -> None:
    table = {"kind": "Aggregator", "setups": [
        {"kind": "OneActuator", "dir": 1, "sizeTrialOut": [2, 2]},
        {"kind": "ThreeActuators2d", **GEOMETRY["ThreeActuators2d"], "nlGeom": True}]}
    setup = make_setup(parse_setup_table(table), 5)
    assert (setup.n_basic, setup.n_actuators) == (5, 4)
    trial = (3.0, 4.0, *TRIALS[1])
    ctrl = setup.ctrl_disp(trial)
    assert ctrl[0] == 3.0
    assert ctrl[1:] == pytest.approx(OPENFRESCO_CTRL["ThreeActuators2d", "left"][1], rel=1e-13)
    assert setup.out_disp(trial, ctrl, ctrl) == pytest.approx((3.0, 4.0, *TRIALS[1]),
                                                              rel=1e-12)
    with pytest.raises(ValueError, match="serve 5 basic DOFs; this site has dofs = 4"):
        make_setup(parse_setup_table(table), 4)


def test_a_three_actuator_column_is_served_end_to_end(
        run_bridge: Callable[[str], BridgeThread]) -> None:
    """Nonlinear geometry on the sim controller with elastic actuators: the bridge's answer is
    the geometry's, computed here independently of the setup code."""
    k = 20.0
    config = textwrap.dedent(f"""
        [record]
        enabled = false
        [[sites]]
        name = "column"
        port = 0
        dofs = 3
        [sites.setup]
        kind = "ThreeActuators2d"
        La1 = 1000.0
        La2 = 900.0
        La3 = 800.0
        L1 = 500.0
        L2 = 400.0
        nlGeom = true
        [sites.controller]
        kind = "sim"
        model = "elastic"
        params = {{ k = {k} }}
        """)
    bridge = run_bridge(config)
    points = [((-500.0, 0.0), (-1500.0, 0.0)), ((-500.0, 0.0), (-500.0, -900.0)),
              ((400.0, 0.0), (400.0, -800.0))]  # (platform point, ground point)
    with GenericClientLink("127.0.0.1", bridge.ports["column"], 3, timeout=20.0) as link:
        for step, (x, y, th) in enumerate(TRIALS, start=1):
            link.set_trial((x, y, th), time=0.01 * step)
            want = np.zeros(3)
            c, s = math.cos(th), math.sin(th)
            for (px, py), (gx, gy) in points:
                wx, wy = c * px - s * py, s * px + c * py
                rx, ry = x + wx - gx, y + wy - gy
                length = math.hypot(rx, ry)
                force = k * (length - math.hypot(px - gx, py - gy))
                ex, ey = rx / length, ry / length
                want += force * np.array([ex, ey, wx * ey - wy * ex])
            assert link.force() == pytest.approx(want.tolist(), rel=1e-12)
            link.commit()


def test_forces_equal_openfrescos_resolved_actuator_forces() -> None:
    """OpenFresco 2.8's ESThreeActuators2d::transfDaqForce (-nlGeom, left), evaluated with
    La 1000/900/800, L 500/400 at the strokes of (50, −20, 0.3) and forces (10, 20, 30)."""
    setup = make_setup(parse_setup_table({
        "kind": "ThreeActuators2d", "La1": 1000.0, "La2": 900.0, "La3": 800.0, "L1": 500.0,
        "L2": 400.0, "nlGeom": True}), 3)
    inverse = make_setup(setup_table := parse_setup_table({
        "kind": "ThreeActuators2d", "La1": 1000.0, "La2": 900.0, "La3": 800.0, "L1": 500.0,
        "L2": 400.0, "nlGeom": True}), 3)
    assert str(setup_table) == "ThreeActuators2d"
    ctrl = setup.ctrl_disp((50.0, -20.0, 0.3))
    got = inverse.basic_force((10.0, 20.0, 30.0), ctrl)  # through Newton, not the command
    assert got == pytest.approx((12.918492485389818, 48.33830782941259, 4311.478135525502),
                                rel=1e-13)


def test_scale_factors_convert_units_end_to_end(
        run_bridge: Callable[[str], BridgeThread]) -> None:
    """An OpenSees model in m and N on a lab in mm and kN, as OpenFresco users write it:
    ``-trialDispFact 1000 -outDispFact 0.001 -outForceFact 1000``."""
    config = textwrap.dedent("""
        [record]
        enabled = false
        [[sites]]
        name = "spring"
        port = 0
        [sites.setup]
        kind = "OneActuator"
        trialDispFact = 1000.0
        outDispFact = 0.001
        outForceFact = 1000.0
        [sites.controller]
        kind = "sim"
        model = "elastic"
        params = { k = 5.0 }
        """)
    bridge = run_bridge(config)
    with GenericClientLink("127.0.0.1", bridge.ports["spring"], 1, timeout=20.0) as link:
        link.set_trial((0.002,), time=0.01)  # 2 mm
        assert link.force() == pytest.approx((10_000.0,))  # 10 kN in N
        k = link.matrix(Action.GET_TANGENT_STIFF)[0][0]
        assert k == pytest.approx(5.0e6)  # 5 kN/mm in N/m
        link.commit()
