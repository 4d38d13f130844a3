"""Telemetry messages: frozen records and their JSON payloads (full or compact).

The payload layout is documented in ``README.md`` next to this file; ``SCHEMA_VERSION`` is
the first thing in every payload and changes whenever a field moves. Non-finite floats are
written as the strings ``"nan"``, ``"inf"``, ``"-inf"`` (as in the run record), so payloads
are always strict JSON.
"""

from __future__ import annotations

import json
import math
import re
import time as _time
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from types import MappingProxyType
from typing import Any

from fresco_bridge.indicators import MonitorSample
from fresco_bridge.site_output import CommittedStep

SCHEMA_VERSION = 1
_NAME = re.compile(r"[A-Za-z0-9][A-Za-z0-9_.-]{0,63}")
RESERVED_SITE_NAMES = frozenset({"_bridge"})

__all__ = [
    "RESERVED_SITE_NAMES",
    "SCHEMA_VERSION",
    "CorrectionSample",
    "SiteEvent",
    "SiteStatus",
    "StepSample",
    "TelemetrySchemaError",
    "check_site_name",
]


class TelemetrySchemaError(ValueError):
    """A telemetry record has a field that cannot be published (name, type, value)."""


def check_site_name(site: str) -> str:
    """Site names become MQTT topic levels: no '/', '+', '#', no leading '$' or '_'."""
    if not isinstance(site, str) or not _NAME.fullmatch(site):
        raise TelemetrySchemaError(
            f"site name {site!r} cannot be an MQTT topic level: use 1-64 characters from "
            "[A-Za-z0-9_.-], starting with a letter or digit"
        )
    return site


def _num(value: float | None) -> float | str | None:
    if value is None:
        return None
    v = float(value)
    return v if math.isfinite(v) else str(v)


def _nums(values: Sequence[float]) -> list[float | str]:
    return [v if math.isfinite(v) else str(v) for v in map(float, values)]


def _jnum(value: float | None) -> str:
    """``json.dumps(_num(value))`` without the encoder. A finite float's repr never contains
    an "n"; "nan", "inf" and "-inf" all do and become JSON strings."""
    if value is None:
        return "null"
    r = repr(float(value))
    return f'"{r}"' if "n" in r else r


def _jnums(values: Sequence[float]) -> str:
    body = ",".join(map(repr, map(float, values)))
    if "n" in body:  # a non-finite value somewhere: quote those
        body = ",".join(map(_jnum, values))
    return f"[{body}]"


_JSON_STRINGS: dict[str, str] = {}


def _jstr(value: str | None) -> str:
    """``json.dumps(value)``, cached: site names and states repeat every step."""
    if value is None:
        return "null"
    out = _JSON_STRINGS.get(value)
    if out is None:
        out = json.dumps(value)
        if len(_JSON_STRINGS) < 1024:
            _JSON_STRINGS[value] = out
    return out


def _dumps(obj: object) -> bytes:
    return json.dumps(obj, separators=(",", ":"), allow_nan=False).encode()


def _monitor_compact(m: MonitorSample) -> list[Any]:
    return [_num(m.tracking_error), _num(m.ti), _num(m.nrms), _num(m.fei_amplitude),
            _num(m.fei_delay), m.warning]


@dataclass(frozen=True, slots=True)
class CorrectionSample:
    """A committed trial's displacement correction (a site with ``[sites.correction]``)."""

    corrections: int
    """Corrected commands after the target's own (the correction's iterations)."""
    residual: float
    """The largest |target − measured| left after the last one (mm)."""
    outcome: str
    """``converged``, ``not-converged``, ``beyond-max-correction``, ``non-finite``, ``refused``."""


@dataclass(frozen=True, slots=True)
class StepSample(CommittedStep):
    """One committed or answered step of a site: what the integrator asked and what was measured.

    ``trial`` is in the element's basic DOFs, ``ctrl``/``daq_*`` in actuator space;
    ``predicted_force`` is the updated model's prediction on updatable sites.
    """

    predicted_force: float | None = None
    monitor: MonitorSample | None = None
    correction: CorrectionSample | None = None

    def to_json(self, compact: bool = False) -> bytes:
        """Full: a keyed object. Compact: a positional array (site/session are in the topic)."""
        if compact:
            return _dumps([
                SCHEMA_VERSION, self.session, self.step, _num(self.time), self.state,
                _nums(self.trial), _nums(self.ctrl), _nums(self.daq_disp), _nums(self.daq_force),
                _num(self.predicted_force),
                None if self.monitor is None else _monitor_compact(self.monitor),
                None if (c := self.correction) is None else
                [c.corrections, _num(c.residual), c.outcome],
            ])
        # Written out by hand: the same bytes as json.dumps of the keyed object (the tests
        # compare them) at a third of the cost, once per step on the bridge's loop.
        m = self.monitor
        monitor = "null" if m is None else (
            f'{{"tracking_error":{_jnum(m.tracking_error)},"ti":{_jnum(m.ti)},'
            f'"nrms":{_jnum(m.nrms)},"fei_amplitude":{_jnum(m.fei_amplitude)},'
            f'"fei_delay":{_jnum(m.fei_delay)},"warning":{_jstr(m.warning)}}}'
        )
        c = self.correction
        correction = "null" if c is None else (
            f'{{"corrections":{int(c.corrections)},"residual":{_jnum(c.residual)},'
            f'"outcome":{_jstr(c.outcome)}}}'
        )
        return (
            f'{{"v":{SCHEMA_VERSION},"site":{_jstr(self.site)},"session":{int(self.session)},'
            f'"step":{int(self.step)},"time":{_jnum(self.time)},"state":{_jstr(self.state)},'
            f'"trial":{_jnums(self.trial)},"ctrl":{_jnums(self.ctrl)},'
            f'"daq":{{"disp":{_jnums(self.daq_disp)},"force":{_jnums(self.daq_force)}}},'
            f'"predicted_force":{_jnum(self.predicted_force)},"monitor":{monitor},'
            f'"correction":{correction}}}'
        ).encode()


@dataclass(frozen=True, slots=True, kw_only=True)
class SiteStatus:
    """The retained "how is this site now" message, republished on every state change."""

    site: str
    state: str
    session: int = 0
    step: int = 0
    time: float | None = None
    reason: str = ""
    holds: int = 0
    wall_time: float = field(default_factory=_time.time)

    def __post_init__(self) -> None:
        check_site_name(self.site)

    def to_json(self, compact: bool = False) -> bytes:
        """Status is rare and retained: always the keyed object (``compact`` drops empties)."""
        body: dict[str, Any] = {
            "v": SCHEMA_VERSION, "site": self.site, "state": self.state,
            "session": self.session, "step": self.step, "time": _num(self.time),
            "reason": self.reason, "holds": self.holds, "wall_time": self.wall_time,
        }
        if compact:
            body = {k: v for k, v in body.items() if v not in (None, "")}
        return _dumps(body)


_Scalar = str | int | float | bool | None


def _plain(value: object) -> object:
    if isinstance(value, float):
        return _num(value)
    if isinstance(value, list | tuple):
        return [_plain(v) for v in value]
    return value


def _check_extra(extra: Mapping[str, object], where: str) -> Mapping[str, object]:
    for key, value in extra.items():
        items = value if isinstance(value, list | tuple) else (value,)
        if not isinstance(key, str) or not all(isinstance(v, _Scalar) for v in items):
            raise TelemetrySchemaError(
                f"{where}: extra field {key!r}={value!r} must be a JSON scalar or a list of them"
            )
    return MappingProxyType(dict(extra))


@dataclass(frozen=True, slots=True, kw_only=True)
class SiteEvent:
    """Something an operator must see: a limit hit, HOLD, a fault, a monitor warning.

    ``kind`` is a short slug (``hold``, ``limit``, ``fault``, ``monitor-warning``,
    ``session-open``...); ``extra`` carries kind-specific JSON scalars (signal, value, limit).
    """

    site: str
    kind: str
    reason: str
    session: int = 0
    step: int | None = None
    time: float | None = None
    extra: Mapping[str, object] = field(default_factory=dict)
    wall_time: float = field(default_factory=_time.time)

    def __post_init__(self) -> None:
        check_site_name(self.site)
        if not isinstance(self.kind, str) or not _NAME.fullmatch(self.kind):
            raise TelemetrySchemaError(f"event kind {self.kind!r} must be a short slug")
        object.__setattr__(self, "extra", _check_extra(self.extra, f"event {self.kind!r}"))

    def to_json(self, compact: bool = False) -> bytes:
        """The keyed object; ``extra`` values are plain JSON (non-finite floats as strings)."""
        extra = {k: _plain(v) for k, v in self.extra.items()}
        body: dict[str, Any] = {
            "v": SCHEMA_VERSION, "site": self.site, "kind": self.kind, "reason": self.reason,
            "session": self.session, "step": self.step, "time": _num(self.time),
            "extra": extra, "wall_time": self.wall_time,
        }
        if compact:
            body = {k: v for k, v in body.items() if v not in (None, "", {})}
        return _dumps(body)
