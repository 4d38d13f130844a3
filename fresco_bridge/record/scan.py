"""One pass over a resumed run's record, for everyone who needs it.

``serve --resume`` needs the record several times over: the writer where its lines stop
(sequence number and time), the daemon each site's last committed step, each in-process
specimen its commands (``sites/experimental_kind.py``), each learner its source's steps and
twins' trials (``twins/build.py``). Read once per need, a long run's record made the resume
wait for as many passes (BENCHMARKS.md, "Updatable sites"). Here each site kind registers a
reader when its group is built, and the daemon reads the record once, handing every line to
every reader in the record's order, then tells each reader the record has ended.
"""

from __future__ import annotations

from collections.abc import Callable, Collection
from pathlib import Path
from typing import Any

from .export import read_record
from .lines import RecordFormatError
from .recovery import LastCommit, ResumePoint
from .writer import RecordError

__all__ = ["LineReader", "ResumeScan"]

LineReader = Callable[[dict[str, Any]], None]
"""Takes one complete record line (``read_record``'s dict)."""


class ResumeScan:
    """The record of the run being resumed, read once by ``read`` for every reader added
    before."""

    def __init__(self, directory: Path) -> None:
        self.directory = directory
        self._readers: dict[str | None, list[LineReader]] = {}
        self._ends: list[Callable[[], None]] = []
        self._point: ResumePoint | None = None

    def add(self, reader: LineReader, end: Callable[[], None] | None = None, *,
            kinds: Collection[str] | None = None) -> None:
        """``reader`` gets every line of the pass (only those of ``kinds``, if given: most
        lines are of kinds few readers want), ``end`` is called after the last one."""
        if self._point is not None:
            raise RuntimeError("the record was read already: a reader added later sees nothing")
        for kind in (None,) if kinds is None else kinds:
            self._readers.setdefault(kind, []).append(reader)
        if end is not None:
            self._ends.append(end)

    def read(self) -> None:
        """The one pass (a torn last line is skipped; ``RunRecord.resume`` moved it aside
        already). A line no reader can take raises ``RecordError`` naming the record."""
        point = ResumePoint()
        self.add(point.line, kinds=ResumePoint.KINDS)
        every = self._readers.pop(None, [])
        of_kind = {kind: [*readers, *every] for kind, readers in self._readers.items()}
        rec: dict[str, Any] = {}
        try:
            for rec in read_record(self.directory):
                for reader in of_kind.get(rec["kind"], every):
                    reader(rec)
        except (RecordFormatError, KeyError) as exc:  # a reader's own errors are its own
            raise RecordError(f"resuming {self.directory}: the record cannot be read back: "
                              f"{exc}") from exc
        point.last_line(rec)
        self._point = point
        for end in self._ends:
            end()

    @property
    def point(self) -> ResumePoint:
        if self._point is None:
            raise RuntimeError("the record has not been read yet")
        return self._point

    def last_commits(self) -> dict[str, LastCommit]:
        """Per site, the last committed step of the record (after ``read``)."""
        return self.point.last_commits()
