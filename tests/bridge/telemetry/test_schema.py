"""Telemetry payloads: documented layout, strict JSON, compact form, validation."""

from __future__ import annotations

import json
import math

import pytest

from fresco_bridge.indicators import MonitorSample
from fresco_bridge.telemetry.schema import (
    SCHEMA_VERSION,
    CorrectionSample,
    SiteEvent,
    SiteStatus,
    StepSample,
    TelemetrySchemaError,
    check_site_name,
)


def make_sample(**changes: object) -> StepSample:
    fields: dict[str, object] = {
        "site": "left-column", "session": 3, "step": 41, "time": 0.41,
        "trial": (1.25, -0.5), "ctrl": (1.25, -0.5), "daq_disp": (1.2491, -0.4998),
        "daq_force": (53.2, -7.75), "state": "RUNNING", "predicted_force": 53.0,
        "monitor": MonitorSample(tracking_error=-0.0009, ti=-0.12, nrms=0.013,
                                 fei_amplitude=0.98, fei_delay=0.004, warning=None),
        "correction": CorrectionSample(corrections=2, residual=0.004, outcome="converged"),
    }
    fields.update(changes)
    return StepSample(**fields)  # type: ignore[arg-type]


def test_full_step_payload_has_the_documented_keys_and_values() -> None:
    body = json.loads(make_sample().to_json())
    assert body == {
        "v": SCHEMA_VERSION, "site": "left-column", "session": 3, "step": 41, "time": 0.41,
        "state": "RUNNING", "trial": [1.25, -0.5], "ctrl": [1.25, -0.5],
        "daq": {"disp": [1.2491, -0.4998], "force": [53.2, -7.75]},
        "predicted_force": 53.0,
        "monitor": {"tracking_error": -0.0009, "ti": -0.12, "nrms": 0.013,
                    "fei_amplitude": 0.98, "fei_delay": 0.004, "warning": None},
        "correction": {"corrections": 2, "residual": 0.004, "outcome": "converged"},
    }
    assert json.loads(make_sample(correction=None).to_json())["correction"] is None


def test_compact_step_payload_is_positional_and_smaller() -> None:
    sample = make_sample()
    compact = sample.to_json(compact=True)
    assert json.loads(compact) == [
        SCHEMA_VERSION, 3, 41, 0.41, "RUNNING", [1.25, -0.5], [1.25, -0.5],
        [1.2491, -0.4998], [53.2, -7.75], 53.0, [-0.0009, -0.12, 0.013, 0.98, 0.004, None],
        [2, 0.004, "converged"],
    ]
    assert json.loads(make_sample(correction=None).to_json(compact=True))[11] is None
    assert len(compact) < len(sample.to_json()) / 2
    assert b" " not in compact


def test_non_finite_values_become_strings_so_payloads_stay_strict_json() -> None:
    sample = make_sample(trial=(math.nan, math.inf), predicted_force=-math.inf, monitor=None)
    def refuse_bare_constant(name: str) -> object:
        raise AssertionError(f"bare {name} in a payload")

    for compact in (False, True):
        body = json.loads(sample.to_json(compact), parse_constant=refuse_bare_constant)
        trial = body["trial"] if not compact else body[5]
        assert trial == ["nan", "inf"]


def test_status_and_event_payloads() -> None:
    status = SiteStatus(site="s1", state="HOLD", session=2, step=9, time=0.09,
                        reason="controller timeout", holds=1, wall_time=1700000000.0)
    assert json.loads(status.to_json()) == {
        "v": SCHEMA_VERSION, "site": "s1", "state": "HOLD", "session": 2, "step": 9,
        "time": 0.09, "reason": "controller timeout", "holds": 1, "wall_time": 1700000000.0}
    idle = SiteStatus(site="s1", state="IDLE", wall_time=1.0)
    assert "reason" not in json.loads(idle.to_json(compact=True))

    event = SiteEvent(site="s1", kind="limit", reason="ctrl beyond upper limit", step=9,
                      extra={"signal": "ctrl_disp", "value": 1.5, "limits": [-1.0, math.inf]},
                      wall_time=2.0)
    body = json.loads(event.to_json())
    assert body["extra"] == {"signal": "ctrl_disp", "value": 1.5, "limits": [-1.0, "inf"]}
    assert (body["kind"], body["step"], body["session"]) == ("limit", 9, 0)


@pytest.mark.parametrize("site", ["", "a/b", "s+", "#", "$SYS", "_bridge", "x" * 65, "é"])
def test_site_names_that_would_break_the_topic_layout_are_refused(site: str) -> None:
    with pytest.raises(TelemetrySchemaError, match="cannot be an MQTT topic level"):
        check_site_name(site)
    with pytest.raises(TelemetrySchemaError):
        SiteStatus(site=site, state="IDLE")


def test_event_extra_must_be_json_scalars() -> None:
    with pytest.raises(TelemetrySchemaError, match="extra field 'obj'"):
        SiteEvent(site="s1", kind="fault", reason="x", extra={"obj": object()})
    with pytest.raises(TelemetrySchemaError, match="short slug"):
        SiteEvent(site="s1", kind="has space", reason="x")
