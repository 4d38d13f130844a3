"""Append-only run record, safe against kill -9 and (with fsync) power loss.

One run directory per bridge run: ``config.toml`` (snapshot), ``run.json`` (metadata) and
``record.jsonl`` (one JSON object per line, with a sequence number and a monotonic
timestamp). Lines are buffered in memory between commits; at each commit (and at every
event) the buffer goes to the kernel with one ``write`` before the bridge processes the next
message, so killing the process loses no committed step. ``fdatasync`` then makes it durable:
``fsync="inline"`` waits for it at each commit, ``fsync="background"`` (default) hands it to
a syncer thread that syncs once per commit (coalescing commits that arrive while a sync is
running), which keeps the ~80 µs disk flush off the step loop.
"""

from __future__ import annotations

import json
import math
import os
import socket
import threading
import time
from collections.abc import Iterable
from datetime import UTC, datetime
from pathlib import Path
from typing import Literal

RECORD_FILE = "record.jsonl"
CONFIG_FILE = "config.toml"
META_FILE = "run.json"
FORMAT_VERSION = 1


class RecordError(OSError):
    """The run record could not be created or written."""


def _nums(values: Iterable[float]) -> str:
    """JSON array of floats; non-finite values (rejected commands) become strings."""
    parts = []
    for v in values:
        if math.isfinite(v):
            parts.append(repr(float(v)))
        else:
            parts.append(f'"{v}"')
    return "[" + ",".join(parts) + "]"


class _Syncer(threading.Thread):
    """Calls fdatasync once per request; requests arriving during a sync are coalesced."""

    def __init__(self, fd: int) -> None:
        super().__init__(name="fresco-record-sync", daemon=True)
        self._fd = fd
        self._wanted = threading.Event()
        self._stopping = False
        self.syncs = 0
        self.error: OSError | None = None

    def request(self) -> None:
        self._wanted.set()

    def run(self) -> None:
        while True:
            self._wanted.wait()
            self._wanted.clear()
            if self._stopping:
                return
            try:
                os.fdatasync(self._fd)
                self.syncs += 1
            except OSError as exc:  # reported at close and on the next flush
                self.error = exc

    def stop(self) -> None:
        self._stopping = True
        self._wanted.set()
        self.join(timeout=5.0)


class RunRecord:
    """The record of one bridge run. Not thread-safe: used from the event loop only."""

    def __init__(
        self, directory: Path, *, fsync: Literal["background", "inline", "off"] = "background"
    ) -> None:
        self.directory = directory
        self._fsync = fsync
        self._seq = 0
        self._buf: list[str] = []
        self._t0 = time.monotonic()
        path = directory / RECORD_FILE
        try:
            self._fd = os.open(path, os.O_WRONLY | os.O_CREAT | os.O_APPEND, 0o644)
        except OSError as exc:
            raise RecordError(exc.errno, f"cannot open run record {path}: {exc.strerror}") from exc
        self._syncer: _Syncer | None = None
        if fsync == "background":
            self._syncer = _Syncer(self._fd)
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
    ) -> RunRecord:
        """Make ``base_dir/<UTC timestamp>-<name>/`` with the config snapshot and metadata."""
        stamp = datetime.now(UTC).strftime("%Y%m%dT%H%M%S")
        try:
            base_dir.mkdir(parents=True, exist_ok=True)
            directory = base_dir / f"{stamp}-{name}"
            suffix = 1
            while directory.exists():
                suffix += 1
                directory = base_dir / f"{stamp}-{name}-{suffix}"
            directory.mkdir()
            (directory / CONFIG_FILE).write_text(config_text, encoding="utf-8")
            full_meta = {
                "format": FORMAT_VERSION,
                "started_utc": datetime.now(UTC).isoformat(),
                "host": socket.gethostname(),
                "units": {"disp": "mm", "force": "kN", "time": "s"},
                **meta,
            }
            (directory / META_FILE).write_text(json.dumps(full_meta, indent=2), encoding="utf-8")
        except OSError as exc:
            raise RecordError(
                exc.errno, f"cannot create run directory under {base_dir}: {exc}"
            ) from exc
        return cls(directory, fsync=fsync)

    # -- appending -------------------------------------------------------------------------
    def _line(self, kind: str, site: str, session: int, body: str) -> None:
        self._seq += 1
        t = time.monotonic() - self._t0
        self._buf.append(
            f'{{"seq":{self._seq},"t":{t:.6f},"kind":"{kind}","site":"{site}",'
            f'"session":{session}{body}}}\n'
        )

    def trial(
        self, site: str, session: int, step: int, time_: float, trial: tuple[float, ...],
        ctrl: tuple[float, ...],
    ) -> None:
        self._line(
            "trial", site, session,
            f',"step":{step},"time":{_num(time_)},"trial":{_nums(trial)},"ctrl":{_nums(ctrl)}',
        )

    def measurement(
        self, site: str, session: int, step: int, disp: tuple[float, ...],
        force: tuple[float, ...],
    ) -> None:
        self._line(
            "daq", site, session, f',"step":{step},"disp":{_nums(disp)},"force":{_nums(force)}'
        )

    def commit(self, site: str, session: int, step: int, time_: float) -> None:
        self._line("commit", site, session, f',"step":{step},"time":{_num(time_)}')
        self.flush(sync=True)

    def event(self, site: str, session: int, kind: str, reason: str, **extra: object) -> None:
        """A state change or fault; flushed at once so it survives whatever follows."""
        body = "," + json.dumps({"event": kind, "reason": reason, **extra})[1:-1]
        self._line("event", site, session, body)
        self.flush(sync=True)

    def monitor(
        self, site: str, session: int, step: int, tracking_error: float, ti: float,
        nrms: float | None, fei_amplitude: float | None, fei_delay: float | None,
    ) -> None:
        """Online error monitors after committed ``step`` (derived data: buffered, not flushed;
        it goes to the file with the next commit or event)."""
        self._line(
            "monitor", site, session,
            f',"step":{step},"err":{_num(tracking_error)},"ti":{_num(ti)},'
            f'"nrms":{_opt(nrms)},"fei_amp":{_opt(fei_amplitude)},"fei_delay":{_opt(fei_delay)}',
        )

    # -- durability ------------------------------------------------------------------------
    def flush(self, *, sync: bool = False) -> None:
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
            self._syncer.request()
        else:
            os.fdatasync(self._fd)

    @property
    def lines(self) -> int:
        """Lines appended so far (0: nothing was ever recorded)."""
        return self._seq

    @property
    def syncs(self) -> int:
        return self._syncer.syncs if self._syncer is not None else 0

    def close(self) -> None:
        if self.closed:
            return
        self.flush()
        if self._syncer is not None:
            self._syncer.stop()
        try:
            os.fdatasync(self._fd)
        finally:
            os.close(self._fd)
            self.closed = True


def _num(v: float) -> str:
    return repr(float(v)) if math.isfinite(v) else f'"{v}"'


def _opt(v: float | None) -> str:
    return "null" if v is None else _num(v)
