"""A test record for diagnosis, read from a bridge run directory or a CSV, checked, in mm/kN/s.

Reading is :mod:`fresco_bridge.element_history`'s, in its one CSV vocabulary (``time``,
``cmd_disp``, ``meas_disp``, ``meas_force``, or the aliases it documents: ``time,disp,force`` is
a record of the measured displacement and force): ``time``, ``meas_force`` and a displacement are
required. A record with no command channel — no ``cmd_disp`` column, or any record read with
``no_command`` (then ``meas_disp``, or else the one displacement column, is the measured
displacement) — drives the law by the measured displacement (``Record.no_command``; what that
hides: :mod:`.nocommand`); a ``cmd_disp`` identical to ``meas_disp`` gets a note (an ideal rig,
or a copied channel?). A site with several actuators uses actuator 1, a record with several
integrator sessions its longest. Every problem is a :class:`DiagnosisInputError` naming the
file, the row or column, and why.
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace
from pathlib import Path

import numpy as np
import numpy.typing as npt

from ..element_history import (
    ElementHistory,
    HistoryInputError,
    check_increasing,
    read_element_history,
    vocabulary,
)

__all__ = [
    "IDENTICAL_NOTE",
    "MIN_SAMPLES",
    "NO_COMMAND_NOTE",
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
    no_command: bool = False
    """True: no command channel; ``cmd`` holds the *measured* displacement (``meas_disp`` is
    None) and the interface layer cannot be seen (:mod:`.nocommand`)."""
    velocity_scale: float = 0.0
    """The whole record's RMS command velocity, mm/s (0: computed here): the reference of the
    rate law, kept by :meth:`part` and :meth:`thinned` so a calibration fit and a prediction
    of the withheld part mean the same coefficient (the command is known before the test)."""

    def __post_init__(self) -> None:
        if self.velocity_scale <= 0.0:
            v = np.diff(self.cmd) / np.diff(self.time) if self.size > 1 else np.zeros(1)
            scale = float(np.sqrt(np.mean(v * v)))
            object.__setattr__(self, "velocity_scale",
                               scale if scale > 0.0 and np.isfinite(scale) else 1.0)

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
    lines: list[int] | None = None, no_command: bool = False,
) -> Record:
    """A checked record: finite, strictly increasing time, long enough to split.

    ``lines`` are the file's line numbers of the samples, so that errors point into the file.
    ``no_command``: ``cmd`` is the measured displacement (give no ``meas_disp``).
    """
    if no_command and meas_disp is not None:
        raise DiagnosisInputError(f"{source}: a record without a command channel has one "
                                  "displacement, the measured one (pass it as cmd)")

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
    try:
        check_increasing("time", clean["time"], source, lines)
    except HistoryInputError as exc:
        raise DiagnosisInputError(str(exc)) from None
    if float(np.ptp(clean["cmd_disp"])) == 0.0:
        what = "the measured displacement" if no_command else "cmd_disp"
        raise DiagnosisInputError(f"{source}: {what} is constant: nothing was tested")
    return Record(clean["time"], clean["cmd_disp"], clean.get("meas_disp"),
                  clean["meas_force"], source, list(notes or []), no_command)


IDENTICAL_NOTE = ("cmd_disp is identical to meas_disp, sample for sample: an ideal rig, or the "
                  "measured displacement copied into the command column; if the record has no "
                  "command channel, give --no-command (the interface effects found here would "
                  "otherwise be invisible, not absent)")
NO_COMMAND_NOTE = ("no command channel ({why}): the measured displacement drives the law; "
                   "interface effects are not identifiable")


def _read(path: Path, site: str | None, required: tuple[str, ...],
          optional: tuple[str, ...]) -> ElementHistory:
    try:
        return read_element_history(path, required, optional, site=site, session="longest")
    except HistoryInputError as exc:
        raise DiagnosisInputError(str(exc)) from None


def _from_history(path: Path, site: str | None, units: dict[str, float],
                  no_command: bool) -> Record:
    """The record through the one reader of a tested element's history; actuator 1, and the
    longest integrator session when the record holds several. Without a command channel
    (given, or detected: no ``cmd_disp`` column) the measured displacement is the one
    displacement. A ``cmd_disp`` identical to ``meas_disp`` is ambiguous — an ideal rig (the
    simulated lab's, the demo's) or a copied channel — so it is kept as the command, with a
    note saying what ``--no-command`` would change."""
    history = _read(path, site, ("time", "meas_force"), ("cmd_disp", "meas_disp"))
    cols = history.columns
    cmd, meas = cols.get("cmd_disp"), cols.get("meas_disp")
    if cmd is None and meas is None:
        raise DiagnosisInputError(
            f"{history.source}: no displacement column: give {vocabulary(['cmd_disp'])} "
            f"and/or {vocabulary(['meas_disp'])} (accepted: {vocabulary()})")
    why = ("--no-command" if no_command else "the record has no cmd_disp column"
           if cmd is None else None)
    notes = list(history.notes)
    if why is None and cmd is not None and meas is not None and np.array_equal(cmd, meas):
        notes.append(IDENTICAL_NOTE)
    time, force = cols["time"] * units["time"], cols["meas_force"] * units["force"]
    if why is not None or cmd is None:
        disp = meas if meas is not None else cmd
        assert disp is not None  # both absent raised above
        return record_from_arrays(
            time, disp * units["disp"], force, source=history.source,
            notes=[*notes, NO_COMMAND_NOTE.format(why=why)], lines=history.lines,
            no_command=True)
    return record_from_arrays(
        time, cmd * units["disp"], force, None if meas is None else meas * units["disp"],
        source=history.source, notes=notes, lines=history.lines,
    )


def load_record(path: Path, *, site: str | None = None, units: str | None = None,
                no_command: bool = False) -> Record:
    """Read a run directory or a CSV (``units`` converts a CSV's columns to mm, kN, s);
    ``no_command``: the record's displacement is the measured one, whatever its column."""
    if path.is_dir() and units:
        raise DiagnosisInputError("--units applies to a CSV; a run directory is in mm, kN, s")
    return _from_history(path, site, parse_units(units), no_command)
