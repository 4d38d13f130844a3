"""Runs that ended without a clean close: found, flagged, repaired and resumed.

A live bridge holds an exclusive ``flock`` on its ``record.jsonl`` for as long as it runs; the
kernel drops it when the process dies, however it dies (``kill -9``, power loss). So a run
whose ``run.json`` still says ``running`` while nobody holds the lock was interrupted. On start
the bridge flags such runs of its run directory (``run.json`` state ``interrupted``, a warning,
the stale control socket removed); ``fresco-bridge runs resume RUN`` continues the record of one
of them from its last committed step.
"""

from __future__ import annotations

import contextlib
import fcntl
import json
import logging
import os
import socket
from collections import deque
from collections.abc import Iterator
from dataclasses import dataclass
from datetime import UTC, datetime
from pathlib import Path
from typing import Any

from .lines import expand
from .rundir import META_FILE, RECORD_FILE, update_meta

log = logging.getLogger("fresco_bridge.record")

TORN_SUFFIX = ".torn"
"""A torn last line cut off before a resume is kept beside the record, not thrown away."""


def is_locked(run_dir: Path) -> bool:
    """True while a bridge holds the run's record open (it is live)."""
    try:
        fd = os.open(run_dir / RECORD_FILE, os.O_RDONLY)
    except OSError:
        return False
    try:
        fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
    except BlockingIOError:
        return True
    finally:
        os.close(fd)  # closing drops our own lock, if we got it
    return False


def _meta(run_dir: Path) -> dict[str, Any]:
    try:
        meta = json.loads((run_dir / META_FILE).read_text(encoding="utf-8"))
    except (OSError, ValueError):
        return {}
    return meta if isinstance(meta, dict) else {}


def run_state(run_dir: Path, meta: dict[str, Any] | None = None) -> str:
    """``running`` (live), ``closed``, ``interrupted`` or ``unknown`` (written before states)."""
    meta = _meta(run_dir) if meta is None else meta
    state = meta.get("state")
    if state == "running":
        return "running" if is_locked(run_dir) else "interrupted"
    return str(state) if state in ("closed", "interrupted") else "unknown"


@dataclass(frozen=True, slots=True)
class LastCommit:
    """Where a site's record stops: its last session and committed step."""

    site: str
    session: int
    step: int
    time: float


class ResumePoint:
    """Where a record stops, read line by line (one pass, shared with other readers:
    ``record/scan.py``): the last line's sequence number and time, and per site its last
    session and committed step. It needs only the commit and event lines (every session
    opens with an event line) and the last line."""

    KINDS = ("commit", "event")

    def __init__(self) -> None:
        self.seq = 0
        self.t = 0.0
        self._commits: dict[str, LastCommit] = {}
        self._sessions: dict[str, int] = {}

    def line(self, rec: dict[str, Any]) -> None:
        """A commit or event line (``KINDS``)."""
        site, session = str(rec.get("site", "")), int(rec.get("session", 0))
        if session > self._sessions.get(site, -1):
            self._sessions[site] = session
        if rec.get("kind") == "commit":
            t = rec.get("time", 0.0)
            self._commits[site] = LastCommit(site, session, int(rec["step"]),
                                             float(t) if isinstance(t, int | float) else 0.0)

    def last_line(self, rec: dict[str, Any]) -> None:
        """The record's last line (any kind): where the sequence numbers and times go on."""
        self.seq, self.t = int(rec.get("seq", self.seq)), float(rec.get("t", self.t))

    def last_commits(self) -> dict[str, LastCommit]:
        """Per site, the last committed step (a session opened after it counts too)."""
        out = dict(self._commits)
        for site, session in self._sessions.items():
            last = out.get(site)
            if last is None:
                out[site] = LastCommit(site, session, 0, 0.0)
            elif session > last.session:
                out[site] = LastCommit(site, session, last.step, last.time)
        return out


def last_commits(run_dir: Path) -> dict[str, LastCommit]:
    """Per site, the last committed step of the record (torn tail ignored)."""
    point = ResumePoint()
    for rec in _lines(run_dir):
        if rec.get("kind") in ResumePoint.KINDS:
            point.line(rec)
    return point.last_commits()


def last_seq_and_time(run_dir: Path) -> tuple[int, float]:
    point = ResumePoint()
    for rec in deque(_lines(run_dir), maxlen=1):
        point.last_line(rec)
    return point.seq, point.t


def _lines(run_dir: Path) -> Iterator[dict[str, Any]]:
    """The complete lines of the record (either format), torn tail and bad lines skipped."""
    return expand(_raw_lines(run_dir))


def _raw_lines(run_dir: Path) -> Iterator[dict[str, Any]]:
    with (run_dir / RECORD_FILE).open("rb") as fh:
        for raw in fh:
            if not raw.endswith(b"\n"):
                return  # the torn tail
            with contextlib.suppress(ValueError):
                rec = json.loads(raw)
                if isinstance(rec, dict):
                    yield rec


def open_sessions(run_dir: Path) -> list[tuple[str, int]]:
    """(site, session) opened in the record and never closed. A session cut by an
    interruption that the run then resumed (the site's ``resumed`` event) is not open any
    more: the resumed run continues it as the next session."""
    opened: dict[tuple[str, int], bool] = {}
    for rec in _lines(run_dir):
        if rec.get("kind") != "event":
            continue
        site = str(rec.get("site", ""))
        key = (site, int(rec.get("session", 0)))
        if rec.get("event") == "session-open":
            opened[key] = True
        elif rec.get("event") == "session-close":
            opened.pop(key, None)
        elif rec.get("event") == "resumed":
            opened = {k: v for k, v in opened.items() if k[0] != site}
    return list(opened)


def cut_torn_tail(run_dir: Path) -> int:
    """Move a torn last line to ``record.jsonl.torn`` (appended) and truncate the record to
    its last complete line, so appending can go on; returns the bytes moved."""
    path = run_dir / RECORD_FILE
    with path.open("r+b") as fh:
        size = fh.seek(0, os.SEEK_END)
        if size == 0:
            return 0
        back = min(size, 1 << 20)
        fh.seek(size - back)
        tail = fh.read(back)
        if tail.endswith(b"\n"):
            return 0
        cut = tail.rfind(b"\n") + 1
        torn = tail[cut:]
        keep = os.open(str(path) + TORN_SUFFIX, os.O_WRONLY | os.O_CREAT | os.O_APPEND, 0o600)
        try:
            os.write(keep, torn + b"\n")
            os.fsync(keep)
        finally:
            os.close(keep)
        fh.truncate(size - len(torn))
        fh.flush()
        os.fsync(fh.fileno())
    return len(torn)


def _remove_stale_socket(run_dir: Path) -> list[Path]:
    removed = []
    candidates = [run_dir / "control.sock"]
    with contextlib.suppress(OSError):
        candidates.append(Path((run_dir / "control.path").read_text(encoding="utf-8").strip()))
    for path in candidates:
        if not (path.exists() or path.is_symlink()) or socket_answers(path):
            continue
        with contextlib.suppress(OSError):
            path.unlink()
            removed.append(path)
    with contextlib.suppress(OSError):
        (run_dir / "control.path").unlink()
    return removed


def socket_answers(path: Path) -> bool:
    """Whether a process listens on the Unix socket ``path`` (a stale one refuses)."""
    with socket.socket(socket.AF_UNIX, socket.SOCK_STREAM) as s:
        s.settimeout(1.0)
        try:
            s.connect(str(path))
        except OSError:
            return False
        return True


def flag_interrupted(run_root: Path, *, exclude: Path | None = None) -> list[Path]:
    """Find the runs under ``run_root`` that ended without a clean close; mark each one
    ``interrupted`` in its ``run.json``, remove its stale control socket and warn. Returns
    every interrupted run (also those flagged by an earlier start)."""
    if not run_root.is_dir():
        return []
    found = []
    for run_dir in sorted(p for p in run_root.iterdir() if p.is_dir()):
        if exclude is not None and run_dir.resolve() == exclude.resolve():
            continue
        meta = _meta(run_dir)
        if run_state(run_dir, meta) != "interrupted":
            continue
        found.append(run_dir)
        removed = _remove_stale_socket(run_dir)
        if meta.get("state") == "interrupted":
            continue  # already reported at an earlier start
        update_meta(run_dir, state="interrupted",
                    interrupted_found_utc=datetime.now(UTC).isoformat())
        where = ", ".join(f"{c.site} session {c.session} step {c.step}"
                          for c in last_commits(run_dir).values()) or "no committed step"
        unclosed = ", ".join(f"{s} session {n}" for s, n in open_sessions(run_dir))
        log.warning("run %s ended without a clean close (bridge killed or host lost); last "
                    "committed: %s%s%s. The actuators hold where the controller left them: see "
                    "docs/run-record.md 'After a crash', then 'fresco-bridge runs resume %s'",
                    run_dir.name,
                    where, f"; sessions never closed: {unclosed}" if unclosed else "",
                    f"; stale control socket removed: {', '.join(map(str, removed))}"
                    if removed else "", run_dir.name)
    return found
