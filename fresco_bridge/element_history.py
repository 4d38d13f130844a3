"""One tested element's recorded history, read from a bridge run directory or a CSV.

The one reader behind the commands that learn from or judge a test (``diagnose``, ``updater
pretrain``, ``updater replay``): one site, one integrator session, one actuator, committed step
by committed step. Values come back as written (a run directory is in mm, kN and s; a CSV in
its own units, which the caller converts). Every problem is a :class:`HistoryInputError`
naming the file, the line or column, and why, so each command can print it as one line.

**One CSV vocabulary** (:data:`COLUMNS`, :data:`ALIASES`; ``docs/run-record.md`` shows it to
users): the bridge's export (``fresco-bridge export``:
``time,step,site,cmd_disp,meas_disp,meas_force,session``, with ``_1.._n`` suffixes when a site
has n actuators, then ``site_kind,predicted``: ``predicted = 1`` marks a site whose forces are
its model's predictions, an updatable site's, read back as :attr:`ElementHistory.predicted`)
names every column; a CSV from elsewhere may use the short names of
:data:`ALIASES` (``time,disp,force``: the measured displacement and force, as the shipped
``examples/data`` records have them). Callers ask for the canonical names; every error lists the
same accepted set (:func:`vocabulary`).
"""

from __future__ import annotations

import csv
import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Literal

import numpy as np
import numpy.typing as npt

FloatArray = npt.NDArray[np.float64]

__all__ = [
    "ALIASES",
    "COLUMNS",
    "RUN_COLUMNS",
    "ElementHistory",
    "HistoryInputError",
    "InterfaceHistory",
    "SessionChoice",
    "check_increasing",
    "read_element_history",
    "read_interface",
    "vocabulary",
]

RUN_COLUMNS = ("time", "step", "cmd_disp", "meas_disp", "meas_force")
"""What a run directory holds per committed step (the export's numeric columns)."""
COLUMNS: Mapping[str, str] = {
    "time": "s, strictly increasing",
    "cmd_disp": "the commanded displacement, mm",
    "meas_disp": "the measured displacement, mm",
    "meas_force": "the measured force, kN",
}
"""The history columns a caller may ask for, by their canonical (the export's) names, with
their meaning and the units of a run directory (a CSV's may differ: the commands' ``--units``)."""
ALIASES: Mapping[str, tuple[str, ...]] = {
    "cmd_disp": ("cmd",),
    "meas_disp": ("disp",),
    "meas_force": ("force",),
}
"""Other header names accepted for a canonical column, tried when it is absent: ``disp`` and
``force`` are the *measured* displacement and force (a characterisation test's file), ``cmd``
the command. A header that holds both a name and its alias is read by the canonical name."""


def vocabulary(names: Sequence[str] | None = None) -> str:
    """The accepted header names of ``names`` (default: every column), as every message and
    help text says them: ``time, cmd_disp (or cmd), meas_disp (or disp), meas_force (or
    force)``."""
    return ", ".join(n + (f" (or {' or '.join(ALIASES[n])})" if n in ALIASES else "")
                     for n in (COLUMNS if names is None else names))

SessionChoice = int | Literal["last", "longest"]
"""An integrator session by number, or the rule that picks one when a record holds several."""


class HistoryInputError(ValueError):
    """A history cannot be read as asked (the message names the file, where and why)."""


@dataclass(frozen=True)
class ElementHistory:
    """The columns asked for, one value per committed step, and where they came from."""

    columns: dict[str, FloatArray]
    source: str
    lines: list[int] | None = None
    """The file line of each sample (a CSV), so later checks can point into the file."""
    notes: list[str] = field(default_factory=list)
    """Choices made for the caller (which session, which actuator), worth printing."""
    site_kind: str | None = None
    """The site's kind as an export names it (``site_kind`` column); None: not said."""
    predicted: bool = False
    """The forces are the site's model's predictions (``predicted = 1``: an updatable site's
    served forces), no measurement: nothing to learn from nor score against."""


def check_increasing(name: str, values: FloatArray, source: str,
                     lines: Sequence[int] | None = None) -> None:
    """HistoryInputError when ``values`` (time, step) do not increase strictly."""
    back = np.flatnonzero(np.diff(values) <= 0.0)
    if back.size:
        i = int(back[0]) + 1
        where = f"line {lines[i]}" if lines is not None else f"sample {i + 1}"
        raise HistoryInputError(
            f"{source}: {name} is not strictly increasing at {where} "
            f"({float(values[i - 1])!r} then {float(values[i])!r}); sort the record or give "
            "one session"
        )


def read_element_history(
    path: Path, required: Sequence[str], optional: Sequence[str] = (), *,
    site: str | None = None, session: SessionChoice | None = None, actuator: int = 1,
) -> ElementHistory:
    """The ``required`` (and present ``optional``) columns of one element's history, by their
    canonical names (:data:`COLUMNS`; a CSV may use their :data:`ALIASES`).

    ``site`` may be omitted only when the record holds one; ``session`` defaults to ``last``.
    """
    unknown = [n for n in (*required, *optional) if n not in COLUMNS]
    if unknown:
        raise ValueError(f"not history columns: {', '.join(unknown)} (known: {vocabulary()})")
    choice: SessionChoice = "last" if session is None else session
    if path.is_dir():
        return _read_run(path, [*required, *optional], site, choice, actuator)
    if not path.exists():
        raise HistoryInputError(f"{path}: no such file or run directory")
    return _read_csv(path, required, optional, site, choice, actuator)


def _choose_site(path: Path, sites: list[str], site: str | None) -> str:
    if not sites:
        raise HistoryInputError(f"{path}: the run has no committed steps (nothing was "
                                "tested, or the integrator never committed a step)")
    if site is None:
        if len(sites) > 1:
            raise HistoryInputError(f"{path}: the record holds {len(sites)} sites "
                                    f"({', '.join(sites)}); choose one with --site")
        return sites[0]
    if site not in sites:
        raise HistoryInputError(f"{path}: no site {site!r} in the record "
                                f"(sites: {', '.join(sites)})")
    return site


def _choose_session(where: str, sizes: Mapping[int, int],
                    choice: SessionChoice) -> tuple[int, str | None]:
    """The session number and, when the record holds several, a note saying which was used."""
    if isinstance(choice, int):
        if choice not in sizes:
            raise HistoryInputError(f"{where} has sessions "
                                    f"{', '.join(map(str, sorted(sizes)))}, not {choice}")
        return choice, None
    chosen = max(sizes, key=lambda s: sizes[s]) if choice == "longest" else max(sizes)
    if len(sizes) == 1:
        return chosen, None
    return chosen, (f"{len(sizes)} integrator sessions: the {choice} (session {chosen}, "
                    f"{sizes[chosen]} steps) used")


def _read_run(path: Path, wanted: Sequence[str], site: str | None, choice: SessionChoice,
              actuator: int) -> ElementHistory:
    from .runs import RunDirError, load_run, session_signals

    try:
        run = load_run(path)
    except RunDirError as exc:
        raise HistoryInputError(str(exc)) from None
    name = _choose_site(path, sorted({s.site for s in run.steps}), site)
    signals = {s.session: s for s in session_signals(run.steps) if s.site == name}
    sizes = {k: v.step.size for k, v in signals.items()}
    number, note = _choose_session(f"{path}: site {name!r}", sizes, choice)
    sig = signals[number]
    notes = [*run.notes, *([note] if note else [])]
    width = sig.cmd.shape[1]
    if not 1 <= actuator <= width:
        raise HistoryInputError(f"{path}: site {name!r} has {width} actuator(s), not {actuator}")
    if width > 1:
        notes.append(f"site {name!r} has {width} actuators: actuator {actuator} used")
    available = {"time": sig.time.astype(np.float64), "step": sig.step.astype(np.float64),
                 "cmd_disp": sig.cmd[:, actuator - 1], "meas_disp": sig.meas[:, actuator - 1],
                 "meas_force": sig.force[:, actuator - 1]}
    source = f"{path} (site {name}, session {number}, actuator {actuator})"
    columns: dict[str, FloatArray] = {}
    for col in wanted:
        values = available[col]
        bad = np.flatnonzero(~np.isfinite(values))
        if bad.size:
            raise HistoryInputError(
                f"{source}: step {int(sig.step[int(bad[0])])}: {col} is not finite (a HOLD "
                f"answer? {bad.size} such step(s)); every step needs a value")
        columns[col] = values
    return ElementHistory(columns, source, None, notes)


def _column(header: list[str], name: str, actuator: int) -> int | None:
    """Index of ``name`` (``name_<actuator>`` in a multi-actuator export), None when absent."""
    for candidate in (name, f"{name}_{actuator}"):
        if candidate in header:
            return header.index(candidate)
    return None


def _read_csv(path: Path, required: Sequence[str], optional: Sequence[str],
              site: str | None, choice: SessionChoice, actuator: int) -> ElementHistory:
    try:
        with path.open(newline="", encoding="utf-8") as fh:
            rows = list(csv.reader(fh))
    except OSError as exc:
        raise HistoryInputError(f"{path}: cannot read: {exc.strerror}") from None
    except UnicodeDecodeError:
        raise HistoryInputError(f"{path}: not a UTF-8 text CSV") from None
    if not rows or not any(cell.strip() for cell in rows[0]):
        raise HistoryInputError(f"{path}: empty file (expected a header line naming "
                                f"{vocabulary([*required, *optional])})")
    header = [h.strip() for h in rows[0]]
    if "step" in header and "step" not in (*required, *optional):
        optional = (*optional, "step")  # checked for order below
    cols: dict[str, tuple[str, int]] = {}
    for name in (*required, *optional):
        for candidate in (name, *ALIASES.get(name, ())):
            index = _column(header, candidate, actuator)
            if index is not None:
                cols[name] = (header[index], index)
                break
    missing = [n for n in required if n not in cols]
    if missing:
        raise HistoryInputError(
            f"{path}:1: missing column(s) {vocabulary(missing)} (the header has "
            f"{', '.join(header)}; needed: {vocabulary(required)})")
    notes: list[str] = []
    width = sum(1 for h in header if h.startswith("meas_force_"))
    if width and actuator > width:
        raise HistoryInputError(f"{path}: {width} actuator(s), not {actuator}")
    if width > 1:
        notes.append(f"{width} actuators: actuator {actuator} used")
    body = [(i, r) for i, r in enumerate(rows[1:], start=2) if any(c.strip() for c in r)]
    if not body:
        raise HistoryInputError(f"{path}: no data rows after the header")
    where = str(path)
    if "site" in header:
        col = header.index("site")
        chosen = _choose_site(path, sorted({r[col] for _, r in body if len(r) > col}), site)
        body = [(i, r) for i, r in body if len(r) > col and r[col] == chosen]
        where += f" (site {chosen})"
    elif site is not None:  # one element; other inputs of the same command may have sites
        notes.append(f"no site column: --site {site} does not apply, every row is used")
    if "session" in header:
        body, note = _one_session(path, where, body, header.index("session"), choice)
        if note:
            notes.append(note)
    columns = {name: np.empty(len(body)) for name in cols}
    for n, (line, row) in enumerate(body):
        for name, (label, c) in cols.items():
            text = row[c].strip() if c < len(row) else ""
            try:
                value = float(text)
            except ValueError:
                raise HistoryInputError(
                    f"{path}:{line}: column {label} is {text!r}, not a number") from None
            if not math.isfinite(value):
                raise HistoryInputError(
                    f"{path}:{line}: column {label} is {text!r}, not a finite number (a gap in "
                    "the record? every step needs a value: remove or repair the row)")
            columns[name][n] = value
    lines = [line for line, _ in body]
    for name in ("time", "step"):
        if name in columns:
            check_increasing(name, columns[name], where, lines)
    kind, predicted = _site_kind(header, body)
    return ElementHistory(columns, where, lines, notes, kind, predicted)


def _site_kind(header: list[str], body: list[tuple[int, list[str]]]) -> tuple[str | None, bool]:
    """The chosen rows' ``site_kind`` and whether any is ``predicted`` (an export's last
    columns; a file without them says nothing: measured)."""
    def cells(name: str) -> set[str]:
        if name not in header:
            return set()
        col = header.index(name)
        return {row[col].strip() for _, row in body if len(row) > col} - {""}

    kinds = cells("site_kind")
    return (", ".join(sorted(kinds)) if kinds else None), "1" in cells("predicted")


def _one_session(path: Path, where: str, body: list[tuple[int, list[str]]], col: int,
                 choice: SessionChoice) -> tuple[list[tuple[int, list[str]]], str | None]:
    groups: dict[int, list[tuple[int, list[str]]]] = {}
    for line, row in body:
        text = row[col].strip() if col < len(row) else ""
        try:
            groups.setdefault(int(text), []).append((line, row))
        except ValueError:
            raise HistoryInputError(f"{path}:{line}: column session is {text!r}, not an "
                                    "integer") from None
    number, note = _choose_session(where, {k: len(v) for k, v in groups.items()}, choice)
    return groups[number], note


@dataclass(frozen=True)
class InterfaceHistory:
    """Per committed step of one site session, actuator: where the integrator asked the specimen
    to be and where it was measured — the interface layer as the integrator sees it.

    ``target`` is the integrator's command, never a corrected one: a site with
    ``[sites.correction]`` sends the controller other commands for the same trial, and the
    committed step's ``cmd_disp`` is the last of them, so the target comes from the trial's
    correction line. ``measured`` is the displacement the correction compared there, on
    ``channel`` (``daq``, or ``external``: the channel the site's controller names), or without
    correction lines the committed step's ``meas_disp`` (``daq``)."""

    step: FloatArray
    target: FloatArray
    measured: FloatArray
    channel: str
    corrections: npt.NDArray[np.int64] | None
    """Corrected commands per step (None: the run has no correction lines for the site)."""
    outcomes: list[str]
    """Each corrected step's outcome (``converged``…; empty without correction lines)."""
    tolerance: float | None
    """The correction's tolerance (mm) for this actuator from the config snapshot, if known."""
    source: str
    notes: list[str] = field(default_factory=list)


def read_interface(path: Path, *, site: str | None = None, session: SessionChoice = "longest",
                   actuator: int = 1) -> InterfaceHistory:
    """The interface history of a run directory (a CSV holds no integrator target apart from
    its command: HistoryInputError). The session rule is :func:`read_element_history`'s."""
    from .runs import RunDirError, load_run

    if not path.is_dir():
        raise HistoryInputError(f"{path}: the interface gap needs a run directory (its "
                                "correction lines hold the integrator's target), not a file")
    try:
        run = load_run(path)
    except RunDirError as exc:
        raise HistoryInputError(str(exc)) from None
    name = _choose_site(path, sorted({s.site for s in run.steps}), site)
    steps: dict[int, list[int]] = {}
    for s in run.steps:
        if s.site == name:
            steps.setdefault(s.session, []).append(s.step)
    number, note = _choose_session(f"{path}: site {name!r}",
                                   {k: len(v) for k, v in steps.items()}, session)
    committed = [s for s in run.steps if s.site == name and s.session == number]
    lines = {c.step: c for c in run.corrections if c.site == name and c.session == number}
    width = len(committed[0].cmd_disp)
    if not 1 <= actuator <= width:
        raise HistoryInputError(f"{path}: site {name!r} has {width} actuator(s), not {actuator}")
    a = actuator - 1
    notes = [*([note] if note else [])]
    config = run.site_configs().get(name, {}).get("correction")
    source = f"{path} (site {name}, session {number}, actuator {actuator})"
    if not lines:
        return InterfaceHistory(
            np.array([s.step for s in committed], dtype=np.float64),
            np.array([s.cmd_disp[a] for s in committed]),
            np.array([s.meas_disp[a] for s in committed]), "daq", None, [], None, source,
            notes)
    kept = [s for s in committed if s.step in lines]
    if len(kept) < len(committed):
        notes.append(f"{len(committed) - len(kept)} committed step(s) without a correction "
                     "line left out")
    rows = [lines[s.step] for s in kept]
    tolerance = None if not isinstance(config, dict) else config.get("tolerance")
    if isinstance(tolerance, list):
        tolerance = tolerance[a] if a < len(tolerance) else None
    channel = "daq" if not isinstance(config, dict) else str(config.get("measured", "daq"))
    return InterfaceHistory(
        np.array([s.step for s in kept], dtype=np.float64),
        np.array([c.target[a] for c in rows]), np.array([c.measured[-1][a] for c in rows]),
        channel, np.array([c.corrections for c in rows], dtype=np.int64),
        [c.outcome for c in rows], None if tolerance is None else float(tolerance), source,
        notes)
