"""The record's line format: a lean encoder (format 2) and one decoder for every format.

Format 1 (until issue 8) wrote every field on every line: ``seq``, ``t``, ``kind``, ``site``,
``session`` and the values, 8 lines and ~1160 bytes per committed 1-DOF step, most of it
repeated. Format 2 writes each line as a JSON object too, but only what changed:

- no ``seq``: a line's sequence number is its position (the previous line's + 1);
- ``site`` and ``session`` only when they differ from the line before;
- on ``trial``, ``daq``, ``commit`` and ``monitor`` lines, a value field that is absent has
  the value of the previous line of the same kind, site and session (the first such line of a
  session carries every field). So a Newton iteration that repeats the last trial is
  ``{"t":…,"kind":"trial"}``: the repeat marker;
- ``ctrl`` absent on a ``trial`` line means ctrl equals the trial (no transformation, no
  limit changed it); it is never inherited;
- ``event`` lines are complete (apart from site/session) and never inherited from;
- numbers in the shortest form that reads back to the same double (``repr``); non-finite
  values as the strings ``"nan"``/``"inf"``/``"-inf"``, as in format 1.

``expand`` turns lines of either format (or a file mixing them: a format-1 run resumed by
this version) back into complete format-1 dicts, so every reader (export, report, ``runs``,
HDF5, recovery) sees exactly what it saw before.
"""

from __future__ import annotations

import json
import math
from collections.abc import Iterable, Iterator
from typing import Any

FORMAT_VERSION = 2
INHERITED_KINDS = frozenset(("trial", "daq", "commit", "monitor"))
"""Line kinds whose absent value fields repeat the previous line's (same site, session)."""


def num(v: float) -> str:
    """The shortest exact JSON form of a float; non-finite values as strings."""
    return repr(float(v)) if math.isfinite(v) else f'"{v}"'


def nums(values: Iterable[float]) -> str:
    """JSON array of floats in their shortest exact form (non-finite as strings)."""
    body = ",".join(map(repr, values))
    if "n" in body:  # nan / inf / -inf (no finite repr contains an "n")
        body = ",".join(num(v) for v in values)
    return "[" + body + "]"


def opt(v: float | None) -> str:
    return "null" if v is None else num(v)


class LineEncoder:
    """Format-2 lines; remembers what the file already says (not thread-safe).

    Every line it returns must reach the file in order: the next lines are written relative
    to it.
    """

    __slots__ = ("_commit", "_ctx", "_daq", "_monitor", "_nums", "_nums_of", "_trial")

    def __init__(self) -> None:
        self._ctx: tuple[str, int] | None = None
        self._nums_of: tuple[float, ...] | None = None
        self._nums = ""
        """The last vector formatted and its text: an in-process specimen measures the very
        command tuple it was sent, so its daq disp is formatted once, not twice (~0.5 µs a
        number: 64 DOFs)."""
        self._trial: dict[str, tuple[int, int, float, tuple[float, ...]]] = {}
        self._daq: dict[str, tuple[int, int, tuple[float, ...], tuple[float, ...]]] = {}
        self._commit: dict[str, tuple[int, int, float]] = {}
        self._monitor: dict[str, tuple[Any, ...]] = {}

    def line(self, t: float, kind: str, site: str, session: int, body: str) -> str:
        if self._ctx == (site, session):
            return f'{{"t":{t:.6f},"kind":"{kind}"{body}}}\n'
        self._ctx = (site, session)
        return f'{{"t":{t:.6f},"kind":"{kind}","site":"{site}","session":{session}{body}}}\n'

    def _vector(self, values: tuple[float, ...]) -> str:
        if values is self._nums_of:
            return self._nums
        text = nums(values)
        self._nums_of, self._nums = values, text
        return text

    def trial(self, site: str, session: int, step: int, time_: float,
              trial: tuple[float, ...], ctrl: tuple[float, ...]) -> str:
        last = self._trial.get(site)
        if last is None or last[0] != session:
            body = f',"step":{step},"time":{num(time_)},"trial":{self._vector(trial)}'
        else:
            body = ""
            if step != last[1]:
                body += f',"step":{step}'
            if time_ != last[2]:
                body += f',"time":{num(time_)}'
            if trial != last[3]:
                body += f',"trial":{self._vector(trial)}'
        if ctrl != trial:
            body += f',"ctrl":{self._vector(ctrl)}'
        self._trial[site] = (session, step, time_, trial)
        return body

    def daq(self, site: str, session: int, step: int, disp: tuple[float, ...],
            force: tuple[float, ...]) -> str:
        last = self._daq.get(site)
        if last is None or last[0] != session:
            body = f',"step":{step},"disp":{self._vector(disp)},"force":{self._vector(force)}'
        else:
            body = ""
            if step != last[1]:
                body += f',"step":{step}'
            if disp != last[2]:
                body += f',"disp":{self._vector(disp)}'
            if force != last[3]:
                body += f',"force":{self._vector(force)}'
        self._daq[site] = (session, step, disp, force)
        return body

    def commit(self, site: str, session: int, step: int, time_: float) -> str:
        last = self._commit.get(site)
        self._commit[site] = (session, step, time_)
        if last is None or last[0] != session:
            return f',"step":{step},"time":{num(time_)}'
        return ((f',"step":{step}' if step != last[1] else "")
                + (f',"time":{num(time_)}' if time_ != last[2] else ""))

    def monitor(self, site: str, session: int, step: int, err: float, ti: float,
                nrms: float | None, fei_amp: float | None, fei_delay: float | None) -> str:
        values = (step, err, ti, nrms, fei_amp, fei_delay)
        last = self._monitor.get(site)
        self._monitor[site] = (session, values)
        if last is None or last[0] != session:
            return (f',"step":{step},"err":{num(err)},"ti":{num(ti)},"nrms":{opt(nrms)},'
                    f'"fei_amp":{opt(fei_amp)},"fei_delay":{opt(fei_delay)}')
        old = last[1]
        body = f',"step":{step}' if step != old[0] else ""
        for name, v, was in zip(_MONITOR_FLOATS, values[1:], old[1:], strict=True):
            if v != was:
                body += f',"{name}":{opt(v)}'
        return body

    @staticmethod
    def event(kind: str, reason: str, extra: dict[str, object]) -> str:
        return "," + json.dumps({"event": kind, "reason": reason, **extra},
                                separators=(",", ":"))[1:-1]


_MONITOR_FLOATS = ("err", "ti", "nrms", "fei_amp", "fei_delay")


def expand(objs: Iterable[dict[str, Any]]) -> Iterator[dict[str, Any]]:
    """Complete format-1 dicts (with ``seq``, ``site``, ``session`` and every value) from the
    decoded lines of a record of format 1, 2 or both, in order."""
    seq, site, session = 0, "", 0
    last: dict[tuple[str, str], dict[str, Any]] = {}
    for obj in objs:
        if "seq" in obj:  # format 1: already complete
            seq = int(obj["seq"])
            site, session = str(obj.get("site", site)), int(obj.get("session", session))
            if obj.get("kind") in INHERITED_KINDS:
                last[(site, obj["kind"])] = obj
            yield obj
            continue
        seq += 1
        if "site" in obj:
            site = str(obj["site"])
        if "session" in obj:
            session = int(obj["session"])
        kind = obj.get("kind")
        full: dict[str, Any] = {"seq": seq, "t": obj.get("t", 0.0), "kind": kind, "site": site,
                                "session": session}
        if kind in INHERITED_KINDS:
            prev = last.get((site, kind))
            if prev is not None and prev.get("session") == session:
                for k, v in prev.items():
                    if k not in full and k != "ctrl":
                        full[k] = v
            for k, v in obj.items():
                if k not in ("t", "kind", "site", "session"):
                    full[k] = v
            if kind == "trial" and "ctrl" not in obj and "trial" in full:
                full["ctrl"] = full["trial"]
            last[(site, kind)] = full
        else:
            for k, v in obj.items():
                if k not in ("t", "kind", "site", "session"):
                    full[k] = v
        yield full
