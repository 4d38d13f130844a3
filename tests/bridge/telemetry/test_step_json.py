"""The hand-written step payload is byte for byte json.dumps of the documented object."""

from __future__ import annotations

import json
import math
from typing import Any

from hypothesis import given
from hypothesis import strategies as st

from fresco_bridge.indicators import MonitorSample
from fresco_bridge.telemetry.schema import SCHEMA_VERSION, CorrectionSample, StepSample

floats = st.floats(allow_nan=True, allow_infinity=True, width=64)
vectors = st.lists(floats, min_size=0, max_size=4).map(tuple)
optional = st.none() | floats
monitors = st.none() | st.builds(
    MonitorSample, floats, floats, optional, optional, optional,
    st.none() | st.text(max_size=40))
corrections = st.none() | st.builds(
    CorrectionSample, st.integers(0, 100), floats,
    st.sampled_from(["converged", "not-converged", "beyond-max-correction", "non-finite"]))


def _plain(v: float | None) -> float | str | None:
    return None if v is None else (v if math.isfinite(v) else str(v))


def reference(s: StepSample) -> bytes:
    m = s.monitor
    body: dict[str, Any] = {
        "v": SCHEMA_VERSION, "site": s.site, "session": s.session, "step": s.step,
        "time": _plain(s.time), "state": s.state, "trial": [_plain(v) for v in s.trial],
        "ctrl": [_plain(v) for v in s.ctrl],
        "daq": {"disp": [_plain(v) for v in s.daq_disp],
                "force": [_plain(v) for v in s.daq_force]},
        "predicted_force": _plain(s.predicted_force),
        "monitor": None if m is None else {
            "tracking_error": _plain(m.tracking_error), "ti": _plain(m.ti),
            "nrms": _plain(m.nrms), "fei_amplitude": _plain(m.fei_amplitude),
            "fei_delay": _plain(m.fei_delay), "warning": m.warning},
        "correction": None if (c := s.correction) is None else {
            "corrections": c.corrections, "residual": _plain(c.residual),
            "outcome": c.outcome},
    }
    return json.dumps(body, separators=(",", ":"), allow_nan=False).encode()


@given(site=st.from_regex(r"[A-Za-z0-9][A-Za-z0-9_.-]{0,20}", fullmatch=True),
       session=st.integers(0, 10**6), step=st.integers(0, 10**9), time=floats,
       state=st.sampled_from(["RUNNING", "HOLD", "PAUSED", "IDLE", "FAULT"]),
       trial=vectors, ctrl=vectors, disp=vectors, force=vectors, predicted=optional,
       monitor=monitors, correction=corrections)
def test_full_step_payload_equals_json_dumps(
    site: str, session: int, step: int, time: float, state: str,
    trial: tuple[float, ...], ctrl: tuple[float, ...], disp: tuple[float, ...],
    force: tuple[float, ...], predicted: float | None, monitor: MonitorSample | None,
    correction: CorrectionSample | None,
) -> None:
    s = StepSample(site, session, step, time, trial, ctrl, disp, force, state, predicted, monitor,
                   correction)
    assert s.to_json() == reference(s)
    json.loads(s.to_json())  # strict JSON
