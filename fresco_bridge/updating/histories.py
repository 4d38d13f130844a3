"""Recorded (d, F) histories for the ``updater`` commands: CSV files and bridge run directories.

The I/O edge of the updating package (the numerics never read files). Every error is a
:class:`HistoryError` naming the file, the line and the column, and saying why.

CSV: a header row, then one row per committed step. ``time`` must increase strictly; a
``step`` column, when present, too. Other columns are ignored. Values are converted to mm and
kN by ``Units`` (``--units m,N``), and back for writing.
"""

from __future__ import annotations

import csv
import math
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import numpy.typing as npt

from .base import UpdaterError

FloatArray = npt.NDArray[np.float64]

__all__ = ["DISP_UNITS", "FORCE_UNITS", "HistoryError", "Units", "read_csv_history",
           "read_run_history"]

DISP_UNITS = {"mm": 1.0, "cm": 10.0, "m": 1000.0, "in": 25.4}
"""Displacement unit -> mm."""
FORCE_UNITS = {"kN": 1.0, "N": 1e-3, "MN": 1e3, "kip": 4.4482216152605, "lbf": 4.4482216152605e-3}
"""Force unit -> kN."""


class HistoryError(UpdaterError):
    """A history file is missing, unreadable or malformed (file, line, column and why)."""


@dataclass(frozen=True, slots=True)
class Units:
    """The units of a file's displacement and force columns (internally mm and kN)."""

    disp: str = "mm"
    force: str = "kN"

    @classmethod
    def parse(cls, text: str) -> Units:
        """``"m,N"`` -> Units("m", "N"); HistoryError listing the known units otherwise."""
        parts = [p.strip() for p in text.split(",")]
        if len(parts) != 2 or parts[0] not in DISP_UNITS or parts[1] not in FORCE_UNITS:
            raise HistoryError(
                f"--units: expected DISP,FORCE with DISP in {', '.join(DISP_UNITS)} and FORCE in "
                f"{', '.join(FORCE_UNITS)}, got {text!r}"
            )
        return cls(parts[0], parts[1])

    @property
    def to_mm(self) -> float:
        return DISP_UNITS[self.disp]

    @property
    def to_kn(self) -> float:
        return FORCE_UNITS[self.force]

    def __str__(self) -> str:
        return f"{self.disp},{self.force}"


def read_csv_history(path: Path, required: Sequence[str], optional: Sequence[str] = (),
                     units: Units = Units()) -> dict[str, FloatArray]:
    """The named columns of a CSV as float arrays (disp in mm, force in kN)."""
    try:
        with path.open(newline="", encoding="utf-8") as fh:
            rows = list(csv.reader(fh))
    except FileNotFoundError:
        raise HistoryError(f"{path}: no such file") from None
    except (OSError, UnicodeDecodeError) as exc:
        raise HistoryError(f"{path}: cannot read ({exc})") from exc
    if not rows or not any(cell.strip() for cell in rows[0]):
        raise HistoryError(f"{path}: empty file (expected a header row: "
                           f"{','.join([*required, *optional])})")
    header = [cell.strip() for cell in rows[0]]
    missing = [name for name in required if name not in header]
    if missing:
        raise HistoryError(f"{path}:1: missing column(s) {', '.join(missing)} (the header has "
                           f"{', '.join(header)}; needed: {', '.join(required)})")
    wanted = [n for n in (*required, *optional) if n in header]
    if "step" in header and "step" not in wanted:
        wanted.append("step")
    index = {name: header.index(name) for name in wanted}
    data = {name: np.empty(len(rows) - 1) for name in wanted}
    n = 0
    for line_no, row in enumerate(rows[1:], start=2):
        if not any(cell.strip() for cell in row):
            continue  # a blank line (e.g. at the end)
        for name, col in index.items():
            cell = row[col].strip() if col < len(row) else ""
            try:
                value = float(cell)
            except ValueError:
                raise HistoryError(f"{path}:{line_no}: column {name!r}: not a number "
                                   f"({cell!r})") from None
            if not math.isfinite(value):
                raise HistoryError(f"{path}:{line_no}: column {name!r}: {cell!r} is not finite "
                                   "(a gap in the record? every step needs a value)")
            data[name][n] = value
        n += 1
    if n == 0:
        raise HistoryError(f"{path}: no data rows after the header")
    out = {name: values[:n] for name, values in data.items()}
    for name in ("time", "step"):
        if name in out:
            bad = np.flatnonzero(np.diff(out[name]) <= 0.0)
            if bad.size:
                i = int(bad[0]) + 1
                raise HistoryError(
                    f"{path}:{_line_of(rows, i)}: column {name!r}: {float(out[name][i])!r} does "
                    f"not increase (previous row {float(out[name][i - 1])!r}); steps must be in "
                    "order, "
                    "one row each"
                )
    if "disp" in out:
        out["disp"] = out["disp"] * units.to_mm
    if "force" in out:
        out["force"] = out["force"] * units.to_kn
    return out


def _line_of(rows: list[list[str]], data_index: int) -> int:
    """The file line number of the ``data_index``-th non-blank data row."""
    seen = -1
    for line_no, row in enumerate(rows[1:], start=2):
        if any(cell.strip() for cell in row):
            seen += 1
            if seen == data_index:
                return line_no
    return len(rows)


def read_run_history(path: Path, site: str | None = None, actuator: int = 1,
                     session: int | None = None) -> tuple[FloatArray, FloatArray, str]:
    """(disp mm, force kN, description) of one actuator's measurements in a bridge run.

    A run can hold several sites and integrator sessions; with one site it is used, and the
    last session is used unless ``session`` says otherwise (each session starts from rest).
    """
    from fresco_bridge.runs import RunDirError, load_run

    try:
        run = load_run(path)
    except RunDirError as exc:
        raise HistoryError(str(exc)) from exc
    sites = sorted({s.site for s in run.steps})
    if not sites:
        raise HistoryError(f"{path}: the run has no committed steps")
    if site is None:
        if len(sites) > 1:
            raise HistoryError(f"{path}: the run has sites {', '.join(sites)}; choose one "
                               "with --site")
        site = sites[0]
    if site not in sites:
        raise HistoryError(f"{path}: no site {site!r} in the run (sites: {', '.join(sites)})")
    steps = [s for s in run.steps if s.site == site]
    sessions = sorted({s.session for s in steps})
    chosen = sessions[-1] if session is None else session
    if chosen not in sessions:
        raise HistoryError(f"{path}: site {site!r} has sessions "
                           f"{', '.join(map(str, sessions))}, not {session}")
    steps = [s for s in steps if s.session == chosen]
    width = len(steps[0].meas_disp)
    if not 1 <= actuator <= width:
        raise HistoryError(f"{path}: site {site!r} has {width} actuator(s), not {actuator}")
    disp = np.array([s.meas_disp[actuator - 1] for s in steps])
    force = np.array([s.meas_force[actuator - 1] for s in steps])
    bad = np.flatnonzero(~(np.isfinite(disp) & np.isfinite(force)))
    if bad.size:
        raise HistoryError(f"{path}: site {site!r} step {steps[int(bad[0])].step}: the "
                           "measurement is not finite (a HOLD answer?); cannot train on it")
    return disp, force, f"{path} site {site} session {chosen} actuator {actuator}"
