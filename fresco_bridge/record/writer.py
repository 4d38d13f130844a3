"""Append-only run record, safe against kill -9 and, within ``sync_interval``, power loss.

One run directory per bridge run: ``config.toml`` (snapshot), ``run.json`` (metadata) and
``record.jsonl`` (one JSON object per line, format in ``record/lines.py``). Lines are buffered
in memory between commits; at each commit (and at every event) the buffer goes to the kernel
with one ``write`` before the bridge processes the next message, so killing the process loses
no committed step. ``fdatasync`` makes it durable against a power loss:

- ``fsync="background"`` (default): group commit, as databases do. A syncer thread runs one
  ``fdatasync`` for every commit written since the last one, at most once per
  ``sync_interval`` (default 10 ms); an event (hold, fault, session change) asks for a sync at
  once. A power loss can cost the commits of the last ``sync_interval`` plus the duration of
  one ``fdatasync`` (typically < 1 ms on a local SSD); the step loop never waits for the disk.
  ``sync_interval = 0`` syncs after every commit (still off the step loop).
- ``fsync="inline"``: the bridge waits for ``fdatasync`` at every commit and event.
- ``fsync="off"``: the kernel writes back when it likes (30 s on Linux by default).

The run directory is private (0700, files 0600: the record and the config snapshot describe a
lab's test; the snapshot never holds a secret, see ``config_model.redact_config_text``).
``run.json`` says ``state``: ``running`` while a bridge holds the record's ``flock``, ``closed``
after a clean close; a run left ``running`` with no lock holder was interrupted
(``record/recovery.py``), and ``RunRecord.resume`` continues it.
"""

from __future__ import annotations

import fcntl
import json
import math
import os
import socket
import threading
import time
from datetime import UTC, datetime
from pathlib import Path
from typing import Literal

from .lines import FORMAT_VERSION, LineEncoder

RECORD_FILE = "record.jsonl"
CONFIG_FILE = "config.toml"
META_FILE = "run.json"
DEFAULT_SYNC_INTERVAL = 0.01
"""Group commit: at most one fdatasync per this many seconds (events sync at once)."""


class RecordError(OSError):
    """The run record could not be created or written."""


def write_private(path: Path, text: str) -> None:
    """Write ``text`` to ``path`` readable by this user only (0600), atomically."""
    tmp = path.with_name(f".{path.name}.tmp")
    fd = os.open(tmp, os.O_WRONLY | os.O_CREAT | os.O_TRUNC, 0o600)
    try:
        os.fchmod(fd, 0o600)
        data = text.encode("utf-8")
        view = memoryview(data)
        while view:
            view = view[os.write(fd, view):]
        os.fsync(fd)
    finally:
        os.close(fd)
    os.replace(tmp, path)


def update_meta(directory: Path, **changes: object) -> dict[str, object]:
    """Rewrite ``run.json`` with ``changes`` applied (atomic; 0600)."""
    path = directory / META_FILE
    try:
        meta = json.loads(path.read_text(encoding="utf-8"))
    except (OSError, ValueError):
        meta = {}
    if not isinstance(meta, dict):
        meta = {}
    meta.update(changes)
    write_private(path, json.dumps(meta, indent=2))
    return meta


class _Syncer(threading.Thread):
    """Group commit: one fdatasync covers every line written before it starts.

    Syncs at most once per ``interval``; a request while the last sync is younger than that
    waits out the rest of the interval, unless it is urgent (an event). Requests that arrive
    during a sync or a wait are coalesced into the next sync.
    """

    def __init__(self, fd: int, interval: float) -> None:
        super().__init__(name="fresco-record-sync", daemon=True)
        self._fd = fd
        self._interval = interval
        self._wanted = threading.Event()
        self._urgent = threading.Event()
        self._stopping = False
        self._requested = 0  # lines written to the kernel when the last request came
        self.durable = 0  # lines covered by the last completed fdatasync
        self.syncs = 0
        self.error: OSError | None = None

    def request(self, lines: int, urgent: bool) -> None:
        self._requested = lines
        if urgent:
            self._urgent.set()
        if not self._wanted.is_set():
            self._wanted.set()

    def run(self) -> None:
        last = -math.inf
        while True:
            self._wanted.wait()
            if self._stopping:
                return
            wait = last + self._interval - time.monotonic()
            if wait > 0.0 and not self._urgent.is_set():
                self._urgent.wait(wait)
                if self._stopping:
                    return
            self._urgent.clear()
            self._wanted.clear()
            covered = self._requested
            last = time.monotonic()
            try:
                os.fdatasync(self._fd)
                self.durable = covered
                self.syncs += 1
            except OSError as exc:  # reported at close and on the next flush
                self.error = exc

    def stop(self) -> None:
        self._stopping = True
        self._urgent.set()
        self._wanted.set()
        self.join(timeout=5.0)


class RunRecord:
    """The record of one bridge run. Not thread-safe: used from the event loop only."""

    def __init__(
        self, directory: Path, *, fsync: Literal["background", "inline", "off"] = "background",
        sync_interval: float = DEFAULT_SYNC_INTERVAL, seq: int = 0, t: float = 0.0,
    ) -> None:
        self.directory = directory
        self._fsync = fsync
        self._seq = seq
        self._buf: list[str] = []
        self._enc = LineEncoder()
        self._t0 = time.monotonic() - t
        path = directory / RECORD_FILE
        try:
            self._fd = os.open(path, os.O_WRONLY | os.O_CREAT | os.O_APPEND, 0o600)
        except OSError as exc:
            raise RecordError(exc.errno, f"cannot open run record {path}: {exc.strerror}") from exc
        try:  # held while this bridge lives: the kernel drops it however the process ends
            fcntl.flock(self._fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except BlockingIOError:
            os.close(self._fd)
            raise RecordError(f"{path}: the run is in use by another running bridge") from None
        os.fchmod(self._fd, 0o600)
        self._syncer: _Syncer | None = None
        if fsync == "background":
            self._syncer = _Syncer(self._fd, sync_interval)
            self._syncer.start()
        self.closed = False

    @classmethod
    def create(
        cls,
        base_dir: Path,
        name: str,
        config_text: str,
        meta: dict[str, object],
        *,
        fsync: Literal["background", "inline", "off"] = "background",
        sync_interval: float = DEFAULT_SYNC_INTERVAL,
    ) -> RunRecord:
        """Make ``base_dir/<UTC timestamp>-<name>/`` (0700) with the config snapshot and
        metadata (0600). ``config_text`` must already be redacted."""
        stamp = datetime.now(UTC).strftime("%Y%m%dT%H%M%S")
        try:
            base_dir.mkdir(parents=True, exist_ok=True)
            directory = base_dir / f"{stamp}-{name}"
            suffix = 1
            while directory.exists():
                suffix += 1
                directory = base_dir / f"{stamp}-{name}-{suffix}"
            directory.mkdir(mode=0o700)
            directory.chmod(0o700)  # whatever the umask
            write_private(directory / CONFIG_FILE, config_text)
            full_meta = {
                "format": FORMAT_VERSION,
                "started_utc": datetime.now(UTC).isoformat(),
                "host": socket.gethostname(),
                "units": {"disp": "mm", "force": "kN", "time": "s"},
                "state": "running",
                "pid": os.getpid(),
                **meta,
            }
            write_private(directory / META_FILE, json.dumps(full_meta, indent=2))
        except OSError as exc:
            raise RecordError(
                exc.errno, f"cannot create run directory under {base_dir}: {exc}"
            ) from exc
        return cls(directory, fsync=fsync, sync_interval=sync_interval)

    @classmethod
    def resume(
        cls, directory: Path, *, fsync: Literal["background", "inline", "off"] = "background",
        sync_interval: float = DEFAULT_SYNC_INTERVAL,
    ) -> RunRecord:
        """Continue the record of an interrupted run: a torn last line is moved aside, the
        sequence numbers and times go on from the last complete line."""
        from .recovery import cut_torn_tail, last_seq_and_time, run_state

        state = run_state(directory)
        if state == "running":
            raise RecordError(f"{directory}: the run is in use by another running bridge")
        if not (directory / RECORD_FILE).is_file():
            raise RecordError(f"{directory}: not a run directory ({RECORD_FILE} is missing)")
        try:
            cut_torn_tail(directory)
            seq, t = last_seq_and_time(directory)
            record = cls(directory, fsync=fsync, sync_interval=sync_interval, seq=seq, t=t)
            directory.chmod(0o700)
            meta = update_meta(directory)
            resumed = list(meta.get("resumed", []))  # type: ignore[call-overload]
            resumed.append({"utc": datetime.now(UTC).isoformat(), "pid": os.getpid(),
                            "after_state": state, "format": FORMAT_VERSION})
            update_meta(directory, state="running", pid=os.getpid(), resumed=resumed)
        except OSError as exc:
            raise RecordError(exc.errno, f"cannot resume run {directory}: {exc}") from exc
        return record

    # -- appending -------------------------------------------------------------------------
    def _line(self, kind: str, site: str, session: int, body: str) -> None:
        self._seq += 1
        self._buf.append(self._enc.line(time.monotonic() - self._t0, kind, site, session, body))

    # trial, measurement and commit are ``_line`` written out: they run several times a step
    def trial(
        self, site: str, session: int, step: int, time_: float, trial: tuple[float, ...],
        ctrl: tuple[float, ...],
    ) -> None:
        enc = self._enc
        self._seq += 1
        self._buf.append(enc.line(time.monotonic() - self._t0, "trial", site, session,
                                  enc.trial(site, session, step, time_, trial, ctrl)))

    def measurement(
        self, site: str, session: int, step: int, disp: tuple[float, ...],
        force: tuple[float, ...],
    ) -> None:
        enc = self._enc
        self._seq += 1
        self._buf.append(enc.line(time.monotonic() - self._t0, "daq", site, session,
                                  enc.daq(site, session, step, disp, force)))

    def commit(self, site: str, session: int, step: int, time_: float) -> None:
        enc = self._enc
        self._seq += 1
        self._buf.append(enc.line(time.monotonic() - self._t0, "commit", site, session,
                                  enc.commit(site, session, step, time_)))
        self.flush(sync=True)

    def event(self, site: str, session: int, kind: str, reason: str, **extra: object) -> None:
        """A state change or fault; written and synced at once so it survives what follows."""
        self._line("event", site, session, self._enc.event(kind, reason, extra))
        self.flush(sync=True, urgent=True)

    def monitor(
        self, site: str, session: int, step: int, tracking_error: float, ti: float,
        nrms: float | None, fei_amplitude: float | None, fei_delay: float | None,
    ) -> None:
        """Online error monitors after committed ``step`` (derived data: buffered, not flushed;
        it goes to the file with the next commit or event)."""
        self._line("monitor", site, session, self._enc.monitor(
            site, session, step, tracking_error, ti, nrms, fei_amplitude, fei_delay))

    # -- durability ------------------------------------------------------------------------
    def flush(self, *, sync: bool = False, urgent: bool = False) -> None:
        if self.closed:
            return
        if self._buf:
            data = "".join(self._buf).encode()
            self._buf.clear()
            try:
                view = memoryview(data)
                while view:
                    n = os.write(self._fd, view)
                    view = view[n:]
            except OSError as exc:
                raise RecordError(exc.errno, f"run record write failed: {exc.strerror}") from exc
        if not sync or self._fsync == "off":
            return
        if self._syncer is not None:
            if self._syncer.error is not None:
                err, self._syncer.error = self._syncer.error, None
                raise RecordError(err.errno, f"run record fdatasync failed: {err.strerror}")
            self._syncer.request(self._seq, urgent)
        else:
            os.fdatasync(self._fd)

    @property
    def lines(self) -> int:
        """Lines appended so far (0: nothing was ever recorded)."""
        return self._seq

    @property
    def syncs(self) -> int:
        """fdatasync calls made by the syncer thread so far (background durability)."""
        return self._syncer.syncs if self._syncer is not None else 0

    @property
    def durable_lines(self) -> int:
        """Lines known to be on disk: covered by a completed fdatasync (background), or every
        line written (inline, after each commit/event)."""
        if self._syncer is not None:
            return self._syncer.durable
        return self._seq if self._fsync == "inline" and not self._buf else 0

    def close(self) -> None:
        if self.closed:
            return
        self.flush()
        if self._syncer is not None:
            self._syncer.stop()
        try:
            os.fdatasync(self._fd)
            update_meta(self.directory, state="closed", ended_utc=datetime.now(UTC).isoformat())
        finally:
            os.close(self._fd)
            self.closed = True
