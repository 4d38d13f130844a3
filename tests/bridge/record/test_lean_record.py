"""The lean record: format 2 says each value once, and reads back as format 1 did.

A format-1 run made by a bridge that wrote format 1 (``data/format1-run``: 12 Newton steps on a
bilinear spring, monitor lines, a HOLD) is replayed through today's writer: the format-2 file
must read back to exactly the same lines (only ``t`` differs), at well under half the bytes.
The format-1 run itself is read unchanged by ``export``, ``runs show``, ``report`` and the HDF5
export, and a format-1 run resumed by today's bridge reads as one record. Random call sequences
(two sites, several sessions, repeats, NaN/inf) round-trip too.
"""

from __future__ import annotations

import json
import math
import shutil
from pathlib import Path
from typing import Any

import h5py  # type: ignore[import-untyped]
from hypothesis import example, given, settings
from hypothesis import strategies as st

from fresco_bridge.cli import main as cli_main
from fresco_bridge.record import RunRecord, read_record
from fresco_bridge.record.export import committed_steps, monitor_lines
from fresco_bridge.record.lines import LineEncoder

FORMAT1 = Path(__file__).parent / "data" / "format1-run"


def format1_lines() -> list[dict[str, Any]]:
    return [json.loads(line) for line in (FORMAT1 / "record.jsonl").read_text().splitlines()]


def same(a: Any, b: Any) -> bool:
    """Equal values, NaN equal to NaN (the writer writes non-finite values as strings)."""
    if isinstance(a, list) and isinstance(b, list):
        return len(a) == len(b) and all(same(x, y) for x, y in zip(a, b, strict=True))
    if isinstance(a, str) != isinstance(b, str) and all(
            isinstance(x, str | float | int) for x in (a, b)):
        return same(float(a), float(b))
    if isinstance(a, float) and isinstance(b, float) and math.isnan(a) and math.isnan(b):
        return True
    return bool(a == b)


def without_t(rec: dict[str, Any]) -> dict[str, Any]:
    return {k: v for k, v in rec.items() if k != "t"}


def floats(r: dict[str, Any], key: str) -> tuple[float, ...]:
    return tuple(float(v) for v in r[key])


def replay(lines: list[dict[str, Any]], record: RunRecord) -> None:
    """Make the same calls the bridge made to write ``lines`` (format 1)."""
    for r in lines:
        site, session, kind = r["site"], r["session"], r["kind"]
        if kind == "trial":
            record.trial(site, session, r["step"], float(r["time"]), floats(r, "trial"),
                         floats(r, "ctrl"))
        elif kind == "daq":
            record.measurement(site, session, r["step"], floats(r, "disp"), floats(r, "force"))
        elif kind == "commit":
            record.commit(site, session, r["step"], float(r["time"]))
        elif kind == "monitor":
            record.monitor(site, session, r["step"], r["err"], r["ti"], r["nrms"], r["fei_amp"],
                           r["fei_delay"])
        else:
            extra = {k: v for k, v in r.items()
                     if k not in ("seq", "t", "kind", "site", "session", "event", "reason")}
            record.event(site, session, r["event"], r["reason"], **extra)


def test_a_real_format1_record_replayed_in_format2_reads_back_identical(tmp_path: Path) -> None:
    old = format1_lines()
    record = RunRecord.create(tmp_path, "lean", "", {})
    replay(old, record)
    record.close()
    new = list(read_record(record.directory))
    assert len(new) == len(old)
    for a, b in zip(new, old, strict=True):
        assert without_t(a).keys() == without_t(b).keys(), (a, b)
        assert all(same(a[k], b[k]) for k in without_t(b)), (a, b)
    old_size = (FORMAT1 / "record.jsonl").stat().st_size
    new_size = (record.directory / "record.jsonl").stat().st_size
    assert new_size < 0.5 * old_size, (new_size, old_size)
    assert committed_steps(record.directory) == committed_steps(FORMAT1)
    assert monitor_lines(read_record(record.directory)) == monitor_lines(read_record(FORMAT1))


def test_a_repeated_trial_and_measurement_are_one_short_marker_each() -> None:
    enc = LineEncoder()
    first = enc.line(0.5, "trial", "s", 1, enc.trial("s", 1, 3, 0.04, (1.25,), (1.25,)))
    assert first == '{"t":0.500000,"kind":"trial","site":"s","session":1,"step":3,' \
                    '"time":0.04,"trial":[1.25]}\n'
    enc.line(0.5, "daq", "s", 1, enc.daq("s", 1, 3, (1.25,), (12.5,)))
    again = enc.line(0.6, "trial", "s", 1, enc.trial("s", 1, 3, 0.04, (1.25,), (1.25,)))
    assert again == '{"t":0.600000,"kind":"trial"}\n'
    assert enc.line(0.7, "daq", "s", 1, enc.daq("s", 1, 3, (1.25,), (12.5,))) == \
        '{"t":0.700000,"kind":"daq"}\n'
    # a changed ctrl (a limit clamped it) is always written; site/session only on change
    clamped = enc.line(0.8, "trial", "t", 1, enc.trial("t", 1, 0, 0.0, (0.1,), (0.05,)))
    assert '"site":"t"' in clamped and '"ctrl":[0.05]' in clamped
    nan = enc.line(0.9, "daq", "t", 1, enc.daq("t", 1, 0, (math.nan,), (math.inf, -math.inf)))
    assert '"disp":["nan"],"force":["inf","-inf"]' in nan


def test_the_format1_run_reads_unchanged_by_every_reader(tmp_path: Path, capsys: Any) -> None:
    run = tmp_path / "runs" / FORMAT1.name
    shutil.copytree(FORMAT1, run)
    steps = committed_steps(run)
    assert [s.step for s in steps] == list(range(1, 13))
    old = format1_lines()
    commits = [i for i, r in enumerate(old) if r["kind"] == "commit"]
    for s, i in zip(steps, commits, strict=True):  # the trial and daq right before the commit
        trial = next(r for r in reversed(old[:i]) if r["kind"] == "trial")
        daq = next(r for r in reversed(old[:i]) if r["kind"] == "daq")
        assert s.cmd_disp == tuple(trial["ctrl"]) and s.time == trial["time"]
        assert s.meas_disp == tuple(daq["disp"]) and s.meas_force == tuple(daq["force"])

    assert cli_main(["export", str(run), "-o", str(tmp_path / "steps.csv")]) == 0
    rows = (tmp_path / "steps.csv").read_text().splitlines()
    assert rows[0] == ("time,step,site,cmd_disp,meas_disp,meas_force,session,site_kind,"
                       "predicted") and len(rows) == 13
    assert rows[1].split(",")[:6] == [repr(steps[0].time), "1", "spring",
                                     repr(steps[0].cmd_disp[0]), repr(steps[0].meas_disp[0]),
                                     repr(steps[0].meas_force[0])]
    assert cli_main(["runs", "show", run.name, "--runs", str(tmp_path / "runs")]) == 0
    shown = capsys.readouterr().out
    assert "12" in shown and "spring" in shown
    assert cli_main(["report", str(run), "-o", str(tmp_path / "report.html")]) == 0
    assert "spring" in (tmp_path / "report.html").read_text()
    assert cli_main(["export", str(run), "-o", str(tmp_path / "run.h5")]) == 0
    with h5py.File(tmp_path / "run.h5", "r") as f:
        assert list(f["sites/spring/meas_force"][:, 0]) == [s.meas_force[0] for s in steps]


def test_a_format1_run_resumed_today_reads_as_one_record(tmp_path: Path) -> None:
    run = tmp_path / FORMAT1.name
    shutil.copytree(FORMAT1, run)
    record = RunRecord.resume(run)
    record.event("spring", 2, "session-open", "client again", peer="x")
    record.trial("spring", 2, 12, 0.13, (0.5,), (0.5,))
    record.measurement("spring", 2, 12, (0.5,), (5.0,))
    record.trial("spring", 2, 12, 0.13, (0.5,), (0.5,))
    record.measurement("spring", 2, 12, (0.5,), (5.0,))
    record.commit("spring", 2, 13, 0.13)
    record.close()
    lines = list(read_record(run))
    assert [r["seq"] for r in lines] == list(range(1, 107))
    assert '"seq"' not in (run / "record.jsonl").read_text().splitlines()[-1]
    steps = committed_steps(run)
    assert [(s.session, s.step) for s in steps][-2:] == [(1, 12), (2, 13)]
    assert steps[-1].cmd_disp == (0.5,) and steps[-1].meas_force == (5.0,)


CALL = st.one_of(
    st.tuples(st.just("trial"), st.sampled_from([0.0, 0.25, -1.5, 1e-300, math.inf]),
              st.booleans()),
    st.tuples(st.just("daq"), st.sampled_from([0.0, 2.5, math.nan]), st.booleans()),
    st.tuples(st.just("commit"), st.just(0.0), st.booleans()),
    st.tuples(st.just("monitor"), st.sampled_from([0.0, 0.125]), st.booleans()),
    st.tuples(st.just("event"), st.just(0.0), st.booleans()),
    st.tuples(st.just("switch"), st.sampled_from(["a", "b"]), st.booleans()),
)


@settings(max_examples=60, deadline=None)
@given(st.lists(CALL, max_size=40))
@example([("commit", 0.0, False), ("switch", "b", False), ("trial", 0.0, False),
          ("switch", "a", False), ("trial", 0.0, False)])
@example([("switch", "b", False), ("event", 0.0, False), ("switch", "a", False),
          ("trial", 0.0, False), ("switch", "b", False), ("trial", 0.0, False)])
def test_any_call_sequence_reads_back_as_written(tmp_path_factory: Any,
                                                 calls: list[tuple[str, Any, bool]]) -> None:
    """Each site's lines read back in the order they were recorded; a site's trial, daq and
    monitor lines go to the file with its next commit or event (or at close), so across sites
    only commits and events keep the order of the calls."""
    record = RunRecord.create(tmp_path_factory.mktemp("r"), "h", "", {}, fsync="off")
    site, session, step, expected = "a", 1, 0, []
    pending: dict[str, list[dict[str, Any]]] = {}
    for kind, v, flag in calls:
        if kind == "switch":
            site, session = str(v), session + int(flag)
            continue
        if kind == "trial":
            ctrl = (v / 2,) if flag else (v,)
            record.trial(site, session, step, 0.01 * step, (v, 1.0), (*ctrl, 1.0))
            body: dict[str, Any] = {"step": step, "time": 0.01 * step, "trial": [v, 1.0],
                                    "ctrl": [*ctrl, 1.0]}
        elif kind == "daq":
            record.measurement(site, session, step, (v,), (v * 3,) if flag else (v,))
            body = {"step": step, "disp": [v], "force": [v * 3 if flag else v]}
        elif kind == "commit":
            step += 1
            record.commit(site, session, step, 0.01 * step)
            body = {"step": step, "time": 0.01 * step}
        elif kind == "monitor":
            nrms = None if flag else v
            record.monitor(site, session, step, v, 2 * v, nrms, None, 0.5 if flag else None)
            body = {"step": step, "err": v, "ti": 2 * v, "nrms": nrms, "fei_amp": None,
                    "fei_delay": 0.5 if flag else None}
        else:
            record.event(site, session, "note", "why", n=step)
            body = {"event": "note", "reason": "why", "n": step}
        line = {"kind": kind, "site": site, "session": session, **body}
        if kind in ("commit", "event"):
            # the writer's list for a site exists from the site's first trial, daq, monitor or
            # commit (an event only flushes it), and at close the sites' leftovers go out in
            # that order (``RunRecord.close``)
            flushed = pending.setdefault(site, []) if kind == "commit" else pending.get(site, [])
            expected += flushed
            flushed.clear()
            expected.append(line)
        else:
            pending.setdefault(site, []).append(line)
    record.close()
    for lines in pending.values():
        expected += lines
    got = [without_t(r) for r in read_record(record.directory)]
    assert len(got) == len(expected)
    for n, (a, b) in enumerate(zip(got, expected, strict=True), 1):
        b = {"seq": n, **b}
        assert a.keys() == b.keys() and all(same(a[k], b[k]) for k in b), (a, b)
