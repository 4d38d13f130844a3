"""A test record for diagnosis, read from a bridge run directory or a CSV, checked, in mm/kN/s.

The CSV header names the columns: ``time,cmd_disp,meas_force`` are required, ``meas_disp`` is
optional (without it the interface layer cannot be seen). The bridge's own export
(``fresco-bridge runs export``: ``time,step,site,cmd_disp,meas_disp,meas_force,session``) is
read as is; a site with several actuators uses actuator 1 (``cmd_disp_1``...). Every problem is
a :class:`DiagnosisInputError` naming the file, the row or column, and why.
"""

from __future__ import annotations

import csv
import math
from dataclasses import dataclass, field, replace
from pathlib import Path

import numpy as np
import numpy.typing as npt

__all__ = [
    "MIN_SAMPLES",
    "REVERSAL_SHARE",
    "UNITS",
    "DiagnosisInputError",
    "Record",
    "load_record",
    "parse_units",
    "record_from_arrays",
    "turning_points",
]

FloatArray = npt.NDArray[np.float64]

MIN_SAMPLES = 100
"""Shortest record that splits into a calibration part and a withheld part worth scoring."""

UNITS: dict[str, dict[str, float]] = {
    "disp": {"mm": 1.0, "cm": 10.0, "m": 1000.0, "in": 25.4},
    "force": {"kN": 1.0, "N": 1e-3, "MN": 1e3, "lb": 4.4482216152605e-3, "kip": 4.4482216152605},
    "time": {"s": 1.0, "ms": 1e-3},
}
"""Accepted ``--units`` per quantity, as factors to the tool's units mm, kN and s."""


REVERSAL_SHARE = 0.005
"""A reversal of the command kept by thinning moves it by more than this share of its peak."""


def turning_points(x: FloatArray, h: float) -> npt.NDArray[np.int64]:
    """Indices of the reversals of ``x`` by more than ``h`` (a peak-valley filter: smaller
    excursions between them are ignored); ``h = 0`` gives every strict reversal."""
    turns: list[int] = []
    values = x.tolist()
    lo = hi = ext = 0
    direction = 0
    for i in range(1, len(values)):
        v = values[i]
        if direction == 0:
            if v > values[hi]:
                hi = i
            if v < values[lo]:
                lo = i
            if values[hi] - values[lo] > h:
                direction = 1 if hi > lo else -1
                ext = hi if hi > lo else lo
                turns.append(lo if hi > lo else hi)
        elif direction > 0:
            if v >= values[ext]:
                ext = i
            elif values[ext] - v > h:
                turns.append(ext)
                direction, ext = -1, i
        elif v <= values[ext]:
            ext = i
        elif v - values[ext] > h:
            turns.append(ext)
            direction, ext = 1, i
    return np.array(turns, dtype=np.int64)


class DiagnosisInputError(ValueError):
    """The record or an option cannot be diagnosed (the message names what, where and why)."""


@dataclass(frozen=True)
class Record:
    """One actuator's history: command, measured displacement (optional) and force."""

    time: FloatArray
    cmd: FloatArray
    meas_disp: FloatArray | None
    force: FloatArray
    source: str
    notes: list[str] = field(default_factory=list)

    @property
    def size(self) -> int:
        return int(self.time.size)

    def thinned(self, max_samples: int) -> Record:
        """At most ``max_samples`` samples for the fits: every k-th one, every reversal of the
        command by more than :data:`REVERSAL_SHARE` of its peak, and the last sample, so a
        rate-independent law sees the same path (smaller wiggles, such as LVDT noise on a
        broadband record, are ironed out: they move the law by less than the noise floor).
        When the reversals alone exceed the budget (broadband records: 0-50 Hz random motion
        reverses every few ms), the fits get a contiguous window from the start of the
        record instead (the law starts at rest there, as in the test): its first
        ``max_samples`` kept samples."""
        if self.size <= max_samples:
            return self
        turns = turning_points(self.cmd, REVERSAL_SHARE * float(np.max(np.abs(self.cmd))))
        # the reversals take what they need; every k-th sample fills the rest (at least half)
        step = -(-self.size // max(max_samples - turns.size, max_samples // 2))
        keep = np.union1d(np.union1d(np.arange(0, self.size, step), turns), [self.size - 1])
        note = (f"fits used {keep.size} of the {self.size} calibration samples "
                f"(one in {step} and every reversal)")
        if keep.size > max_samples:
            keep = keep[:max_samples]
            note = (f"fits used a window of the calibration part: {keep.size} samples (one in "
                    f"{step} and every reversal) from t = {float(self.time[0]):g} to "
                    f"{float(self.time[keep[-1]]):g} s of {float(self.time[-1]):g} s "
                    f"({turns.size} reversals exceed the budget of {max_samples} samples)")
        return replace(
            self, time=self.time[keep], cmd=self.cmd[keep], force=self.force[keep],
            meas_disp=None if self.meas_disp is None else self.meas_disp[keep],
            notes=[*self.notes, note],
        )

    def part(self, stop: int) -> Record:
        """The first ``stop`` samples (what a fit on the calibration part may see)."""
        return replace(
            self, time=self.time[:stop], cmd=self.cmd[:stop], force=self.force[:stop],
            meas_disp=None if self.meas_disp is None else self.meas_disp[:stop],
        )


def parse_units(text: str | None) -> dict[str, float]:
    """``"disp=in,force=kip,time=s"`` -> factors to mm, kN, s (missing keys: factor 1)."""
    factors = {"disp": 1.0, "force": 1.0, "time": 1.0}
    if not text:
        return factors
    for item in text.split(","):
        key, sep, unit = (part.strip() for part in item.partition("="))
        if not sep or key not in UNITS:
            raise DiagnosisInputError(
                f"--units: {item!r} is not QUANTITY=UNIT with QUANTITY one of disp, force, time"
            )
        if unit not in UNITS[key]:
            raise DiagnosisInputError(
                f"--units: unknown {key} unit {unit!r}; known: {', '.join(UNITS[key])}"
            )
        factors[key] = UNITS[key][unit]
    return factors


def record_from_arrays(
    time: FloatArray, cmd: FloatArray, force: FloatArray, meas_disp: FloatArray | None = None,
    *, source: str = "<arrays>", notes: list[str] | None = None,
    lines: list[int] | None = None,
) -> Record:
    """A checked record: finite, strictly increasing time, long enough to split.

    ``lines`` are the file's line numbers of the samples, so that errors point into the file.
    """

    def where(i: int) -> str:
        return f"line {lines[i]}" if lines is not None else f"sample {i + 1}"

    arrays = {"time": time, "cmd_disp": cmd, "meas_force": force}
    if meas_disp is not None:
        arrays["meas_disp"] = meas_disp
    sizes = {name: np.asarray(a).size for name, a in arrays.items()}
    if len(set(sizes.values())) != 1:
        raise DiagnosisInputError(f"{source}: columns differ in length: {sizes}")
    n = sizes["time"]
    if n < MIN_SAMPLES:
        raise DiagnosisInputError(
            f"{source}: record too short to split: {n} sample(s), need at least {MIN_SAMPLES} "
            "(a calibration part to fit on and a withheld part to score on)"
        )
    clean: dict[str, FloatArray] = {}
    for name, values in arrays.items():
        a = np.asarray(values, dtype=np.float64)
        bad = np.flatnonzero(~np.isfinite(a))
        if bad.size:
            raise DiagnosisInputError(
                f"{source}: {name} is not a finite number at {where(int(bad[0]))} "
                f"({bad.size} such sample(s)); remove or repair those rows"
            )
        clean[name] = a
    steps = np.diff(clean["time"])
    back = np.flatnonzero(steps <= 0.0)
    if back.size:
        i = int(back[0])
        raise DiagnosisInputError(
            f"{source}: time is not strictly increasing at {where(i + 1)} "
            f"({float(clean['time'][i])!r} then {float(clean['time'][i + 1])!r}); sort the "
            "record or give one session"
        )
    if float(np.ptp(clean["cmd_disp"])) == 0.0:
        raise DiagnosisInputError(f"{source}: cmd_disp is constant: nothing was tested")
    return Record(clean["time"], clean["cmd_disp"], clean.get("meas_disp"),
                  clean["meas_force"], source, list(notes or []))


def _column(header: list[str], name: str) -> int | None:
    """Index of ``name`` (or ``name_1`` for a multi-actuator export), None when absent."""
    for candidate in (name, f"{name}_1"):
        if candidate in header:
            return header.index(candidate)
    return None


def _load_csv(path: Path, site: str | None, units: dict[str, float]) -> Record:
    try:
        with path.open(newline="", encoding="utf-8") as fh:
            rows = list(csv.reader(fh))
    except OSError as exc:
        raise DiagnosisInputError(f"{path}: cannot read: {exc.strerror}") from None
    except UnicodeDecodeError:
        raise DiagnosisInputError(f"{path}: not a UTF-8 text CSV") from None
    if not rows:
        raise DiagnosisInputError(f"{path}: empty file (expected a header line)")
    header = [h.strip() for h in rows[0]]
    cols = {name: _column(header, name) for name in ("time", "cmd_disp", "meas_disp",
                                                     "meas_force")}
    missing = [n for n in ("time", "cmd_disp", "meas_force") if cols[n] is None]
    if missing:
        raise DiagnosisInputError(
            f"{path}: missing column(s) {', '.join(missing)} in the header "
            f"({','.join(header)}); required: time,cmd_disp,meas_force (meas_disp optional)"
        )
    notes: list[str] = []
    if "cmd_disp_1" in header:
        notes.append("several actuators: actuator 1 diagnosed")
    body = [(i, r) for i, r in enumerate(rows[1:], start=2) if any(c.strip() for c in r)]
    site_col = header.index("site") if "site" in header else None
    if site_col is not None:
        sites = sorted({r[site_col] for _, r in body if len(r) > site_col})
        if site is None and len(sites) > 1:
            raise DiagnosisInputError(
                f"{path}: the record holds {len(sites)} sites ({', '.join(sites)}); "
                "choose one with --site"
            )
        if site is not None:
            if site not in sites:
                raise DiagnosisInputError(
                    f"{path}: no site {site!r} (sites: {', '.join(sites) or 'none'})")
            body = [(i, r) for i, r in body if r[site_col] == site]
    elif site is not None:
        raise DiagnosisInputError(f"{path}: --site {site} given but the CSV has no site column")
    if "session" in header:
        body, note = _longest_session(body, header.index("session"))
        if note:
            notes.append(note)
    values: dict[str, list[float]] = {name: [] for name, c in cols.items() if c is not None}
    for line, row in body:
        for name, c in cols.items():
            if c is None:
                continue
            text = row[c].strip() if c < len(row) else ""
            try:
                values[name].append(float(text))
            except ValueError:
                raise DiagnosisInputError(
                    f"{path}:{line}: column {name} is {text!r}, not a number") from None
            if not math.isfinite(values[name][-1]):
                raise DiagnosisInputError(
                    f"{path}:{line}: column {name} is {text!r} (NaN rows cannot be diagnosed; "
                    "remove or repair them)"
                )
    arr = {k: np.array(v, dtype=np.float64) for k, v in values.items()}
    meas = arr.get("meas_disp")
    return record_from_arrays(
        arr["time"] * units["time"], arr["cmd_disp"] * units["disp"],
        arr["meas_force"] * units["force"], None if meas is None else meas * units["disp"],
        source=str(path), notes=notes, lines=[line for line, _ in body],
    )


def _longest_session(body: list[tuple[int, list[str]]],
                     col: int) -> tuple[list[tuple[int, list[str]]], str | None]:
    sessions: dict[str, list[tuple[int, list[str]]]] = {}
    for line, row in body:
        sessions.setdefault(row[col] if col < len(row) else "", []).append((line, row))
    if len(sessions) <= 1:
        return body, None
    name, rows = max(sessions.items(), key=lambda kv: len(kv[1]))
    return rows, f"{len(sessions)} integrator sessions: the longest (session {name}) diagnosed"


def _load_run(path: Path, site: str | None) -> Record:
    from ..runs import RunDirError, load_run, session_signals

    try:
        run = load_run(path)
    except RunDirError as exc:
        raise DiagnosisInputError(str(exc)) from None
    if not run.steps:
        raise DiagnosisInputError(
            f"{path}: the run has no committed steps (nothing was tested, or the integrator "
            "never committed a step)"
        )
    sites = sorted({s.site for s in run.steps})
    if site is None:
        if len(sites) > 1:
            raise DiagnosisInputError(
                f"{path}: the run holds {len(sites)} sites ({', '.join(sites)}); choose one "
                "with --site")
        site = sites[0]
    elif site not in sites:
        raise DiagnosisInputError(f"{path}: no committed steps for site {site!r} "
                                  f"(sites: {', '.join(sites)})")
    signals = [s for s in session_signals(run.steps) if s.site == site]
    notes = list(run.notes)
    sig = max(signals, key=lambda s: s.step.size)
    if len(signals) > 1:
        notes.append(f"{len(signals)} integrator sessions: the longest (session {sig.session}) "
                     "diagnosed")
    if sig.cmd.shape[1] > 1:
        notes.append("several actuators: actuator 1 diagnosed")
    return record_from_arrays(sig.time, sig.cmd[:, 0], sig.force[:, 0], sig.meas[:, 0],
                              source=f"{path} (site {site})", notes=notes)


def load_record(path: Path, *, site: str | None = None, units: str | None = None) -> Record:
    """Read a run directory or a CSV (``units`` converts a CSV's columns to mm, kN, s)."""
    if path.is_dir():
        if units:
            raise DiagnosisInputError("--units applies to a CSV; a run directory is in mm, kN, s")
        return _load_run(path, site)
    if not path.exists():
        raise DiagnosisInputError(f"{path}: no such file or run directory")
    return _load_csv(path, site, parse_units(units))
