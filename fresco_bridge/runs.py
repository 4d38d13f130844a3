"""Run directories after the fact: find, load, summarise (``fresco-bridge runs``, ``report``).

A run directory is what ``RunRecord.create`` makes: ``run.json`` (metadata), ``record.jsonl``
(the record) and ``config.toml`` (snapshot). ``load_run`` reads the record once and keeps the
committed steps, events and online-monitor lines; a torn last line (the bridge was killed
mid-write) is skipped and reported, everything before it is used. All indicator math comes
from ``indicators.py``.
"""

from __future__ import annotations

import json
import math
import tomllib
from collections.abc import Iterable, Iterator
from dataclasses import dataclass, field
from datetime import UTC, datetime
from pathlib import Path
from typing import Any

import numpy as np

from .indicators import IndicatorError, fei, nrms_error, peak_errors, tracking_indicator
from .indicators import xcorr_delay as _xcorr_delay
from .numbers import fmt
from .record.export import (
    CommittedStep,
    CorrectionLine,
    MonitorLine,
    correction_lines,
    monitor_lines,
    pair_commits,
    read_record,
    record_is_torn,
)
from .record.lines import RecordFormatError
from .record.recovery import open_sessions, run_state
from .record.rundir import CONFIG_FILE, META_FILE, RECORD_FILE, update_meta

DEFAULT_DT = 0.01  # TelemetryConfig.monitor_dt's default, for records without integrator time
XCORR_MAX_LAG = 50  # samples either side for the cross-correlation delay estimate


class RunDirError(ValueError):
    """A run directory is missing, incomplete or corrupt (the message says which and why)."""


@dataclass(frozen=True, slots=True)
class Run:
    """One run directory, read once."""

    directory: Path
    meta: dict[str, Any]
    config_text: str | None
    steps: list[CommittedStep]
    events: list[dict[str, Any]]
    monitors: list[MonitorLine]
    torn: bool
    size_bytes: int
    notes: list[str] = field(default_factory=list)
    updates: list[dict[str, Any]] = field(default_factory=list)
    """The update lines of updatable sites (format 5: ``site``, ``session``, ``step``,
    ``through``, ``secs``), in record order."""
    corrections: list[CorrectionLine] = field(default_factory=list)
    """The displacement corrections of sites with ``[sites.correction]`` (format 6), in record
    order."""

    @property
    def name(self) -> str:
        return self.directory.name

    @property
    def sites(self) -> list[str]:
        """Configured sites (run.json) first, then any other site that appears in the record."""
        names = [str(s) for s in self.meta.get("sites", [])]
        for s in self.steps:
            if s.site not in names:
                names.append(s.site)
        return names

    def site_configs(self) -> dict[str, dict[str, Any]]:
        """``{site: its [[sites]] table}`` from the config snapshot (``{}``: no snapshot, or
        one that does not parse)."""
        if self.config_text is None:
            return {}
        try:
            sites = tomllib.loads(self.config_text).get("sites", [])
        except tomllib.TOMLDecodeError:
            return {}
        return {str(s["name"]): s for s in sites if isinstance(s, dict) and "name" in s}

    def site_kinds(self) -> dict[str, str]:
        """``{site: its kind}`` from the config snapshot (``experimental`` where the table
        names none, the config's default; ``{}``: no snapshot)."""
        return {name: str(s.get("kind", "experimental"))
                for name, s in self.site_configs().items()}

    def sources(self) -> dict[str, str]:
        """``{updatable site: the site it learns from}`` from the config snapshot (``{}``: no
        snapshot, or no updatable site)."""
        return {name: str(s["learns_from"]) for name, s in self.site_configs().items()
                if s.get("kind") == "updatable" and "learns_from" in s}

    def config_value(self, section: str, key: str, default: Any) -> Any:
        """A value from the config snapshot (``default`` when absent or unreadable)."""
        if self.config_text is None:
            return default
        try:
            return tomllib.loads(self.config_text).get(section, {}).get(key, default)
        except tomllib.TOMLDecodeError:
            return default


def _dir_size(directory: Path) -> int:
    return sum(p.stat().st_size for p in directory.iterdir() if p.is_file())


def check_run_dir(path: Path) -> Path:
    """``path`` if it is a run directory, else a RunDirError saying what is wrong."""
    if not path.exists():
        raise RunDirError(f"{path}: no such run directory")
    if not path.is_dir():
        raise RunDirError(f"{path}: not a directory (give a run directory, e.g. runs/<stamp>-demo)")
    if not (path / RECORD_FILE).is_file():
        raise RunDirError(
            f"{path}: not a run directory: {RECORD_FILE} is missing (a run directory holds "
            f"{META_FILE}, {RECORD_FILE} and {CONFIG_FILE}, as the bridge writes them)"
        )
    return path


def _read_meta(path: Path) -> dict[str, Any]:
    """run.json as a dict; ``{}`` when absent (the record alone is still a run)."""
    meta_path = path / META_FILE
    if not meta_path.exists():
        return {}
    try:
        meta = json.loads(meta_path.read_text(encoding="utf-8"))
    except OSError as exc:
        raise RunDirError(f"{meta_path}: cannot read the run metadata: {exc.strerror}") from exc
    except (json.JSONDecodeError, UnicodeDecodeError) as exc:
        raise RunDirError(f"{meta_path}: run metadata is not valid JSON ({exc})") from exc
    if not isinstance(meta, dict):
        raise RunDirError(f"{meta_path}: run metadata must be a JSON object, got "
                          f"{type(meta).__name__}")
    return meta


def load_run(path: Path) -> Run:
    """Read a run directory; RunDirError names the file, the place and the reason."""
    directory = check_run_dir(path)
    meta = _read_meta(directory)
    notes: list[str] = [] if meta else [f"{META_FILE} is missing: no run metadata"]
    config_text: str | None = None
    try:
        config_text = (directory / CONFIG_FILE).read_text(encoding="utf-8")
    except OSError as exc:
        notes.append(f"{CONFIG_FILE} could not be read ({exc.strerror}); no config snapshot")
    events: list[dict[str, Any]] = []
    monitors: list[dict[str, Any]] = []
    updates: list[dict[str, Any]] = []
    corrections: list[dict[str, Any]] = []
    last_seq: list[object] = [None]

    def tap(records: Iterator[dict[str, Any]]) -> Iterator[dict[str, Any]]:
        for rec in records:
            last_seq[0] = rec.get("seq")
            kind = rec["kind"]
            if kind == "event":
                events.append(rec)
            elif kind == "monitor":
                monitors.append(rec)
            elif kind == "update":
                updates.append(rec)
            elif kind == "correction":
                corrections.append(rec)
            yield rec

    record = directory / RECORD_FILE
    try:
        steps = pair_commits(tap(read_record(directory)))
        monitor_data = monitor_lines(monitors)
        correction_data = correction_lines(corrections)
        torn = record_is_torn(directory)
    except RecordFormatError as exc:
        raise RunDirError(str(exc)) from exc
    except (KeyError, TypeError, ValueError) as exc:
        raise RunDirError(
            f"{record}: a record line near seq {last_seq[0]} lacks a field or has a value the "
            f"writer never writes ({type(exc).__name__}: {exc}); the record is corrupt"
        ) from exc
    if torn:
        notes.append(f"{RECORD_FILE} ends with a torn line (the bridge was killed mid-write); "
                     "it was skipped, everything before it is intact")
    state = run_state(directory, meta)
    if state == "interrupted":
        how = ("the bridge was stopped (Ctrl-C or SIGTERM) while a client was served"
               if "interrupted_utc" in meta else
               "the run ended without a clean close (bridge killed or host lost)")
        notes.append(f"{how}; 'fresco-bridge runs resume' continues it")
    for site, session in open_sessions(directory):
        if state != "running":
            notes.append(f"site {site} session {session} was opened and never closed")
    return Run(directory, meta, config_text, steps, events, monitor_data, torn,
               _dir_size(directory), notes, updates, correction_data)


def check_resumable(path: Path) -> Path:
    """``path`` if it is a run that can be resumed (interrupted, or closed and continued on
    purpose), else why not."""
    check_run_dir(path)
    if run_state(path) == "running":
        raise RunDirError(f"{path}: the run is live (a bridge holds its record); stop it first")
    return path


def mark_interrupted(path: Path) -> None:
    """A run stopped mid-test (Ctrl-C while a client was served): ``run.json`` says
    ``interrupted``, as for a bridge killed and found later, so ``runs list`` shows it and
    ``runs resume`` continues it. Called after the record closed (its clean close says
    ``closed``)."""
    update_meta(path, state="interrupted", interrupted_utc=datetime.now(UTC).isoformat())


def resolve_run(name: str | Path, runs_root: Path) -> Path:
    """A run given as a path, or as a directory name (or unique prefix) under ``runs_root``."""
    path = Path(name)
    if path.exists() or path.is_absolute() or len(path.parts) > 1:
        return path
    candidate = runs_root / path
    if candidate.exists():
        return candidate
    if runs_root.is_dir():
        hits = sorted(p for p in runs_root.iterdir() if p.is_dir() and p.name.startswith(str(name)))
        if len(hits) == 1:
            return hits[0]
        if len(hits) > 1:
            more = f" and {len(hits) - 5} more" if len(hits) > 5 else ""
            shown = ", ".join(p.name for p in hits[:5]) + more
            raise RunDirError(f"{name!r} matches {len(hits)} runs under {runs_root}: {shown} "
                              "(give more of the name)")
    raise RunDirError(f"{name}: no such run (not a path, and not a run under {runs_root})")


# -- listing (a fast scan: only event lines are parsed) ----------------------------------------
@dataclass(frozen=True, slots=True)
class RunListing:
    name: str
    directory: Path
    started_utc: str
    sites: list[str]
    steps: int
    sessions: int
    holds: int
    size_bytes: int
    error: str | None = None
    state: str = "unknown"
    site_sessions: dict[str, int] = field(default_factory=dict)
    """Integrator sessions per site; ``sessions`` is their sum (two sites served to one
    integrator are two sessions, one each)."""


def scan_run(path: Path) -> RunListing:
    """Counts for ``runs list`` without decoding every line (step and commit lines are only
    counted)."""
    try:
        meta = _read_meta(check_run_dir(path))
        steps = holds = 0
        sites = [str(s) for s in meta.get("sites", [])]
        site_sessions = dict.fromkeys(sites, 0)
        with (path / RECORD_FILE).open("rb") as fh:
            for line in fh:
                if not line.endswith(b"\n"):
                    continue  # a torn last line, as load_run skips it
                if b'"kind":"step"' in line or b'"kind":"commit"' in line:  # format 3, 1/2
                    steps += 1
                elif b'"kind":"event"' in line:
                    ev = json.loads(line)
                    if ev.get("event") == "session-open":
                        site = str(ev.get("site", "?"))
                        site_sessions[site] = site_sessions.get(site, 0) + 1
                    holds += ev.get("event") == "hold"
        return RunListing(path.name, path, str(meta.get("started_utc", "?")), sites, steps,
                          sum(site_sessions.values()), holds, _dir_size(path),
                          state=run_state(path, meta), site_sessions=site_sessions)
    except (RunDirError, OSError, ValueError) as exc:
        return RunListing(path.name, path, "?", [], 0, 0, 0, 0, error=str(exc))


def list_runs(runs_root: Path) -> list[RunListing]:
    """Every run directory under ``runs_root``, oldest first (names start with a UTC stamp)."""
    if not runs_root.is_dir():
        raise RunDirError(f"{runs_root}: no such runs directory (use --runs DIR)")
    dirs = sorted(p for p in runs_root.iterdir()
                  if p.is_dir() and ((p / META_FILE).exists() or (p / RECORD_FILE).exists()))
    return [scan_run(p) for p in dirs]


def human_size(n: int) -> str:
    size = float(n)
    for unit in ("B", "KiB", "MiB", "GiB"):
        if size < 1024 or unit == "GiB":
            return f"{size:.0f} {unit}" if unit == "B" else f"{size:.1f} {unit}"
        size /= 1024
    return f"{size:.1f} GiB"


def _per_site(counts: dict[str, int]) -> str:
    """Sessions of several sites: ``1 each``, or one count per site in the sites' order
    (``2,1``), never their sum (two sites of one integrator are not two test sessions)."""
    values = list(counts.values())
    if len(values) < 2:
        return str(sum(values)) if values else ""
    if len(set(values)) == 1:
        return f"{values[0]} each"
    return ",".join(map(str, values))


def format_listing(runs: list[RunListing]) -> str:
    """``runs list``: one line per run (the sessions column counts per site)."""
    header = ("run", "started (UTC)", "state", "sites", "steps", "sessions", "holds", "size")
    rows = [header]
    for r in runs:
        if r.error is not None:
            rows.append((r.name, "unreadable", "", r.error, "", "", "", ""))
            continue
        rows.append((r.name, r.started_utc[:19], r.state, ",".join(r.sites), str(r.steps),
                     _per_site(r.site_sessions) or str(r.sessions), str(r.holds),
                     human_size(r.size_bytes)))
    widths = [max(len(row[i]) for row in rows) for i in range(len(header) - 1)]
    return "\n".join(
        "  ".join(c.ljust(w) for c, w in zip(row[:-1], widths, strict=True)) + "  " + row[-1]
        for row in rows
    )


# -- summaries (all indicator math in indicators.py) -------------------------------------------
@dataclass(frozen=True, slots=True)
class SessionSummary:
    """One actuator of one site over one integrator session."""

    site: str
    session: int
    actuator: int
    steps: int
    time_start: float
    time_end: float
    dt: float
    dt_source: str
    peak_cmd: float
    peak_meas: float
    force_max: float
    force_min: float
    max_tracking_error: float
    peak_amplitude_error: float
    nrms: float | None
    ti_final: float
    fei_amplitude: float | None
    fei_delay: float | None
    xcorr_delay: float | None

    def as_dict(self) -> dict[str, Any]:
        return {k: getattr(self, k) for k in self.__slots__}


@dataclass(frozen=True, slots=True)
class SiteSummary:
    site: str
    steps: int
    sessions: int
    events: dict[str, int]
    sessions_detail: list[SessionSummary]

    @property
    def holds(self) -> int:
        return self.events.get("hold", 0)

    @property
    def limit_events(self) -> int:
        return sum(n for k, n in self.events.items() if k.startswith("limit"))


@dataclass(frozen=True, slots=True)
class SessionSignals:
    """Committed-step arrays of one site session (rows = steps, columns = actuators)."""

    site: str
    session: int
    time: np.ndarray
    step: np.ndarray
    cmd: np.ndarray
    meas: np.ndarray
    force: np.ndarray


def session_signals(steps: Iterable[CommittedStep]) -> list[SessionSignals]:
    """Committed steps grouped by (site, session), in order of first appearance."""
    groups: dict[tuple[str, int], list[CommittedStep]] = {}
    for s in steps:
        groups.setdefault((s.site, s.session), []).append(s)
    out = []
    for (site, session), rows in groups.items():
        n = max(len(r.cmd_disp) for r in rows)

        def mat(rows: list[CommittedStep], attr: str, n: int = n) -> np.ndarray:
            return np.array([tuple(getattr(r, attr)) + (math.nan,) * (n - len(getattr(r, attr)))
                             for r in rows], dtype=np.float64).reshape(len(rows), n)

        out.append(SessionSignals(
            site, session, np.array([r.time for r in rows]), np.array([r.step for r in rows]),
            mat(rows, "cmd_disp"), mat(rows, "meas_disp"), mat(rows, "meas_force"),
        ))
    return out


def _or_none(fn: Any, *args: Any, **kw: Any) -> Any:
    try:
        return fn(*args, **kw)
    except IndicatorError:
        return None


def _summarise_actuator(sig: SessionSignals, a: int, fallback_dt: float) -> SessionSummary:
    cmd, meas, force = sig.cmd[:, a], sig.meas[:, a], sig.force[:, a]
    ok = np.isfinite(cmd) & np.isfinite(meas)
    c, m = cmd[ok], meas[ok]
    steps = np.diff(sig.time)
    positive = steps[steps > 0]
    if positive.size:
        dt, dt_source = float(np.median(positive)), "integrator time"
    else:
        dt, dt_source = fallback_dt, "telemetry.monitor_dt (the record has no time)"
    e_dm, e_md = (_or_none(peak_errors, c, m) or (math.nan, math.nan))
    ti = _or_none(tracking_indicator, c, m)
    fe = _or_none(fei, c, m, dt)
    max_lag = min(XCORR_MAX_LAG, c.size - 3)
    xd = _or_none(_xcorr_delay, c, m, dt, max_lag) if max_lag >= 1 else None
    fmax = float(np.nanmax(force)) if np.isfinite(force).any() else math.nan
    fmin = float(np.nanmin(force)) if np.isfinite(force).any() else math.nan
    return SessionSummary(
        site=sig.site, session=sig.session, actuator=a + 1, steps=int(sig.step.size),
        time_start=float(sig.time[0]), time_end=float(sig.time[-1]), dt=dt, dt_source=dt_source,
        peak_cmd=float(np.max(np.abs(c))) if c.size else math.nan,
        peak_meas=float(np.max(np.abs(m))) if m.size else math.nan,
        force_max=fmax, force_min=fmin, max_tracking_error=e_md, peak_amplitude_error=e_dm,
        nrms=_or_none(nrms_error, c, m),
        ti_final=float(ti[-1]) if ti is not None and ti.size else math.nan,
        fei_amplitude=None if fe is None else fe[0], fei_delay=None if fe is None else fe[1],
        xcorr_delay=xd,
    )


def summarise(run: Run) -> list[SiteSummary]:
    """Per site: committed steps, sessions, event counts and per-session indicators."""
    fallback_dt = float(run.config_value("telemetry", "monitor_dt", DEFAULT_DT))
    signals = session_signals(run.steps)
    out = []
    for site in run.sites:
        counts: dict[str, int] = {}
        for ev in run.events:
            if ev.get("site") == site:
                kind = str(ev.get("event", "?"))
                counts[kind] = counts.get(kind, 0) + 1
        detail = [
            _summarise_actuator(sig, a, fallback_dt)
            for sig in signals if sig.site == site for a in range(sig.cmd.shape[1])
        ]
        out.append(SiteSummary(
            site=site, steps=sum(1 for s in run.steps if s.site == site),
            sessions=counts.get("session-open", len({d.session for d in detail})),
            events=counts, sessions_detail=detail,
        ))
    return out


@dataclass(frozen=True, slots=True)
class CorrectionStats:
    """One site's displacement corrections, summed up (``runs show``, the report, the same
    numbers): per trial in record order, its corrections and residual; the median (the upper
    one of an even count: a whole number of corrections), the max, the largest residual and
    the trials that did not converge."""

    steps: list[int]
    corrections: list[int]
    residual: list[float]
    converged: list[bool]

    @property
    def median(self) -> int:
        counts = sorted(self.corrections)
        return counts[len(counts) // 2]

    @property
    def not_converged(self) -> int:
        return sum(not c for c in self.converged)


def correction_stats(lines: list[CorrectionLine]) -> CorrectionStats:
    """The stats of one site's correction lines (at least one)."""
    return CorrectionStats([c.step for c in lines], [c.corrections for c in lines],
                           [c.residual for c in lines], [c.outcome == "converged" for c in lines])


def correction_summary(lines: list[CorrectionLine]) -> str:
    """One site's displacement corrections in a line: trials, corrections per trial (median,
    max), the largest residual left, the trials that did not converge."""
    st = correction_stats(lines)
    return (f"displacement correction: {len(lines)} trial(s), corrections a trial median "
            f"{st.median} max {max(st.corrections)}, largest residual "
            f"{fmt(max(st.residual), 'mm')}, {st.not_converged} not converged")


def format_show(run: Run, summaries: list[SiteSummary]) -> str:
    """``runs show``: metadata, then one block per site."""
    head = [("run", str(run.directory)), ("state", run_state(run.directory, run.meta))]
    head += [(key, str(run.meta[key])) for key in ("started_utc", "host", "fresco_bridge",
                                                    "format") if key in run.meta]
    head += [("size", human_size(run.size_bytes)), *(("note", n) for n in run.notes)]
    width = max(len(k) for k, _ in head)
    lines = [f"{k:<{width}}  {v}" for k, v in head]
    twins = run.sources()
    for s in summaries:
        events = ", ".join(f"{k} {n}" for k, n in sorted(s.events.items())) or "none"
        lines += ["", f"site {s.site}: {s.steps} committed step(s), {s.sessions} session(s), "
                  f"{s.holds} hold(s), {s.limit_events} limit event(s)", f"  events: {events}"]
        corrected = [c for c in run.corrections if c.site == s.site]
        if corrected:
            lines.append("  " + correction_summary(corrected))
        for d in s.sessions_detail:
            lines.append(
                f"  session {d.session} actuator {d.actuator}: {d.steps} steps, t "
                f"{fmt(d.time_start)}..{fmt(d.time_end)} s; peak |cmd| {fmt(d.peak_cmd, 'mm')}, "
                f"|meas| {fmt(d.peak_meas, 'mm')}; force {fmt(d.force_min)}..{fmt(d.force_max)} kN"
            )
            if s.site in twins:  # no actuator: its "measurement" is its trial, zeros say nothing
                lines.append(f"    updatable site (the twin of {twins[s.site]}): no actuator, no "
                             "tracking error")
                continue
            lines.append(
                f"    max |error| {fmt(d.max_tracking_error, 'mm')}, NRMS {fmt(d.nrms)}, "
                f"TI {fmt(d.ti_final, 'mm²')}, FEI amplitude {fmt(d.fei_amplitude)}, "
                f"FEI delay {fmt(d.fei_delay, 's')}, xcorr delay {fmt(d.xcorr_delay, 's')} "
                f"(dt {fmt(d.dt)} s from {d.dt_source})"
            )
    return "\n".join(lines)
