"""``CommittedStep`` sets its slots through their descriptors (cheaper than the generated
``__init__``): it must still behave as the frozen dataclass it was."""

from __future__ import annotations

import dataclasses

import pytest

from fresco_bridge.site_output import CommittedStep
from fresco_bridge.telemetry.schema import StepSample


def make(step: int = 5) -> CommittedStep:
    return CommittedStep("spec", 1, step, 0.05, (0.1,), (0.2,), (0.3,), (4.0,), "running")


def test_a_committed_step_is_a_frozen_value_with_every_field_set() -> None:
    step = make()
    assert [getattr(step, f.name) for f in dataclasses.fields(step)] == [
        "spec", 1, 5, 0.05, (0.1,), (0.2,), (0.3,), (4.0,), "running"]
    assert step == make() and hash(step) == hash(make()) and step != make(6)
    with pytest.raises(dataclasses.FrozenInstanceError):
        step.step = 6  # type: ignore[misc]
    assert dataclasses.replace(step, step=6) == make(6)
    match step:
        case CommittedStep("spec", 1, 5):
            pass
        case _:
            pytest.fail("positional match on the fields")


def test_the_telemetry_step_sample_extends_it_unchanged() -> None:
    sample = StepSample("spec", 1, 5, 0.05, (0.1,), (0.2,), (0.3,), (4.0,), "running", 1.5)
    assert isinstance(sample, CommittedStep) and sample.step == 5
    assert sample.predicted_force == 1.5 and sample.monitor is None
