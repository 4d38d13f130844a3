"""Format 3: a committed step is one line, and reads back as the lines it stands for.

A real format-2 run made by a bridge that wrote format 2 (``data/format2-run``: 40 Newton steps of
four iterations on a bilinear spring, monitor lines with FEI values, a HOLD) is replayed
through today's writer and must read back to exactly the same lines (only ``t`` differs); it
is read unchanged by every reader, and resumed by today's bridge it reads as one record.
Random Newton steps (two sites interleaved, repeats, clamped ctrl, NaN, events inside a step,
monitor samples) round-trip too, and every line a site had pending reaches the file with its
next event or at close.
"""

from __future__ import annotations

import json
import math
import shutil
from pathlib import Path
from typing import Any

import h5py  # type: ignore[import-untyped]
from hypothesis import given, settings
from hypothesis import strategies as st

from fresco_bridge.cli import main as cli_main
from fresco_bridge.record import RunRecord, read_record
from fresco_bridge.record.export import committed_steps, monitor_lines
from fresco_bridge.record.lines import FORMAT_VERSION
from fresco_bridge.record.writer import PENDING_LIMIT
from tests.bridge.record.test_lean_record import replay, same, without_t
from tests.support.recorded_run import raw_lines

FORMAT2 = Path(__file__).parent / "data" / "format2-run"


def file_lines(run: Path) -> list[dict[str, Any]]:
    return [json.loads(line) for line in (run / "record.jsonl").read_text().splitlines()]


def assert_same_lines(got: list[dict[str, Any]], want: list[dict[str, Any]]) -> None:
    assert len(got) == len(want)
    for a, b in zip(got, want, strict=True):
        assert without_t(a).keys() == without_t(b).keys(), (a, b)
        assert all(same(a[k], b[k]) for k in without_t(b)), (a, b)


def test_a_newton_step_is_one_line_with_the_monitor_of_the_step_before(tmp_path: Path) -> None:
    record = RunRecord.create(tmp_path, "s", "", {}, fsync="off")
    record.trial("s", 1, 0, 0.01, (0.0,), (0.0,))  # the first step of a session: format 2
    record.measurement("s", 1, 0, (0.0,), (0.0,))
    record.commit("s", 1, 1, 0.01)
    record.monitor("s", 1, 1, 0.0, 0.0, 0.0, None, None)
    a, b = (0.25,), (0.5,)
    for trial, ctrl, force in ((a, a, (2.5,)), (b, b, (5.0,)), (b, b, (5.0,))):
        record.trial("s", 1, 1, 0.02, trial, ctrl)
        record.measurement("s", 1, 1, trial, force)
    record.commit("s", 1, 2, 0.02)
    record.monitor("s", 1, 2, 0.0, 0.0, 0.0, None, None)
    record.trial("s", 1, 2, 0.03, (0.75,), (0.5,))  # a limit clamped it
    record.measurement("s", 1, 2, (0.5,), (5.0,))
    record.commit("s", 1, 3, 0.03)
    record.monitor("s", 1, 3, 0.125, -1.5, 0.25, 1.01, math.nan)
    record.trial("s", 1, 3, 0.04, (0.75,), (0.5,))
    record.measurement("s", 1, 3, (0.5,), (5.0,))
    record.commit("s", 1, 4, 0.04)
    record.monitor("s", 1, 4, 0.0625, -1.5, 0.25, 1.01, math.nan)  # the FEI pair held
    record.trial("s", 1, 4, 0.05, (0.75,), (0.5,))
    record.measurement("s", 1, 4, (0.5,), (5.0,))
    record.commit("s", 1, 5, 0.05)
    record.close()
    text = (record.directory / "record.jsonl").read_text().splitlines()
    assert [json.loads(line)["kind"] for line in text] == [
        "trial", "daq", "commit", "step", "step", "step", "step"]
    assert '"mon":[0.125,-1.5,0.25,1.01,"nan"]' in text[5]
    assert '"mon":[0.0625,-1.5,0.25],"it":[0]' in text[6]  # NaN is not == NaN: the same object
    assert text[3].endswith('"kind":"step","step":2,"time":0.02,"mon":[0.0,0.0,0.0,null,null],'
                            '"it":[[[0.25],[0.25],[2.5]],[[0.5],[0.5],[5.0]],0]}')
    assert text[4].endswith('"kind":"step","step":3,"time":0.03,"mon":0,'
                            '"it":[[[0.75],0,0,[0.5]]]}')  # disp, force unchanged; ctrl ≠ trial
    lines = list(read_record(record.directory))
    assert [(r["seq"], r["kind"], r["step"]) for r in lines] == [
        (1, "trial", 0), (2, "daq", 0), (3, "commit", 1), (4, "monitor", 1),
        (5, "trial", 1), (6, "daq", 1), (7, "trial", 1), (8, "daq", 1), (9, "trial", 1),
        (10, "daq", 1), (11, "commit", 2), (12, "monitor", 2), (13, "trial", 2), (14, "daq", 2),
        (15, "commit", 3), (16, "monitor", 3), (17, "trial", 3), (18, "daq", 3),
        (19, "commit", 4), (20, "monitor", 4), (21, "trial", 4), (22, "daq", 4),
        (23, "commit", 5)]
    assert lines[8]["trial"] == lines[8]["ctrl"] == [0.5] and lines[9]["force"] == [5.0]
    assert lines[12]["trial"] == [0.75] and lines[12]["ctrl"] == [0.5]
    assert lines[12]["time"] == 0.03 and lines[13]["disp"] == [0.5]
    assert math.isnan(float(lines[15]["fei_delay"])) and lines[15]["fei_amp"] == 1.01
    assert lines[19]["err"] == 0.0625 and lines[19]["fei_amp"] == 1.01
    assert math.isnan(float(lines[19]["fei_delay"]))
    assert_same_lines(lines, raw_lines(record.directory))  # docs/run-record.md, decoded apart
    assert [(s.step, s.cmd_disp, s.meas_force) for s in committed_steps(record.directory)] == [
        (1, (0.0,), (0.0,)), (2, (0.5,), (5.0,)), (3, (0.5,), (5.0,)), (4, (0.5,), (5.0,)),
        (5, (0.5,), (5.0,))]


def test_the_real_format2_run_replayed_in_format3_reads_back_identical(tmp_path: Path) -> None:
    old = list(read_record(FORMAT2))
    assert json.loads((FORMAT2 / "run.json").read_text())["format"] == 2
    assert not any(r["kind"] == "step" for r in file_lines(FORMAT2))
    record = RunRecord.create(tmp_path, "lean", "", {})
    replay(old, record)
    record.close()
    meta = json.loads((record.directory / "run.json").read_text())
    assert meta["format"] == FORMAT_VERSION  # its lines: format 3
    assert_same_lines(list(read_record(record.directory)), old)
    assert_same_lines(raw_lines(record.directory), old)
    kinds = [r["kind"] for r in file_lines(record.directory)]
    assert kinds.count("step") == 39 and kinds.count("commit") == 1  # all but the first step
    new_size = (record.directory / "record.jsonl").stat().st_size
    old_size = (FORMAT2 / "record.jsonl").stat().st_size
    assert new_size < 0.5 * old_size, (new_size, old_size)
    assert committed_steps(record.directory) == committed_steps(FORMAT2)
    assert monitor_lines(read_record(record.directory)) == monitor_lines(read_record(FORMAT2))


def test_the_format2_run_reads_unchanged_by_every_reader(tmp_path: Path, capsys: Any) -> None:
    run = tmp_path / "runs" / FORMAT2.name
    shutil.copytree(FORMAT2, run)
    steps = committed_steps(run)
    assert [s.step for s in steps] == list(range(1, 41))
    lines = raw_lines(run)  # decoded apart from fresco_bridge.record, by docs/run-record.md
    assert_same_lines(list(read_record(run)), lines)
    assert len(monitor_lines(lines)) == 40
    assert sum(m.fei_amplitude is not None for m in monitor_lines(lines)) >= 6
    assert cli_main(["export", str(run), "-o", str(tmp_path / "steps.csv")]) == 0
    rows = (tmp_path / "steps.csv").read_text().splitlines()
    assert len(rows) == 41 and rows[-1].split(",")[1] == "40"
    assert cli_main(["runs", "list", "--runs", str(tmp_path / "runs")]) == 0
    assert " 40 " in capsys.readouterr().out  # the step count, from the raw lines
    assert cli_main(["report", str(run), "-o", str(tmp_path / "report.html")]) == 0
    assert "spring" in (tmp_path / "report.html").read_text()
    assert cli_main(["export", str(run), "-o", str(tmp_path / "run.h5")]) == 0
    with h5py.File(tmp_path / "run.h5", "r") as f:
        assert list(f["sites/spring/meas_force"][:, 0]) == [s.meas_force[0] for s in steps]


def test_a_format2_run_resumed_today_reads_as_one_record(tmp_path: Path, capsys: Any) -> None:
    run = tmp_path / "runs" / FORMAT2.name
    shutil.copytree(FORMAT2, run)
    before = list(read_record(run))
    record = RunRecord.resume(run)
    record.event("spring", 2, "session-open", "client again", peer="x")
    record.trial("spring", 2, 40, 0.41, (0.5,), (0.5,))
    record.measurement("spring", 2, 40, (0.5,), (5.0,))
    record.commit("spring", 2, 41, 0.41)
    for step in (42, 43):
        t = 0.01 * step
        record.trial("spring", 2, step - 1, t, (t,), (t,))
        record.measurement("spring", 2, step - 1, (t,), (10 * t,))
        record.trial("spring", 2, step - 1, t, (t,), (t,))
        record.measurement("spring", 2, step - 1, (t,), (10 * t,))
        record.commit("spring", 2, step, t)
    record.close()
    lines = list(read_record(run))
    assert lines[:len(before)] == before
    assert [r["seq"] for r in lines] == list(range(1, len(before) + 15))
    assert [r["kind"] for r in file_lines(run)][-2:] == ["step", "step"]
    assert_same_lines(lines, raw_lines(run))
    assert [(s.session, s.step, s.meas_force) for s in committed_steps(run)][-3:] == [
        (2, 41, (5.0,)), (2, 42, (4.2,)), (2, 43, (4.3,))]
    assert cli_main(["runs", "list", "--runs", str(tmp_path / "runs")]) == 0
    assert " 43 " in capsys.readouterr().out


def test_a_sites_pending_lines_go_to_the_file_with_its_event_and_at_close(
        tmp_path: Path) -> None:
    record = RunRecord.create(tmp_path, "p", "", {}, fsync="off")
    path = record.directory / "record.jsonl"
    record.trial("a", 1, 0, 0.01, (1.0,), (1.0,))
    record.measurement("a", 1, 0, (1.0,), (10.0,))
    assert path.read_text() == ""  # waits for the site's commit or event, as lines always did
    record.trial("b", 1, 0, 0.01, (2.0,), (2.0,))
    record.event("a", 1, "hold", "limit")  # a's trial and daq before a's event; b still waits
    assert [(r["site"], r["kind"]) for r in read_record(record.directory)] == [
        ("a", "trial"), ("a", "daq"), ("a", "event")]
    record.monitor("a", 1, 0, 0.5, 0.0, None, None, None)
    record.close()
    assert [(r["site"], r["kind"]) for r in read_record(record.directory)][3:] == [
        ("a", "monitor"), ("b", "trial")]  # at close, site by site
    assert record.lines == 5


def test_trials_that_never_commit_go_to_the_file_in_bounded_batches(tmp_path: Path) -> None:
    record = RunRecord.create(tmp_path, "n", "", {}, fsync="off")
    for i in range(2000):  # an integrator iterating without end
        record.trial("s", 1, 0, 0.01, (0.001 * i,), (0.001 * i,))
        record.measurement("s", 1, 0, (0.001 * i,), (0.01 * i,))
        assert len(record.pending("s")) <= PENDING_LIMIT + 1
    written = list(read_record(record.directory))
    assert len(written) >= 2000 - PENDING_LIMIT - 1 and record.lines == len(written)
    trials = [r["trial"] for r in written if r["kind"] == "trial"]
    assert trials == [[0.001 * i] for i in range(len(trials))]  # in order, none lost
    record.trial("s", 1, 0, 0.01, (5.0,), (5.0,))
    record.measurement("s", 1, 0, (5.0,), (50.0,))
    record.commit("s", 1, 1, 0.01)
    record.close()
    assert committed_steps(record.directory)[-1].meas_force == (50.0,)
    assert len(list(read_record(record.directory))) == 4003


@given(st.lists(st.sampled_from(["trial", "daq", "monitor"]), min_size=1, max_size=7))
@settings(max_examples=40, deadline=None)
def test_pending_items_of_any_order_read_back_as_recorded(tmp_path_factory: Any,
                                                          kinds: list[str]) -> None:
    """Whatever order a site's trials, measurements and monitor samples came in (a measurement
    with no trial, two trials in a row, a monitor sample between them), the commit writes them
    as a step line only when they have its shape, and they read back in order."""
    record = RunRecord.create(tmp_path_factory.mktemp("o"), "o", "", {}, fsync="off")
    record.trial("s", 1, 0, 0.01, (0.5,), (0.5,))  # the session's first step: format 2
    record.measurement("s", 1, 0, (0.5,), (5.0,))
    record.commit("s", 1, 1, 0.01)
    expected: list[tuple[str, float | None]] = [("trial", 0.5), ("daq", 0.5), ("commit", None)]
    for i, kind in enumerate(kinds):
        v = 1.0 + i
        if kind == "trial":
            record.trial("s", 1, 1, 0.02, (v,), (v,))
        elif kind == "daq":
            record.measurement("s", 1, 1, (v,), (10 * v,))
        else:
            record.monitor("s", 1, 1, v, 0.0, None, None, None)
        expected.append((kind, v))
    record.commit("s", 1, 2, 0.02)
    record.close()
    expected.append(("commit", None))
    got = [(r["kind"], r["trial"][0] if r["kind"] == "trial" else r["disp"][0]
            if r["kind"] == "daq" else r["err"] if r["kind"] == "monitor" else None)
           for r in read_record(record.directory)]
    assert got == expected
    assert_same_lines(raw_lines(record.directory), list(read_record(record.directory)))


VALUES = st.sampled_from([0.0, 0.25, -1.5, 1e-300, math.inf, math.nan])
ITERATION = st.tuples(VALUES, st.booleans(), VALUES)  # trial, ctrl clamped, force
STEP = st.tuples(
    st.sampled_from(["a", "b"]),
    st.lists(ITERATION, min_size=1, max_size=4),
    st.booleans(),  # a monitor sample after the commit
    st.sampled_from([None, 0, 1, 2]),  # an event before this trial index (then no fold)
    st.integers(1, 64),  # DOFs of the vectors
)


@settings(max_examples=60, deadline=None)
@given(st.lists(STEP, max_size=25))
def test_random_newton_steps_read_back_as_recorded(tmp_path_factory: Any,
                                                   steps: list[Any]) -> None:
    record = RunRecord.create(tmp_path_factory.mktemp("r"), "h", "", {}, fsync="off")
    committed = {"a": 0, "b": 0}
    expected: list[dict[str, Any]] = []
    pending: dict[str, list[dict[str, Any]]] = {}  # in the order sites first had one
    for site, iterations, monitor, event_at, dofs in steps:
        pending.setdefault(site, [])
        n = committed[site]
        t = 0.01 * (n + 1)
        for i, (v, clamp, f) in enumerate(iterations):
            if event_at == i:
                record.event(site, 1, "note", "inside a step", at=i)
                expected += pending[site] + [{"kind": "event", "site": site, "session": 1,
                                              "event": "note", "reason": "inside a step",
                                              "at": i}]
                pending[site] = []
            trial = (v,) * dofs
            ctrl = (v / 2,) * dofs if clamp else trial
            record.trial(site, 1, n, t, trial, ctrl)
            record.measurement(site, 1, n, ctrl, (f,) * dofs)
            pending[site] += [
                {"kind": "trial", "site": site, "session": 1, "step": n, "time": t,
                 "trial": list(trial), "ctrl": list(ctrl)},
                {"kind": "daq", "site": site, "session": 1, "step": n, "disp": list(ctrl),
                 "force": [f] * dofs}]
        committed[site] = n + 1
        record.commit(site, 1, n + 1, t)
        expected += pending[site] + [{"kind": "commit", "site": site, "session": 1,
                                      "step": n + 1, "time": t}]
        pending[site] = []
        if monitor:
            record.monitor(site, 1, n + 1, f, 2 * f, None if clamp else v, 1.0, None)
            pending[site].append({"kind": "monitor", "site": site, "session": 1, "step": n + 1,
                                  "err": f, "ti": 2 * f, "nrms": None if clamp else v,
                                  "fei_amp": 1.0, "fei_delay": None})
    record.close()
    for lines in pending.values():  # written at close
        expected += lines
    got = list(read_record(record.directory))
    assert_same_lines(got, [{"seq": n, **e} for n, e in enumerate(expected, 1)])
    assert_same_lines(raw_lines(record.directory), got)
