"""The record's line format: a lean encoder (format 5) and one decoder for every format.

Format 1 (the oldest; still read) wrote every field on every line: ``seq``, ``t``, ``kind``,
``site``, ``session`` and the values, 8 lines per committed 1-DOF step, most of it repeated
(BENCHMARKS.md, "Record size and durability"). Format 2 writes each line as a JSON object too,
but only what changed:

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

Format 3 is format 2 plus the **step line**: a committed step's
trial and daq lines, its commit line and the monitor line of the step before, folded into one
line written at the commit (one line per step instead of eight; the Python formatting of the
lines was the largest cost left on the step path)::

    {"t":…,"kind":"step","step":S,"time":T,"mon":M,"it":[I1,I2,…]}

- ``step``/``time`` are the commit's; every trial of the step had step ``S − 1`` and time ``T``
  (the step line is only written then: otherwise the step's lines are format-2 lines);
- ``it``: one entry per trial, each followed by its measurement (the Newton iterations):
  ``0`` when trial, ctrl, daq disp and force all equal the previous iteration's (for the first,
  the previous trial and daq lines of the site and session), else ``[trial, disp, force]`` or
  ``[trial, disp, force, ctrl]`` (ctrl absent: equal to the trial), where a ``0`` in place of a
  vector means "unchanged from the previous iteration";
- ``mon`` (optional): the monitor line of step ``S − 1`` (it is computed after that commit and
  goes to the file with the next one, as in format 2): ``[err, ti, nrms, fei_amp, fei_delay]``,
  ``[err, ti, nrms]`` when the FEI pair is that of the previous monitor line (it is held
  between its updates), or ``0`` for all the values of the previous monitor line;
- ``site``/``session`` as on every line; ``t`` is when the line was written (the commit), and
  the lines it stands for read back with that ``t``.

Format 4 is format 3 plus the **monitors line**,
the monitor lines of consecutive committed steps of a site in one line, written when the online
monitors run for the record alone (no MQTT, no metrics: the telemetry taps then batch them,
``telemetry/taps.py``)::

    {"t":…,"kind":"monitors","step":S,"v":[V1,V2,…]}

- ``V1`` is the monitor line of committed step ``S``, ``V2`` of ``S + 1``…, each as ``mon`` on a
  step line: ``[err, ti, nrms, fei_amp, fei_delay]``, ``[err, ti, nrms]`` when the FEI pair is
  that of the previous monitor line, or ``0`` for all its values (the first of a session carries
  all five);
- step lines then carry no ``mon``; ``site``/``session``/``t`` as on every line.

Format 5 is format 4 plus the **update line**
of an updatable site (``twins/``), written right after each of its committed steps::

    {"t":…,"kind":"update","step":S,"through":K,"secs":U,"err":E}

- ``step``: the twin's committed step; ``through``: the source step its answer was learned
  through (the snapshot it came from; 0: none learned); ``secs``: the wall time the worker
  spent learning source steps for this twin step (0 when it learned none); ``err`` (only when
  the updater predicts the source, ``Updater.last_one_step_error``): |F − F̂| of the last
  source step learned for this twin step, F̂ predicted from the source's measured past before
  learning it (kN);
- ``upto`` (only while the twin's learner is catching up, ``twins/catchup.py``):
  ``[session, step]``, the source step the answer was learned through when that is short of
  what the twin's causality asked for (a resume replays exactly that);
- complete (never inherited); ``site``/``session``/``t`` as on every line; a step whose last
  trial the learner did not answer (the site HOLDs) has none.

Format 6 (``FORMAT_VERSION``, what this version writes) is format 5 plus the **correction
line** of a site with ``[sites.correction]`` (``sites/correcting.py``), written when a trial's
displacement correction ends (before the step line that holds its commands)::

    {"t":…,"kind":"correction","step":S,"target":[…],"outcome":O,"n":K,"residual":R,
     "it":[[command, measured],…]}

- ``step``: the step the trial belongs to (its commit will be step ``S``; its trial and daq
  lines say ``S − 1``, as every trial's); ``target``: the integrator's command (ctrl, mm);
- ``it``: every command the controller reached for it, the target's own first (a trial
  repeated at the same target: the command already held), each with the
  displacement the correction compared (the daq or the external channel, mm); each command is
  also a trial line (ctrl) followed by its daq line, so a step line folds them as iterations;
- ``outcome``: ``converged``, ``not-converged``, ``beyond-max-correction``, ``non-finite`` or
  ``refused``; ``n``: corrected commands after the target; ``residual``: the largest
  |target − measured| of the corrected control points at the end (mm);
- complete (never inherited); ``site``/``session``/``t`` as on every line. Older formats have
  none, and a reader of them sees no correction.

``expand`` turns lines of every format (or a file mixing them: an older run resumed by this
version) back into complete format-1 dicts, in file order (each site's lines in the order it
recorded them), so every reader (export, report, ``runs``, HDF5, recovery) sees exactly what
it saw before.
"""

from __future__ import annotations

import json
import math
from collections.abc import Iterable, Iterator, Sequence
from typing import Any

FORMAT_VERSION = 6
INHERITED_KINDS = frozenset(("trial", "daq", "commit", "monitor"))
"""Line kinds whose absent value fields repeat the previous line's (same site, session)."""
TRIAL, DAQ, MONITOR = 0, 1, 2
"""Kinds of a site's pending items (``LineEncoder.fold``, ``LineEncoder.lines``): ``(TRIAL,
session, step, time, trial, ctrl)``, ``(DAQ, session, step, disp, force)``, ``(MONITOR, session,
step, (err, ti, nrms, fei_amp, fei_delay))``."""
Item = tuple[Any, ...]


class RecordFormatError(ValueError):
    """A record line is not what the writer produces (names file, line and reason)."""


def num(v: float) -> str:
    """The shortest exact JSON form of a float; non-finite values as strings."""
    return repr(float(v)) if math.isfinite(v) else f'"{v}"'


def nums(values: Sequence[float]) -> str:
    """JSON array of floats in their shortest exact form (non-finite as strings)."""
    body = repr(values[0]) if len(values) == 1 else ",".join(map(repr, values))
    if "n" in body:  # nan / inf / -inf (no finite repr contains an "n")
        body = ",".join(num(v) for v in values)
    return "[" + body + "]"


def opt(v: float | None) -> str:
    return "null" if v is None else num(v)


class LineEncoder:
    """Format-5 lines; remembers what the file already says (not thread-safe).

    Every line it returns must reach the file in order: the next lines are written relative
    to it.
    """

    __slots__ = ("_commit", "_ctx_session", "_ctx_site", "_daq", "_monitor", "_nums",
                 "_nums_of", "_trial")

    def __init__(self) -> None:
        self._ctx_site: str | None = None  # site and session of the line before
        self._ctx_session = 0
        self._nums_of: tuple[float, ...] | None = None
        self._nums = ""
        """The last vector formatted and its text: an in-process specimen measures the very
        command tuple it was sent, so its daq disp is formatted once, not twice (formatting
        numbers is a large share of the record's cost at 64 DOFs: BENCHMARKS.md, "Multi-DOF
        elements")."""
        # per site: (session, step, time, trial, ctrl); (session, step, disp, force);
        # (session, step, time); (session, step, (err, ti, nrms, fei_amp, fei_delay))
        self._trial: dict[str, tuple[int, int, float, tuple[float, ...], tuple[float, ...]]] = {}
        self._daq: dict[str, tuple[int, int, tuple[float, ...], tuple[float, ...]]] = {}
        self._commit: dict[str, tuple[int, int, float]] = {}
        self._monitor: dict[str, tuple[int, int, tuple[Any, ...]]] = {}

    def line(self, t: float, kind: str, site: str, session: int, body: str) -> str:
        if self._ctx_site == site and self._ctx_session == session:
            return f'{{"t":{t:.6f},"kind":"{kind}"{body}}}\n'
        self._ctx_site, self._ctx_session = site, session
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
        self._trial[site] = (session, step, time_, trial, ctrl)
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
        values = (err, ti, nrms, fei_amp, fei_delay)
        last = self._monitor.get(site)
        self._monitor[site] = (session, step, values)
        if last is None or last[0] != session:
            return (f',"step":{step},"err":{num(err)},"ti":{num(ti)},"nrms":{opt(nrms)},'
                    f'"fei_amp":{opt(fei_amp)},"fei_delay":{opt(fei_delay)}')
        body = f',"step":{step}' if step != last[1] else ""
        for name, v, was in zip(_MONITOR_FLOATS, values, last[2], strict=True):
            if v != was:
                body += f',"{name}":{opt(v)}'
        return body

    @staticmethod
    def update(step: int, through: int, seconds: float, error: float | None,
               upto: tuple[int, int] | None = None) -> str:
        """The body of an update line (format 5)."""
        body = f',"step":{step},"through":{through},"secs":{num(seconds)}'
        if error is not None:
            body += f',"err":{num(error)}'
        return body if upto is None else f'{body},"upto":[{upto[0]},{upto[1]}]'

    @staticmethod
    def correction(step: int, target: Sequence[float], outcome: str, residual: float,
                   iterations: Sequence[tuple[Sequence[float], Sequence[float]]]) -> str:
        """The body of a correction line (format 6)."""
        its = ",".join(f"[{nums(c)},{nums(m)}]" for c, m in iterations)
        return (f',"step":{step},"target":{nums(target)},"outcome":"{outcome}",'
                f'"n":{max(0, len(iterations) - 1)},"residual":{num(residual)},"it":[{its}]')

    @staticmethod
    def event(kind: str, reason: str, extra: dict[str, object]) -> str:
        return "," + json.dumps({"event": kind, "reason": reason, **extra},
                                separators=(",", ":"))[1:-1]

    def lines(self, t: float, site: str, items: list[Item]) -> list[str]:
        """A site's pending items as format-2 lines (what ``fold`` cannot fold), in order."""
        out = []
        for item in items:
            kind, session = item[0], item[1]
            if kind == TRIAL:
                out.append(self.line(t, "trial", site, session, self.trial(site, *item[1:])))
            elif kind == DAQ:
                out.append(self.line(t, "daq", site, session, self.daq(site, *item[1:])))
            else:
                out.append(self.line(t, "monitor", site, session,
                                     self.monitor(site, session, item[2], *item[3])))
        return out

    def fold(self, t: float, site: str, session: int, step: int, time_: float,
             items: list[Item]) -> str | None:
        """The step line of committed ``step``: ``items`` (the site's lines since its last
        commit) and the commit in one line; None when they do not have the step line's shape
        (then they are written as format-2 lines).

        The hot path of the record (once a committed step): each item is unpacked once, a
        vector is formatted only when it differs from the previous iteration's (and once for
        the trial and the measurement of an in-process specimen: the same tuple), and the
        line is one f-string.
        """
        last_t = self._trial.get(site)
        last_d = self._daq.get(site)
        if last_t is None or last_d is None or last_t[0] != session or last_d[0] != session:
            return None
        prev = step - 1
        n = len(items)
        i = 0
        mon = ""
        monitor = items[0]
        if monitor[0] == MONITOR:
            if monitor[1] != session or monitor[2] != prev:
                return None
            mon = self._fold_monitor(site, session, monitor[3])
            i = 1
        if n - i < 2 or (n - i) & 1:
            return None
        _, _, _, pt, pc = last_t
        _, _, pd, pf = last_d
        known, text = self._nums_of, self._nums  # the last vector formatted and its text
        its = ""
        try:
            for j in range(i, n, 2):
                kind, s, st, tm, trial, ctrl = items[j]
                dkind, ds, dst, disp, force = items[j + 1]
                if (kind != TRIAL or dkind != DAQ or st != prev or dst != prev or tm != time_
                        or s != session or ds != session):
                    return None
                # each vector "0" (as the previous iteration's) or its text, a 1-DOF vector's
                # made in one f-string (``nums`` for the rest: non-finite, other lengths), and
                # the iteration one f-string
                if trial == pt:
                    if ctrl == pc and disp == pd and force == pf:
                        its += ",0"
                        continue
                    a = "0"
                elif trial is known:
                    a = text
                else:
                    a = f"[{trial[0]!r}]" if len(trial) == 1 else "[]"
                    if "n" in a or len(a) == 2:
                        a = nums(trial)
                    known, text = trial, a
                if disp == pd:
                    b = "0"
                elif disp is known:
                    b = text
                else:
                    b = f"[{disp[0]!r}]" if len(disp) == 1 else "[]"
                    if "n" in b or len(b) == 2:
                        b = nums(disp)
                    known, text = disp, b
                if force == pf:
                    c = "0"
                elif force is known:
                    c = text
                else:
                    c = f"[{force[0]!r}]" if len(force) == 1 else "[]"
                    if "n" in c or len(c) == 2:
                        c = nums(force)
                    known, text = force, c
                if ctrl == trial:
                    its += f",[{a},{b},{c}]"
                else:
                    if ctrl is not known:
                        known, text = ctrl, nums(ctrl)
                    its += f",[{a},{b},{c},{text}]"
                pt, pc, pd, pf = trial, ctrl, disp, force
        except ValueError:  # an item of another kind (another length) where a pair should be
            return None
        self._nums_of, self._nums = known, text
        self._trial[site] = (session, prev, time_, pt, pc)
        self._daq[site] = (session, prev, pd, pf)
        self._commit[site] = (session, step, time_)
        if i:
            self._monitor[site] = (session, prev, monitor[3])
        tt = repr(time_) if time_.__class__ is float and time_ - time_ == 0.0 else num(time_)
        if self._ctx_site == site and self._ctx_session == session:
            return (f'{{"t":{t:.6f},"kind":"step","step":{step},"time":{tt}{mon},'
                    f'"it":[{its[1:]}]}}\n')
        self._ctx_site, self._ctx_session = site, session
        return (f'{{"t":{t:.6f},"kind":"step","site":"{site}","session":{session},'
                f'"step":{step},"time":{tt}{mon},"it":[{its[1:]}]}}\n')

    def monitors(self, t: float, site: str, session: int, step: int,
                 samples: list[tuple[Any, ...]]) -> str:
        """The monitors line of ``samples``, the monitor values (``err, ti, nrms, fei_amp,
        fei_delay``) after committed steps ``step``, ``step + 1``… of ``site`` (format 4)."""
        last_m = self._monitor.get(site)
        was = last_m[2] if last_m is not None and last_m[0] == session else None
        parts = []
        for values in samples:
            if was is not None and was == values:
                parts.append("0")
            elif was is not None and was[3:] == values[3:]:  # the FEI is held between updates
                parts.append(nums(values[:3]) if values[2] is not None else
                             f"[{num(values[0])},{num(values[1])},null]")
            else:
                err, ti, nrms, fei_amp, fei_delay = values
                parts.append(f"[{num(err)},{num(ti)},{opt(nrms)},{opt(fei_amp)},"
                             f"{opt(fei_delay)}]")
            was = values
        if was is not None:
            self._monitor[site] = (session, step + len(samples) - 1, was)
        return self.line(t, "monitors", site, session,
                         f',"step":{step},"v":[{",".join(parts)}]')

    def _fold_monitor(self, site: str, session: int, values: tuple[Any, ...]) -> str:
        """The ``mon`` field of a step line: the monitor sample after the step before."""
        last_m = self._monitor.get(site)
        was = last_m[2] if last_m is not None and last_m[0] == session else None
        if was is not None and was == values:
            return ',"mon":0'
        err, ti, nrms, fei_amp, fei_delay = values
        if was is not None and was[3:] == values[3:]:  # the FEI is held between its updates
            return f',"mon":[{num(err)},{num(ti)},{opt(nrms)}]'
        return f',"mon":[{num(err)},{num(ti)},{opt(nrms)},{opt(fei_amp)},{opt(fei_delay)}]'


_MONITOR_FLOATS = ("err", "ti", "nrms", "fei_amp", "fei_delay")


def expand(objs: Iterable[dict[str, Any]]) -> Iterator[dict[str, Any]]:
    """Complete format-1 dicts (with ``seq``, ``site``, ``session`` and every value) from the
    decoded lines of a record of any format or a mix, in order (a kind it does not know, as
``update``, passes through complete). RecordFormatError: a step
    line without the lines it is relative to (not a record this writer wrote)."""
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
        if "site" in obj:
            site = str(obj["site"])
        if "session" in obj:
            session = int(obj["session"])
        kind = obj.get("kind")
        if kind == "step":
            for line in _unfold(obj, site, session, seq, last):
                seq = line["seq"]
                yield line
            continue
        if kind == "monitors":
            for line in _unfold_monitors(obj, site, session, seq, last):
                seq = line["seq"]
                yield line
            continue
        seq += 1
        full = {"seq": seq, "t": obj.get("t", 0.0), "kind": kind, "site": site,
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


def _unfold(obj: dict[str, Any], site: str, session: int, seq: int,
            last: dict[tuple[str, str], dict[str, Any]]) -> Iterator[dict[str, Any]]:
    """The format-1 lines of one step line (format 3): [monitor], trial, daq, …, commit."""

    def before(kind: str) -> dict[str, Any]:
        prev = last.get((site, kind))
        if prev is None or prev.get("session") != session:
            raise RecordFormatError(
                f"step line after seq {seq} ({site!r} session {session}): no {kind} line of "
                "that site and session before it, which the step line is written relative to")
        return prev

    t, step, time_ = obj.get("t", 0.0), int(obj["step"]), obj["time"]
    head = {"t": t, "site": site, "session": session}
    mon = obj.get("mon")
    if mon is not None:
        values = ([before("monitor")[k] for k in _MONITOR_FLOATS] if mon == 0 else mon)
        if len(values) == 3:  # fei_amp and fei_delay as on the previous monitor line
            held = before("monitor")
            values = [*values, held["fei_amp"], held["fei_delay"]]
        seq += 1
        m = {"seq": seq, "kind": "monitor", **head, "step": step - 1,
             **dict(zip(_MONITOR_FLOATS, values, strict=True))}
        last[(site, "monitor")] = m
        yield m
    its = obj["it"]
    if not its:
        raise RecordFormatError(f"step line after seq {seq}: no iteration in 'it'")
    tr, dq = before("trial"), before("daq")
    trial, ctrl, disp, force = tr["trial"], tr["ctrl"], dq["disp"], dq["force"]
    for it in its:
        if it != 0:
            trial = trial if it[0] == 0 else it[0]
            disp = disp if it[1] == 0 else it[1]
            force = force if it[2] == 0 else it[2]
            ctrl = it[3] if len(it) > 3 else trial
        tr = {"seq": seq + 1, "kind": "trial", **head, "step": step - 1, "time": time_,
              "trial": trial, "ctrl": ctrl}
        dq = {"seq": seq + 2, "kind": "daq", **head, "step": step - 1, "disp": disp,
              "force": force}
        seq += 2
        yield tr
        yield dq
    last[(site, "trial")], last[(site, "daq")] = tr, dq
    commit = {"seq": seq + 1, "kind": "commit", **head, "step": step, "time": time_}
    last[(site, "commit")] = commit
    yield commit


def _unfold_monitors(obj: dict[str, Any], site: str, session: int, seq: int,
                     last: dict[tuple[str, str], dict[str, Any]]) -> Iterator[dict[str, Any]]:
    """The format-1 monitor lines of one monitors line (format 4), steps ``step``, ``step + 1``…"""
    t, step = obj.get("t", 0.0), int(obj["step"])
    prev = last.get((site, "monitor"))
    if prev is not None and prev.get("session") != session:
        prev = None
    for n, entry in enumerate(obj["v"]):
        if entry == 0 or len(entry) == 3:
            if prev is None:
                raise RecordFormatError(
                    f"monitors line after seq {seq} ({site!r} session {session}): an entry "
                    "relative to a monitor line of that site and session, and none before it")
            values = ([prev[k] for k in _MONITOR_FLOATS] if entry == 0
                      else [*entry, prev["fei_amp"], prev["fei_delay"]])
        else:
            values = entry
        seq += 1
        prev = {"seq": seq, "t": t, "kind": "monitor", "site": site, "session": session,
                "step": step + n, **dict(zip(_MONITOR_FLOATS, values, strict=True))}
        yield prev
    if prev is not None:
        last[(site, "monitor")] = prev
