"""Read a run record back and export committed steps as CSV (the diagnosis tool's input).

CSV columns: ``time,step,site,cmd_disp,meas_disp,meas_force`` — with ``_1.._n`` suffixes when a
site has n > 1 actuators — plus ``session`` (a run can hold several integrator sessions) and,
from ``fresco-bridge export``, ``site_kind`` and ``predicted`` last (``1``: the site's force is
its model's prediction, an updatable site's, never a measurement to learn from or score against).
``cmd_disp`` is the actuator command (ctrl), ``meas_*`` the measurement (daq) of that step, in
mm and kN; ``time`` is the integrator's pseudo-time of the committed trial.
"""

from __future__ import annotations

import csv
import json
import math
from collections.abc import Iterable, Iterator, Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from .lines import RecordFormatError, expand
from .rundir import RECORD_FILE


@dataclass(frozen=True, slots=True)
class CommittedStep:
    site: str
    session: int
    step: int
    time: float
    cmd_disp: tuple[float, ...]
    meas_disp: tuple[float, ...]
    meas_force: tuple[float, ...]


@dataclass(frozen=True, slots=True)
class MonitorLine:
    """The online error monitors after one committed step (``monitor`` record lines)."""

    site: str
    session: int
    step: int
    tracking_error: float
    ti: float
    nrms: float | None
    fei_amplitude: float | None
    fei_delay: float | None


@dataclass(frozen=True, slots=True)
class CorrectionLine:
    """One trial's displacement correction (``correction`` record lines, format 6): every
    command the controller reached for ``target``, the target's own first, and the displacement
    measured there (mm)."""

    site: str
    session: int
    step: int
    target: tuple[float, ...]
    outcome: str
    corrections: int
    residual: float
    commands: tuple[tuple[float, ...], ...]
    measured: tuple[tuple[float, ...], ...]


def _float(v: Any) -> float:
    return float(v)  # numbers, and the "nan"/"inf" strings the writer uses for non-finite values


def read_record(run_dir: Path) -> Iterator[dict[str, Any]]:
    """Yield the record's lines as complete dicts (format 1, 2 or 3, see ``lines.py``). A torn
    last line (crash mid-write) is skipped."""
    return expand(_decoded_lines(run_dir))


def _decoded_lines(run_dir: Path) -> Iterator[dict[str, Any]]:
    path = run_dir / RECORD_FILE if run_dir.is_dir() else run_dir
    try:
        lines = path.read_text(encoding="utf-8").splitlines()
    except OSError as exc:
        raise RecordFormatError(f"{path}: cannot read the run record: {exc.strerror}") from exc
    for i, line in enumerate(lines, 1):
        if not line.strip():
            continue
        try:
            obj = json.loads(line)
        except json.JSONDecodeError as exc:
            if i == len(lines):
                return  # torn tail of a killed process: everything before it is intact
            raise RecordFormatError(f"{path}:{i}: not a JSON record line ({exc.msg})") from exc
        if not isinstance(obj, dict) or "kind" not in obj:
            raise RecordFormatError(f"{path}:{i}: record line without a 'kind'")
        yield obj


def record_is_torn(run_dir: Path) -> bool:
    """True when the record's last line was cut short (the writer was killed mid-write)."""
    path = run_dir / RECORD_FILE if run_dir.is_dir() else run_dir
    try:
        with path.open("rb") as fh:
            size = fh.seek(0, 2)
            if size == 0:
                return False
            fh.seek(size - 1)
            return fh.read(1) != b"\n"
    except OSError as exc:
        raise RecordFormatError(f"{path}: cannot read the run record: {exc.strerror}") from exc


def committed_steps(run_dir: Path) -> list[CommittedStep]:
    """Pair each commit with the last trial and measurement before it, per site session."""
    return pair_commits(read_record(run_dir))


def pair_commits(records: Iterable[dict[str, Any]]) -> list[CommittedStep]:
    """``committed_steps`` over already-read record lines (one read serves several uses)."""
    last_trial: dict[tuple[str, int], dict[str, Any]] = {}
    last_daq: dict[tuple[str, int], dict[str, Any]] = {}
    out: list[CommittedStep] = []
    for rec in records:
        key = (rec.get("site", ""), int(rec.get("session", 0)))
        kind = rec["kind"]
        if kind == "trial":
            last_trial[key] = rec
            last_daq.pop(key, None)
        elif kind == "daq":
            last_daq[key] = rec
        elif kind == "commit":
            trial, daq = last_trial.get(key), last_daq.get(key)
            if trial is None or daq is None:
                continue
            out.append(
                CommittedStep(
                    site=key[0], session=key[1], step=int(rec["step"]),
                    time=_float(trial["time"]),
                    cmd_disp=tuple(_float(v) for v in trial["ctrl"]),
                    meas_disp=tuple(_float(v) for v in daq["disp"]),
                    meas_force=tuple(_float(v) for v in daq["force"]),
                )
            )
    return out


def monitor_lines(records: Iterable[dict[str, Any]]) -> list[MonitorLine]:
    """The ``monitor`` lines among ``records``, in record order."""

    def opt(v: Any) -> float | None:
        return None if v is None else float(v)

    return [
        MonitorLine(
            site=rec.get("site", ""), session=int(rec.get("session", 0)), step=int(rec["step"]),
            tracking_error=_float(rec["err"]), ti=_float(rec["ti"]), nrms=opt(rec.get("nrms")),
            fei_amplitude=opt(rec.get("fei_amp")), fei_delay=opt(rec.get("fei_delay")),
        )
        for rec in records if rec["kind"] == "monitor"
    ]


def correction_lines(records: Iterable[dict[str, Any]]) -> list[CorrectionLine]:
    """The ``correction`` lines among ``records``, in record order (none before format 6)."""
    def vector(v: Any) -> tuple[float, ...]:
        return tuple(_float(x) for x in v)

    return [
        CorrectionLine(
            site=rec.get("site", ""), session=int(rec.get("session", 0)), step=int(rec["step"]),
            target=vector(rec["target"]), outcome=str(rec["outcome"]),
            corrections=int(rec["n"]), residual=_float(rec["residual"]),
            commands=tuple(vector(c) for c, _ in rec["it"]),
            measured=tuple(vector(m) for _, m in rec["it"]),
        )
        for rec in records if rec["kind"] == "correction"
    ]


def write_corrections_csv(corrections: Iterable[CorrectionLine], out_path: Path, *,
                          site: str | None = None) -> int:
    """One row per command of each corrected trial: ``session,step,site,iteration`` (0: the
    target's own command), ``target_*``, ``command_*``, ``measured_*`` (``_1.._n`` when a site
    has n > 1 control points), the trial's ``outcome``, ``corrections`` and ``residual``;
    returns the number of rows."""
    rows = [c for c in corrections if site is None or c.site == site]
    n = max((len(c.target) for c in rows), default=1)

    def cols(name: str) -> list[str]:
        return [name] if n == 1 else [f"{name}_{i}" for i in range(1, n + 1)]

    def pad(v: tuple[float, ...]) -> list[str]:
        return [repr(x) if math.isfinite(x) else str(x) for x in v] + [""] * (n - len(v))

    count = 0
    with out_path.open("w", newline="", encoding="utf-8") as fh:
        w = csv.writer(fh)
        w.writerow(["session", "step", "site", "iteration", *cols("target"), *cols("command"),
                    *cols("measured"), "outcome", "corrections", "residual"])
        for c in rows:
            for i, (command, measured) in enumerate(zip(c.commands, c.measured, strict=True)):
                w.writerow([c.session, c.step, c.site, i, *pad(c.target), *pad(command),
                            *pad(measured), c.outcome, c.corrections, repr(c.residual)])
                count += 1
    return count


def export_csv(run_dir: Path, out_path: Path, *, site: str | None = None) -> int:
    """Write the committed steps to ``out_path``; returns the number of rows."""
    return write_csv(committed_steps(run_dir), out_path, site=site)


def write_csv(steps: Iterable[CommittedStep], out_path: Path, *, site: str | None = None,
              kinds: Mapping[str, tuple[str, bool]] | None = None) -> int:
    """``export_csv`` for steps already read; returns the number of rows. ``kinds``: ``{site:
    (its kind, whether its force is predicted)}``, written as the last two columns (a site not
    in it: empty cells, nothing known)."""
    steps = [s for s in steps if site is None or s.site == site]
    n = max((len(s.cmd_disp) for s in steps), default=1)

    def cols(name: str) -> list[str]:
        return [name] if n == 1 else [f"{name}_{i}" for i in range(1, n + 1)]

    header = ["time", "step", "site", *cols("cmd_disp"), *cols("meas_disp"), *cols("meas_force")]
    header.append("session")
    if kinds is not None:
        header += ["site_kind", "predicted"]

    def kind(name: str) -> list[str]:
        if kinds is None:
            return []
        known = kinds.get(name)
        return ["", ""] if known is None else [known[0], "1" if known[1] else "0"]

    def pad(v: tuple[float, ...]) -> list[str]:
        return [repr(x) if math.isfinite(x) else str(x) for x in v] + [""] * (n - len(v))

    with out_path.open("w", newline="", encoding="utf-8") as fh:
        w = csv.writer(fh)
        w.writerow(header)
        for s in steps:
            w.writerow(
                [repr(s.time), s.step, s.site, *pad(s.cmd_disp), *pad(s.meas_disp),
                 *pad(s.meas_force), s.session, *kind(s.site)]
            )
    return len(steps)
