"""The files of a run directory: their names, and how ``run.json`` and the config snapshot are
written (privately, atomically). Shared by the record's writer and the recovery of interrupted
runs, which reads what the writer wrote.
"""

from __future__ import annotations

import json
import os
from pathlib import Path

__all__ = ["CONFIG_FILE", "META_FILE", "RECORD_FILE", "update_meta", "write_private"]

RECORD_FILE = "record.jsonl"
CONFIG_FILE = "config.toml"
META_FILE = "run.json"


def write_private(path: Path, text: str | bytes) -> None:
    """Write ``text`` (str: UTF-8) to ``path`` readable by this user only (0600), atomically:
    a crash leaves the old file or the new one, never a torn one."""
    tmp = path.with_name(f".{path.name}.tmp")
    fd = os.open(tmp, os.O_WRONLY | os.O_CREAT | os.O_TRUNC, 0o600)
    try:
        os.fchmod(fd, 0o600)
        data = text.encode("utf-8") if isinstance(text, str) else text
        view = memoryview(data)
        while view:
            written = os.write(fd, view)  # not inside the slice: mypyc evaluates it twice
            view = view[written:]
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
