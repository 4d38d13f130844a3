"""The learner's checkpoint in the run directory: the worker's last snapshot (its updaters
included), so ``serve --resume`` starts a new worker from it and replays only the record after
it, instead of the whole record (ready-after-resume bounded whatever the run's length).

A checkpoint says how much of the run it covers as counts the record can be checked against:
the source's observations and each twin's commits. On resume, the record's history (rebuilt by
``build.RecordedHistory``) is cut after those counts; a checkpoint the record does not
reach (the bridge was killed between the snapshot and the record's write), one written for
other updaters, or an unreadable one is not used: the whole record is replayed, as before.
The file is written privately and atomically (``record.rundir.write_private``), off the event
loop, the latest snapshot winning.
"""

from __future__ import annotations

import asyncio
import contextlib
import hashlib
import logging
import pickle
from collections import Counter
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

from ..record.rundir import write_private
from .worker import LearnerSpec, Message

__all__ = ["Checkpoint", "CheckpointWriter", "checkpoint_path", "history_after",
           "history_counts", "load_checkpoint", "resume_point"]

log = logging.getLogger("fresco_bridge.twins")

MAGIC = b"fresco-bridge learner checkpoint 3\n"
"""The file's first line: a checkpoint of another format is not read (2: ``online_improved``
keeps its do-no-harm errors as running means, which a version-1 state cannot resume; 3: each
twin's background-learning state, ``twins/catchup.py``)."""


@dataclass(frozen=True)
class Checkpoint:
    """A pickled worker state and how much of the run it holds."""

    observed: int
    """The source's observations (``("observe", ...)`` messages) the state holds."""
    commits: dict[str, int]
    """Each twin's commits the state holds."""
    twin_steps: int
    state: bytes
    """The worker's pickled ``LearnerState`` (``worker.LearnerState.handle("snapshot")``)."""


def checkpoint_path(run_dir: Path, source: str) -> Path:
    return run_dir / f"learner-{source}.checkpoint"


def _spec_key(spec: LearnerSpec) -> str:
    """A fingerprint of the updaters (names, options, offline data): a checkpoint of other
    updaters is not restored."""
    return hashlib.sha256(pickle.dumps(spec, pickle.HIGHEST_PROTOCOL)).hexdigest()


def save_checkpoint(run_dir: Path, spec: LearnerSpec, checkpoint: Checkpoint) -> None:
    body = {"spec": _spec_key(spec), "observed": checkpoint.observed,
            "commits": dict(checkpoint.commits), "twin_steps": checkpoint.twin_steps,
            "state": checkpoint.state}
    write_private(checkpoint_path(run_dir, spec.source),
                  MAGIC + pickle.dumps(body, pickle.HIGHEST_PROTOCOL))


def load_checkpoint(run_dir: Path, spec: LearnerSpec) -> Checkpoint | None:
    """The checkpoint the run ``run_dir`` left for ``spec``'s learner; None (with the reason
    logged) when there is none usable."""
    path = checkpoint_path(run_dir, spec.source)
    try:
        data = path.read_bytes()
    except FileNotFoundError:
        return None
    except OSError as exc:
        log.warning("learner of %s: checkpoint %s unreadable (%s); the whole record is "
                    "replayed", spec.source, path, exc)
        return None
    if not data.startswith(MAGIC):
        log.warning("learner of %s: %s is not a checkpoint of this version; the whole record "
                    "is replayed", spec.source, path)
        return None
    try:
        body = pickle.loads(data[len(MAGIC):])  # our own run directory's file (0600)
        checkpoint = Checkpoint(int(body["observed"]), {str(k): int(v) for k, v in
                                                        body["commits"].items()},
                                int(body["twin_steps"]), bytes(body["state"]))
    except Exception as exc:  # a truncated or corrupted pickle raises many kinds
        log.warning("learner of %s: checkpoint %s corrupted (%s); the whole record is "
                    "replayed", spec.source, path, exc)
        return None
    if body["spec"] != _spec_key(spec):
        log.warning("learner of %s: checkpoint %s was written for other updaters or data; the "
                    "whole record is replayed", spec.source, path)
        return None
    return checkpoint


def history_counts(history: Sequence[Message]) -> tuple[int, Counter[str]]:
    """(source observations, each twin's commits) of a learner's history."""
    commits: Counter[str] = Counter()
    observed = 0
    for msg in history:
        if msg[0] == "observe":
            observed += 1
        elif msg[0] == "commit":
            commits[msg[1]] += 1
    return observed, commits


def history_after(history: Sequence[Message], checkpoint: Checkpoint) -> list[Message] | None:
    """``history`` without what ``checkpoint`` holds (its first observations and each twin's
    first committed trials), in order; None if the history does not reach the checkpoint."""
    observed, commits = checkpoint.observed, dict(checkpoint.commits)
    rest: list[Message] = []
    for msg in history:
        if msg[0] == "observe" and observed:
            observed -= 1
            continue
        if msg[0] == "trial" and commits.get(msg[2], 0):
            continue  # the committed trial of a commit the checkpoint holds
        if msg[0] == "commit" and commits.get(msg[1], 0):
            commits[msg[1]] -= 1
            continue
        rest.append(msg)
    return None if observed or any(commits.values()) else rest


def resume_point(source: str, history: Sequence[Message], checkpoint: Checkpoint | None
                 ) -> list[Message] | None:
    """What a worker started from ``checkpoint`` must replay of ``history`` (None: start
    from scratch and replay it all), said in the log."""
    if checkpoint is None:
        return None
    rest = history_after(history, checkpoint)
    if rest is None:
        log.warning("learner of %s: the record ends before the checkpoint of twin step %d "
                    "(killed between the two writes); the whole record is replayed", source,
                    checkpoint.twin_steps)
    else:
        log.info("learner of %s: resumes from its checkpoint of twin step %d and replays %d "
                 "of the record's %d message(s)", source, checkpoint.twin_steps, len(rest),
                 len(history))
    return rest


class CheckpointWriter:
    """Writes a learner's checkpoints into the run directory in a thread, one at a time; a
    checkpoint offered while one is being written replaces any older one still waiting."""

    def __init__(self, run_dir: Path, spec: LearnerSpec) -> None:
        self.run_dir = run_dir
        self.spec = spec
        self.written = 0
        self._waiting: Checkpoint | None = None
        self._task: asyncio.Task[None] | None = None
        self._failed = False

    def offer(self, checkpoint: Checkpoint) -> None:
        self._waiting = checkpoint
        if self._task is None or self._task.done():
            self._task = asyncio.get_running_loop().create_task(
                self._write(), name=f"checkpoint.{self.spec.source}")

    async def _write(self) -> None:
        loop = asyncio.get_running_loop()
        while self._waiting is not None:
            checkpoint, self._waiting = self._waiting, None
            try:
                await loop.run_in_executor(None, save_checkpoint, self.run_dir, self.spec,
                                           checkpoint)
            except OSError as exc:
                if not self._failed:  # once: a resume then replays the whole record
                    log.error("learner of %s: checkpoint not written to %s: %s", self.spec.source,
                              self.run_dir, exc)
                self._failed = True
                continue
            self.written += 1

    async def close(self) -> None:
        """Wait for the checkpoint being written (a clean stop leaves the latest)."""
        if self._task is not None:
            with contextlib.suppress(asyncio.CancelledError):
                await self._task
