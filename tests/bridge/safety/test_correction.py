"""The outer-loop correction's pure verdict and its ``[sites.correction]`` table."""

from __future__ import annotations

import asyncio
import math
import tracemalloc

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from pydantic import ValidationError

from fresco_bridge.controls.base import Daq, InlineController
from fresco_bridge.safety import ControlPointLimits, CorrectionConfig, Limiter, SiteState
from fresco_bridge.safety.correction import (
    CONVERGED,
    CorrectionSettings,
    Terminal,
    correct,
    needs_warning,
)
from fresco_bridge.sites.correction_loop import CorrectionLoop, LimitedPath

ONE = CorrectionSettings(tolerance=(0.01,), max_correction=(1.0,), max_iterations=4)


def test_within_tolerance_is_converged_and_allocates_nothing() -> None:
    target, command, measured = (2.0, -1.0), (2.0, -1.0), (1.995, -1.004)
    two = CorrectionSettings((0.01, 0.01), (1.0, 1.0))
    assert correct(two, target, command, measured, 0) is CONVERGED
    tracemalloc.start()
    try:
        before = tracemalloc.take_snapshot()
        for _ in range(200):
            correct(two, target, command, measured, 0)
        after = tracemalloc.take_snapshot()
    finally:
        tracemalloc.stop()
    grown = sum(s.size_diff for s in after.compare_to(before, "filename")
                if "correction.py" in str(s.traceback))
    assert grown == 0


def test_the_next_command_adds_gain_times_the_error() -> None:
    half = CorrectionSettings((0.01,), (1.0,), gain=0.5)
    assert correct(ONE, (2.0,), (2.0,), (1.8,), 0) == pytest.approx((2.2,))
    assert correct(half, (2.0,), (2.1,), (1.8,), 1) == pytest.approx((2.2,))


def test_a_correction_beyond_max_correction_is_not_proposed() -> None:
    verdict = correct(ONE, (2.0,), (2.9,), (1.7,), 1)  # next would be 3.2: 1.2 from the target
    assert isinstance(verdict, Terminal)
    assert verdict.outcome == "beyond-max-correction" and verdict.hold
    assert verdict.value == pytest.approx(1.2) and verdict.bound == 1.0
    assert "beyond max_correction 1 mm" in verdict.describe()


def test_non_convergence_follows_the_policy() -> None:
    held = correct(ONE, (2.0,), (2.1,), (1.9,), 4)
    assert isinstance(held, Terminal) and held.outcome == "not-converged" and held.hold
    accept = CorrectionSettings((0.01,), (1.0,), max_iterations=4, policy="accept-with-event")
    verdict = correct(accept, (2.0,), (2.1,), (1.9,), 4)
    assert isinstance(verdict, Terminal) and not verdict.hold and verdict.event
    assert "after the last allowed correction" in verdict.describe()


def test_a_non_finite_measurement_holds_whatever_the_policy() -> None:
    accept = CorrectionSettings((0.01,), (1.0,), policy="accept-with-event")
    verdict = correct(accept, (2.0,), (2.0,), (math.nan,), 0)
    assert isinstance(verdict, Terminal) and verdict.outcome == "non-finite" and verdict.hold


def test_a_point_not_corrected_keeps_its_target() -> None:
    only_first = CorrectionConfig(tolerance=0.01, max_correction=1.0,
                                  actuators=[1]).to_settings(2)
    assert correct(only_first, (1.0, 5.0), (1.0, 5.0), (0.9, 3.0), 0) == \
        pytest.approx((1.1, 5.0))
    assert correct(only_first, (1.0, 5.0), (1.0, 5.0), (1.0, math.nan), 0) is CONVERGED


def test_warning_beyond_half_the_iterations() -> None:
    assert not needs_warning(ONE, 2) and needs_warning(ONE, 3)


def test_the_table_per_control_point_and_its_errors() -> None:
    config = CorrectionConfig(tolerance=[0.01, 0.02], max_correction=2.0, gain=0.8,
                              policy="accept-with-event", max_iterations=6)
    s = config.to_settings(2)
    assert s.tolerance == (0.01, 0.02) and s.max_correction == (2.0, 2.0)
    assert (s.gain, s.policy, s.max_iterations) == (0.8, "accept-with-event", 6)
    with pytest.raises(ValueError, match=r"correction.tolerance: 2 value\(s\) for 3"):
        config.to_settings(3)
    with pytest.raises(ValidationError, match=r"tolerance: -0\.1 mm must be > 0"):
        CorrectionConfig(tolerance=-0.1, max_correction=1.0)
    with pytest.raises(ValidationError, match="policy"):
        CorrectionConfig(tolerance=0.1, max_correction=1.0, policy="ignore")
    with pytest.raises(ValidationError, match="gain"):
        CorrectionConfig(tolerance=0.1, max_correction=1.0, gain=1.5)
    with pytest.raises(ValueError, match="overshoots the target"):
        CorrectionSettings((0.1,), (1.0,), gain=1.5)
    with pytest.raises(ValidationError, match="nosuch"):
        CorrectionConfig.model_validate({"tolerance": 0.1, "max_correction": 1.0, "nosuch": 1})
    with pytest.raises(ValueError, match=r"correction.actuators \[3\]"):
        CorrectionConfig(tolerance=0.1, max_correction=1.0, actuators=[3]).to_settings(2)


class ArbitraryRig(InlineController):
    """Whatever the rig does: each move is measured as the next drawn value (a fake: pure logic)."""

    def __init__(self, readings: list[float]) -> None:
        self.readings = readings
        self.position = 0.0
        self.measured = 0.0

    def set_ctrl_now(self, disp: tuple[float, ...]) -> None:
        self.position = disp[0]
        self.measured = self.readings.pop(0) if self.readings else self.position

    def get_daq_now(self) -> Daq:
        return Daq((self.measured,), (0.0,))

    def commit_now(self) -> None:
        pass

    def reset(self) -> None:
        pass

    def tangent_stiffness_now(self) -> tuple[float, ...]:
        return (1.0,)

    def initial_stiffness_now(self) -> tuple[float, ...]:
        return (1.0,)


finite = st.floats(-60.0, 60.0, allow_nan=False)


@settings(max_examples=300, deadline=None)
@given(target=st.floats(-30.0, 30.0), readings=st.lists(
    st.one_of(finite, st.just(math.nan), st.just(math.inf)), max_size=12),
    policy=st.sampled_from(["reject", "clamp"]), gain=st.floats(0.1, 1.0),
    most=st.floats(0.0, 10.0), increment=st.floats(0.5, 20.0),
    velocity=st.floats(5.0, 500.0), substeps=st.sampled_from([0, 4]), accept=st.booleans())
def test_no_command_outside_the_limits_whatever_the_rig_does(
        target: float, readings: list[float], policy: str, gain: float, most: float,
        increment: float, velocity: float, substeps: int, accept: bool) -> None:
    limits = ControlPointLimits(0, disp_min=-25.0, disp_max=25.0, disp_increment=increment,
                                velocity=velocity, step_time=0.01, max_substeps=substeps,
                                policy=policy)  # type: ignore[arg-type]
    limiter = Limiter([limits], 1)
    rig = ArbitraryRig(list(readings))
    path = LimitedPath(rig, limiter)
    path.reference = (0.0,)
    correction = CorrectionSettings((0.05,), (most,), max_iterations=6, gain=gain,
                                    policy="accept-with-event" if accept else "hold")
    step = asyncio.run(CorrectionLoop(path, correction, rig).run((target,)))
    previous = 0.0
    for sent in path.sent:
        assert -25.0 <= sent[0] <= 25.0
        assert abs(sent[0] - previous) <= increment * (1 + 1e-12)
        assert abs(sent[0] - previous) / 0.01 <= velocity * (1 + 1e-9)
        previous = sent[0]
    assert step.corrections <= 6
    if step.verdict.hold:
        assert path.state == SiteState.HOLD
    if path.state == SiteState.HOLD:
        assert step.verdict.hold


@settings(max_examples=200, deadline=None)
@given(target=st.floats(-30.0, 30.0), readings=st.lists(finite, max_size=12),
       gain=st.floats(0.1, 1.0), most=st.floats(0.0, 10.0))
def test_without_limits_every_correction_stays_within_max_correction(
        target: float, readings: list[float], gain: float, most: float) -> None:
    rig = ArbitraryRig(list(readings))
    path = LimitedPath(rig, Limiter([], 1))
    correction = CorrectionSettings((0.05,), (most,), max_iterations=6, gain=gain)
    asyncio.run(CorrectionLoop(path, correction, rig).run((target,)))
    assert path.sent[0] == (target,)
    assert all(abs(c[0] - target) <= most for c in path.sent[1:])
