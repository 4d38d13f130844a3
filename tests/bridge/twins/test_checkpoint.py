"""The learner's checkpoint file: written privately, read back only for the same updaters, and
a resumed history cut exactly after what it holds (or not used when the record is behind)."""

from __future__ import annotations

from pathlib import Path

from fresco_bridge.twins.checkpoint import (
    Checkpoint,
    checkpoint_path,
    history_after,
    load_checkpoint,
    save_checkpoint,
)
from fresco_bridge.twins.worker import LearnerSpec, Message, TwinSpec

SPEC = LearnerSpec("damper", (TwinSpec("t1", "none", {}), TwinSpec("t2", "none", {})))
HISTORY: list[Message] = [
    ("observe", 1, 1, 0.1, 1.0), ("trial", 0, "t1", 0.2, (1, 0)), ("commit", "t1"),
    ("trial", 0, "t2", 0.3, (1, 0)), ("commit", "t2"),
    ("observe", 1, 2, 0.4, 2.0), ("trial", 0, "t1", 0.5, (1, 1)), ("commit", "t1"),
    ("trial", 0, "t2", 0.6, (1, 1)), ("commit", "t2"), ("observe", 1, 3, 0.7, 3.0),
]


def test_a_checkpoint_is_read_back_for_the_same_updaters_only(tmp_path: Path) -> None:
    saved = Checkpoint(2, {"t1": 1, "t2": 1}, 1, b"state")
    save_checkpoint(tmp_path, SPEC, saved)
    path = checkpoint_path(tmp_path, "damper")
    assert path.stat().st_mode & 0o777 == 0o600
    assert load_checkpoint(tmp_path, SPEC) == saved
    other = LearnerSpec("damper", (TwinSpec("t1", "online_ukf", {}), SPEC.twins[1]))
    assert load_checkpoint(tmp_path, other) is None


def test_a_missing_or_corrupted_checkpoint_is_not_used(tmp_path: Path) -> None:
    assert load_checkpoint(tmp_path, SPEC) is None
    save_checkpoint(tmp_path, SPEC, Checkpoint(1, {}, 0, b"x" * 100))
    path = checkpoint_path(tmp_path, "damper")
    path.write_bytes(path.read_bytes()[:60])  # torn (a checkpoint is written atomically)
    assert load_checkpoint(tmp_path, SPEC) is None
    path.write_bytes(b"something else\n")
    assert load_checkpoint(tmp_path, SPEC) is None


def test_the_history_after_a_checkpoint_is_what_it_does_not_hold() -> None:
    after = history_after(HISTORY, Checkpoint(2, {"t1": 1, "t2": 1}, 1, b""))
    assert after == [("trial", 0, "t1", 0.5, (1, 1)), ("commit", "t1"),
                     ("trial", 0, "t2", 0.6, (1, 1)), ("commit", "t2"),
                     ("observe", 1, 3, 0.7, 3.0)]
    assert history_after(HISTORY, Checkpoint(0, {}, 0, b"")) == HISTORY
    # the record ends before the checkpoint (killed between the two writes): not used
    assert history_after(HISTORY, Checkpoint(4, {"t1": 2, "t2": 2}, 2, b"")) is None
    assert history_after(HISTORY, Checkpoint(3, {"t1": 3, "t2": 2}, 2, b"")) is None
