"""Recorded (d, F) histories for the ``updater`` commands: run directories and CSV files.

The I/O edge of the updating package (the numerics never read files), over the one reader of
a tested element's history (:mod:`fresco_bridge.element_history`, which ``diagnose`` uses too).
Every error is a :class:`HistoryError` naming the file, the line and the column, and saying why.

CSV: the bridge's export (``time,step,site,cmd_disp,meas_disp,meas_force,session``) or a
header row ``time,disp,force`` and one row per committed step. ``time`` must increase
strictly; a ``step`` column, when present, too. Other columns are ignored. Values are converted
to mm and kN by ``Units`` (``--units m,N``), and back for writing.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np
import numpy.typing as npt

from fresco_bridge.element_history import HistoryInputError, read_element_history

from .base import UpdaterError

FloatArray = npt.NDArray[np.float64]

__all__ = ["DISP_UNITS", "FORCE_UNITS", "History", "HistoryError", "Units", "read_history",
           "updatable_site"]

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


@dataclass(frozen=True)
class History:
    """One tested element's (d, F) history for an updater, in mm and kN."""

    disp: FloatArray
    force: FloatArray | None
    """None when the file has no force column (a twin's displacement alone)."""
    source: str
    notes: list[str]
    predicted: bool = False
    """The forces are an updatable site's served predictions (an export's ``predicted``
    column): never learned from nor scored against."""


def read_history(path: Path, *, need_force: bool = True, site: str | None = None,
                 session: int | None = None, actuator: int = 1,
                 units: Units = Units()) -> History:
    """A run directory, the bridge's export CSV or a ``time,disp,force`` CSV, as (d, F).

    The displacement is the *measured* one (an export's ``meas_disp``), not the command: it is
    what the specimen went through, so the force it answered belongs to it. ``units`` apply to
    a CSV (a run directory is in mm and kN); a record with several sites needs ``site``; of
    several integrator sessions the last is used unless ``session`` says otherwise (each
    session starts from rest).
    """
    if path.is_dir():
        units = Units()
    force_col = ("meas_force",)  # ``force`` in a time,disp,force CSV (element_history.ALIASES)
    try:
        history = read_element_history(
            path, ("time", "meas_disp", *(force_col if need_force else ())),
            () if need_force else force_col, site=site, session=session, actuator=actuator)
    except HistoryInputError as exc:
        raise HistoryError(str(exc)) from None
    cols = history.columns
    force = cols.get("meas_force")
    return History(cols["meas_disp"] * units.to_mm,
                   None if force is None else force * units.to_kn, history.source, history.notes,
                   history.predicted)


def updatable_site(path: Path, site: str | None) -> str | None:
    """The name of the site ``path`` holds for ``site`` (given, or the run's only one) when
    it is an *updatable* site of a run directory, else None.

    Why: an updatable site's forces are its updater's predictions, served to the integrator;
    they are no measurement to learn from and no truth to score against. A run directory says
    which sites are updatable (its config snapshot, and the ``update`` line after each of their
    committed steps); a CSV says it in its ``predicted`` column (``fresco-bridge export``),
    read into ``History.predicted``, which the caller checks (a CSV without the column is taken
    as measured).
    """
    if not path.is_dir():
        return None
    from fresco_bridge.runs import RunDirError, load_run

    try:
        run = load_run(path)
    except RunDirError as exc:
        raise HistoryError(str(exc)) from None
    updatable = set(run.sources()) | {str(u["site"]) for u in run.updates}
    sites = run.sites
    chosen = site if site is not None else (sites[0] if len(sites) == 1 else None)
    return chosen if chosen is not None and chosen in updatable else None
