"""Append-only run record, safe against kill -9 and, within ``sync_interval``, power loss.

One run directory per bridge run: ``config.toml`` (snapshot), ``run.json`` (metadata) and
``record.jsonl`` (one JSON object per line, format in ``record/lines.py``). A site's trials,
measurements and monitor samples wait in memory for its next commit or event; the commit (one
step line) or the event goes to the kernel with one ``write`` before the bridge processes the
next message, so killing the process loses no committed step. ``fdatasync`` makes it durable
against a power loss:

- ``fsync="background"`` (default): group commit, as databases do. A syncer thread runs one
  ``fdatasync`` for every commit written since the last one, at most once per
  ``sync_interval`` (default 50 ms); an event (hold, fault, session change) asks for a sync at
  once. A power loss can cost the commits of the last ``sync_interval`` plus the duration of
  one ``fdatasync`` in flight (BENCHMARKS.md, "Record size and durability", gives the window
  measured); the step loop never waits for the disk.
  ``sync_interval = 0`` syncs after every commit (still off the step loop).
- ``fsync="inline"``: the bridge waits for ``fdatasync`` at every commit and event.
- ``fsync="off"``: the kernel writes back when it likes (30 s on Linux by default).

The run directory is private (0700, files 0600: the record and the config snapshot describe a
lab's test; the snapshot never holds a secret, see ``config_model.redact_config_text``).
``run.json`` says ``state``: ``running`` while a bridge holds the record's ``flock``, ``closed``
after a clean close; a run left ``running`` with no lock holder was interrupted
(``record/recovery.py``), and ``RunRecord.resume`` continues it.

A failed write is a fault of the record, not of the bridge: the bytes of the failed write are
cut off again (no torn line stays behind), ``failure`` says why (path and errno) and the commit
raises ``RecordError``, so the site HOLDs and does not count the step. Free space is checked
on the commit path (``os.statvfs``) about once a second and after each quarter of the headroom
written; below ``min_free_mb`` the record
refuses commits the same way, before the disk is full. ``check_writable`` clears the failure
once the filesystem has its headroom again (a new session asks it first).
"""

from __future__ import annotations

import contextlib
import errno
import fcntl
import json
import os
import socket
import time
from collections import defaultdict
from collections.abc import Sequence
from datetime import UTC, datetime
from pathlib import Path
from typing import Literal

from mypy_extensions import mypyc_attr

from .lines import DAQ, FORMAT_VERSION, MONITOR, TRIAL, Item, LineEncoder
from .recovery import cut_torn_tail, last_seq_and_time, run_state
from .rundir import CONFIG_FILE, META_FILE, RECORD_FILE, update_meta, write_private
from .syncer import Syncer

_monotonic = time.monotonic
_os_write = os.write
_statvfs = os.statvfs

DEFAULT_MIN_FREE_MB = 64
"""Commits stop (the site HOLDs) when the run directory's filesystem has less free space than
this: the HOLD event, the session's end and the log still fit."""
RECOVERY_FREE_MB = 1.0
"""A record that failed takes commits again once this much space is free at least (with
``min_free_mb = 0`` a full disk would otherwise look writable to ``check_writable``)."""
SPACE_CHECK_INTERVAL = 1.0
"""Seconds between two free-space checks on the commit path (one ``statvfs``)."""
SPACE_CHECK_SHARE = 4
"""A check also runs after writing a ``1/SPACE_CHECK_SHARE`` of ``min_free_mb`` (at least
``SPACE_CHECK_MIN_BYTES``): a fast step loop cannot write the headroom away within a second."""
SPACE_CHECK_MIN_BYTES = 64 * 1024
_MIB = 1 << 20

DEFAULT_SYNC_INTERVAL = 0.05
"""Group commit: at most one fdatasync per this many seconds (events sync at once). Why 50 ms,
not 10: every sync wakes the syncer thread several times (timer, GIL hand-offs, three I/O
completions on ext4) on the CPU the step loop runs on; at 10 ms that is a measurable share of
a fast OpenSees step, at 50 ms a fifth of it (BENCHMARKS.md, "Record size and durability")."""
PENDING_LIMIT = 256
"""A site's trials waiting for its commit past this many items are written as format-2 lines
(an integrator iterating for ever without committing neither grows the bridge's memory nor
keeps its trials out of the file)."""


@mypyc_attr(native_class=False)  # mypyc: a native class cannot derive from OSError
class RecordError(OSError):
    """The run record could not be created or written."""


class RunRecord:
    """The record of one bridge run. Not thread-safe: used from the event loop only."""

    def __init__(
        self, directory: Path, *, fsync: Literal["background", "inline", "off"] = "background",
        sync_interval: float = DEFAULT_SYNC_INTERVAL, seq: int = 0, t: float = 0.0,
        min_free_mb: float = DEFAULT_MIN_FREE_MB,
    ) -> None:
        self.directory = directory
        self.path = directory / RECORD_FILE
        self.min_free_mb = min_free_mb
        self.failure: RecordError | None = None
        """Why the record cannot take commits now (None: it can); see ``check_writable``."""
        self._space_due = 0.0  # record time of the next free-space check
        self._unchecked = 0  # bytes written since the last free-space check
        self._space_budget = max(SPACE_CHECK_MIN_BYTES,
                                 int(min_free_mb * _MIB) // SPACE_CHECK_SHARE)
        self._cut_to: int | None = None  # the file's size before a failed write not yet cut
        self._fsync = fsync
        self._seq = seq
        self._buf: list[str] = []
        self._pending: defaultdict[str, list[Item]] = defaultdict(list)
        """Per site, its trials, measurements and monitor samples since its last commit: they
        become one step line at the commit (``LineEncoder.fold``), format-2 lines otherwise."""
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
        self._syncer: Syncer | None = None
        if fsync == "background":
            self._syncer = Syncer(self._fd, sync_interval)
            self._syncer.start()
        self.closed = False
        self.check_writable()

    @classmethod
    def create(
        cls,
        base_dir: Path,
        name: str,
        config_text: str,
        meta: dict[str, object],
        *,
        fsync: Literal["background", "inline", "off"] = "background",
        sync_interval: float = DEFAULT_SYNC_INTERVAL, min_free_mb: float = DEFAULT_MIN_FREE_MB,
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
        return cls(directory, fsync=fsync, sync_interval=sync_interval, min_free_mb=min_free_mb)

    @classmethod
    def resume(
        cls, directory: Path, *, fsync: Literal["background", "inline", "off"] = "background",
        sync_interval: float = DEFAULT_SYNC_INTERVAL, min_free_mb: float = DEFAULT_MIN_FREE_MB,
        read_position: bool = True,
    ) -> RunRecord:
        """Continue the record of an interrupted run: a torn last line is moved aside, the
        sequence numbers and times go on from the last complete line (``read_position``
        False: the caller reads the record and says where with ``continue_at`` before the
        first line is written: ``record/scan.py``)."""
        state = run_state(directory)
        if state == "running":
            raise RecordError(f"{directory}: the run is in use by another running bridge")
        if not (directory / RECORD_FILE).is_file():
            raise RecordError(f"{directory}: not a run directory ({RECORD_FILE} is missing)")
        try:
            cut_torn_tail(directory)
            seq, t = last_seq_and_time(directory) if read_position else (0, 0.0)
            record = cls(directory, fsync=fsync, sync_interval=sync_interval, seq=seq, t=t,
                         min_free_mb=min_free_mb)
            directory.chmod(0o700)
            meta = update_meta(directory)
            resumed = list(meta.get("resumed", []))  # type: ignore[call-overload]
            resumed.append({"utc": datetime.now(UTC).isoformat(), "pid": os.getpid(),
                            "after_state": state, "format": FORMAT_VERSION})
            update_meta(directory, state="running", pid=os.getpid(), resumed=resumed)
        except OSError as exc:
            raise RecordError(exc.errno, f"cannot resume run {directory}: {exc}") from exc
        return record

    def continue_at(self, seq: int, t: float) -> None:
        """A resumed record's lines go on after sequence number ``seq`` and time ``t`` (the
        last line's), set before anything is written."""
        if self._seq or self._buf:
            raise RecordError(f"{self.path}: lines were written before the resume position "
                              "was set")
        self._seq = seq
        self._t0 = time.monotonic() - t

    # -- appending -------------------------------------------------------------------------
    # A site's trials, measurements and monitor samples wait in memory for its next commit or
    # event (as the lines did in the buffer before format 3): nothing reaches the kernel
    # between two commits, and the commit writes them, folded into one step line when they
    # have its shape. So a commit's data is in the kernel before the next message is read.
    def trial(
        self, site: str, session: int, step: int, time_: float, trial: tuple[float, ...],
        ctrl: tuple[float, ...],
    ) -> None:
        items = self._pending[site]
        items.append((TRIAL, session, step, time_, trial, ctrl))
        if len(items) > PENDING_LIMIT:
            self.trial_overflow(site)

    def trial_overflow(self, site: str) -> None:
        """``site``'s trials waited past ``PENDING_LIMIT`` for a commit: written as they are."""
        self._write_pending(site, time.monotonic() - self._t0)
        self.flush()

    def measurement(
        self, site: str, session: int, step: int, disp: tuple[float, ...],
        force: tuple[float, ...],
    ) -> None:
        self._pending[site].append((DAQ, session, step, disp, force))

    def commit(self, site: str, session: int, step: int, time_: float) -> None:
        self.commit_items(site, self._pending[site], session, step, time_)

    def commit_items(self, site: str, items: list[Item], session: int, step: int,
                     time_: float) -> None:
        """Committed ``step`` of ``site`` whose pending items are ``items`` (``pending``):
        one step line, written to the kernel before this returns.

        Once a step: the common case (the items fold into a step line, nothing else waits in
        the buffer) runs as one straight path — fold, encode, one ``write``, a sync request.
        """
        t = _monotonic() - self._t0
        if t >= self._space_due or self._unchecked >= self._space_budget:
            self._check_space(t)
        line = (self._enc.fold(t, site, session, step, time_, items)
                if items and not self._buf and not self.closed and self.failure is None
                else None)
        if line is None:
            self._commit_lines(t, site, items, session, step, time_)
            return
        self._seq += len(items) + 1
        items.clear()
        self._write(line.encode())
        syncer = self._syncer
        if syncer is not None and syncer.error is None:  # the common case, without a frame
            syncer.request(self._seq, False)
        elif self._fsync != "off":
            self._sync(False)

    def _commit_lines(self, t: float, site: str, items: list[Item], session: int, step: int,
                      time_: float) -> None:
        """The general commit: a step line when the items fold (after whatever the buffer
        holds), else format-2 lines and a commit line (the fold changes no state when it
        returns None, so trying it again here is safe). A record that cannot take commits
        raises ``failure`` before anything changes: the items wait for the site's event."""
        if self.failure is not None:
            raise self.failure
        enc = self._enc
        if items:
            line = enc.fold(t, site, session, step, time_, items)
            if line is None:
                self._buf += enc.lines(t, site, items)
                line = enc.line(t, "commit", site, session,
                                enc.commit(site, session, step, time_))
            self._seq += len(items) + 1
            items.clear()
        else:
            line = enc.line(t, "commit", site, session, enc.commit(site, session, step, time_))
            self._seq += 1
        self._buf.append(line)
        self.flush(sync=True)

    def event(self, site: str, session: int, kind: str, reason: str, **extra: object) -> None:
        """A state change or fault; written and synced at once so it survives what follows
        (after the site's pending lines, which it may explain)."""
        t = time.monotonic() - self._t0
        self._write_pending(site, t)
        self._buf.append(self._enc.line(t, "event", site, session,
                                        self._enc.event(kind, reason, extra)))
        self._seq += 1
        self.flush(sync=True, urgent=True)

    def update(self, site: str, session: int, step: int, through: int, seconds: float,
               error: float | None, upto: tuple[int, int] | None = None) -> None:
        """An updatable site's committed ``step`` learned through source step ``through`` in
        ``seconds`` of updating, with the source's one-step ``error`` (derived data, after its
        step line: the next commit or event asks for its sync; the site's pending items wait
        for their commit: the line does not refer to them)."""
        if self.closed:
            return
        t = _monotonic() - self._t0
        self._buf.append(self._enc.line(t, "update", site, session,
                                        self._enc.update(step, through, seconds, error,
                                                         upto)))
        self._seq += 1
        self.flush()

    def correction(self, site: str, session: int, step: int, target: Sequence[float],
                   outcome: str, residual: float,
                   iterations: Sequence[tuple[Sequence[float], Sequence[float]]]) -> None:
        """A trial's displacement correction (format 6: every command reached and what was
        measured there; the commands' own trial/daq lines are the site's pending items and go
        with its next commit or event)."""
        if self.closed:
            return
        t = _monotonic() - self._t0
        self._buf.append(self._enc.line(t, "correction", site, session, self._enc.correction(
            step, target, outcome, residual, iterations)))
        self._seq += 1
        self.flush()

    def monitor(
        self, site: str, session: int, step: int, tracking_error: float, ti: float,
        nrms: float | None, fei_amplitude: float | None, fei_delay: float | None,
    ) -> None:
        """Online error monitors after committed ``step`` (derived data: it goes to the file
        with the site's next commit or event)."""
        self._pending[site].append(
            (MONITOR, session, step, (tracking_error, ti, nrms, fei_amplitude, fei_delay)))

    def monitors(self, site: str, session: int, step: int,
                 samples: list[tuple[float, float, float | None, float | None, float | None]]
                 ) -> None:
        """Online error monitors after committed steps ``step``, ``step + 1``… of ``site``, one
        tuple ``(tracking_error, ti, nrms, fei_amplitude, fei_delay)`` a step (a batch, see
        ``telemetry/taps.py``): one monitors line, written to the kernel at once (the site's
        pending trials and measurements wait for their commit: the line does not refer to
        them). Derived data: the next commit or event asks for its sync."""
        if not samples or self.closed:
            return
        t = _monotonic() - self._t0
        self._buf.append(self._enc.monitors(t, site, session, step, samples))
        self._seq += len(samples)
        self.flush()

    def pending(self, site: str) -> list[Item]:
        """The list ``site``'s pending items wait in (the same list for the record's life)."""
        return self._pending[site]

    def _write_pending(self, site: str, t: float) -> None:
        items = self._pending.get(site)
        if items:
            self._buf += self._enc.lines(t, site, items)
            self._seq += len(items)
            items.clear()

    # -- durability ------------------------------------------------------------------------
    def flush(self, *, sync: bool = False, urgent: bool = False) -> None:
        if self.closed:
            return
        buf = self._buf
        if buf:
            data = (buf[0] if len(buf) == 1 else "".join(buf)).encode()
            buf.clear()
            if not self._cut() and self.failure is not None:  # never after a torn line
                raise self.failure
            self._write(data)
        if sync and self._fsync != "off":
            self._sync(urgent)

    def _write(self, data: bytes) -> None:
        """``data`` to the kernel: one ``write`` (the rest after a short one: a signal, a full
        disk). A failure cuts what this call wrote (no torn line) and raises ``RecordError``."""
        done = 0
        try:
            done = _os_write(self._fd, data)
            if done != len(data):
                view = memoryview(data)
                while done < len(data):
                    done += _os_write(self._fd, view[done:])
        except OSError as exc:
            raise self._write_failed(exc, done) from exc
        self._unchecked += done

    def _write_failed(self, exc: OSError, done: int) -> RecordError:
        """The failure of a write that got ``done`` bytes of its data into the file: they are
        cut off (until they are, nothing more is written: a torn line stays the last one,
        which the readers skip and a resume cuts)."""
        if done:
            with contextlib.suppress(OSError):
                self._cut_to = os.fstat(self._fd).st_size - done
            self._cut()
        return self._fail(RecordError(
            exc.errno, f"run record {self.path} cannot be written: {exc.strerror}"))

    def _cut(self) -> bool:
        """Cut a failed write's bytes off the file (True: nothing is left to cut)."""
        if self._cut_to is None:
            return True
        try:
            os.ftruncate(self._fd, self._cut_to)
        except OSError:
            return False
        self._cut_to = None
        return True

    def _fail(self, error: RecordError) -> RecordError:
        self.failure = error
        return error

    def _check_space(self, t: float) -> None:
        """Raise ``failure`` when the filesystem is below ``min_free_mb`` (once a second, and
        once per ``_space_budget`` bytes written)."""
        self._space_due = t + SPACE_CHECK_INTERVAL
        self._unchecked = 0
        error = self.check_writable()
        if error is not None:
            raise error

    def free_mb(self) -> float:
        """Free space (for an unprivileged process) on the record's filesystem, in MiB."""
        st = _statvfs(self.directory)
        return st.f_bavail * st.f_frsize / _MIB

    def check_writable(self) -> RecordError | None:
        """Why the record cannot take commits now (None: it can). A failure clears when the
        filesystem has its ``min_free_mb`` again (a write that fails again sets it again)."""
        if self.closed:
            return RecordError(f"run record {self.path} is closed")
        try:
            free = self.free_mb()
        except OSError as exc:
            return self._fail(RecordError(
                exc.errno, f"run record {self.path}: free space unknown: {exc.strerror}"))
        if free < self.min_free_mb:
            return self._fail(RecordError(
                errno.ENOSPC, f"run record {self.path}: {free:.1f} MiB free on its filesystem, "
                              f"below record.min_free_mb = {self.min_free_mb:g}"))
        if self.failure is not None and (free < RECOVERY_FREE_MB or not self._cut()):
            return self.failure
        self.failure = None
        return None

    def _sync(self, urgent: bool) -> None:
        """Everything written so far durable: asked of the syncer, or now (inline)."""
        syncer = self._syncer
        if syncer is not None:
            if syncer.error is not None:
                err, syncer.error = syncer.error, None
                raise self._fail(RecordError(
                    err.errno, f"run record {self.path}: fdatasync failed: {err.strerror}"))
            syncer.request(self._seq, urgent)
        else:
            try:
                os.fdatasync(self._fd)
            except OSError as exc:
                raise self._fail(RecordError(exc.errno, f"run record {self.path}: fdatasync "
                                             f"failed: {exc.strerror}")) from exc

    @property
    def lines(self) -> int:
        """Lines written so far, counted as format-1 lines (a step line counts the lines it
        stands for; 0: nothing was ever recorded)."""
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
        t = time.monotonic() - self._t0
        for site in list(self._pending):
            self._write_pending(site, t)
        with contextlib.suppress(RecordError):  # lost with the disk; ``failure`` says why
            self.flush()
        if self._syncer is not None:
            self._syncer.stop()
        try:
            os.fdatasync(self._fd)
            update_meta(self.directory, state="closed", ended_utc=datetime.now(UTC).isoformat())
        finally:
            os.close(self._fd)
            self.closed = True
