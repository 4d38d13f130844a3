"""The resume's one pass over the record (``record/scan.py``): every reader gets every line
once, in order, and the pass says where the record stops as the separate readers did."""

from __future__ import annotations

import shutil
from pathlib import Path
from typing import Any

import pytest

from fresco_bridge.record import RunRecord, read_record
from fresco_bridge.record.recovery import last_commits, last_seq_and_time
from fresco_bridge.record.scan import ResumeScan

FORMAT1 = Path(__file__).parent / "data" / "format1-run"


def test_one_pass_hands_every_reader_the_record_and_where_it_stops(tmp_path: Path) -> None:
    run = tmp_path / FORMAT1.name
    shutil.copytree(FORMAT1, run)
    first = RunRecord.resume(run)  # a format-1 run continued in today's lines
    for step in (13, 14):
        first.trial("spring", 2, step - 1, 0.01 * step, (0.5,), (0.5,))
        first.measurement("spring", 2, step - 1, (0.5,), (5.0,))
        first.commit("spring", 2, step, 0.01 * step)
    first.close()
    seen: list[list[dict[str, Any]]] = [[], []]
    ended: list[int] = []
    scan = ResumeScan(run)
    scan.add(seen[0].append, lambda: ended.append(len(seen[0])))
    scan.add(seen[1].append)
    scan.read()
    assert seen[0] == seen[1] == list(read_record(run)) and ended == [len(seen[0])]
    assert (scan.point.seq, scan.point.t) == last_seq_and_time(run)
    assert scan.last_commits() == last_commits(run)
    with pytest.raises(RuntimeError):
        scan.add(seen[0].append)  # too late: the pass is over
    again = RunRecord.resume(run, read_position=False)
    again.continue_at(scan.point.seq, scan.point.t)
    again.event("spring", 3, "session-open", "client again", peer="x")
    again.close()
    assert [r["seq"] for r in read_record(run)][-1] == scan.point.seq + 1
