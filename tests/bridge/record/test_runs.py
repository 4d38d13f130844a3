"""``fresco-bridge runs list|show|export`` and the ``export`` alias, over real run directories."""

from __future__ import annotations

import json
import shutil
from pathlib import Path

import h5py  # type: ignore[import-untyped]
import numpy as np
import pytest

from fresco_bridge import __version__
from fresco_bridge.cli import main as cli_main
from fresco_bridge.record import export_csv
from fresco_bridge.record.export import committed_steps
from fresco_bridge.runs import RunDirError, list_runs, resolve_run
from tests.support.recorded_run import LAB_TOML, raw_lines, record_run, record_sessions


@pytest.fixture(scope="module")
def runs_root(tmp_path_factory: pytest.TempPathFactory) -> Path:
    root = tmp_path_factory.mktemp("runs")
    record_run(root, 120, name="first")
    record_run(root, 80, name="second", hold_at_end=False)
    (root / "not-a-run").mkdir()  # ignored: no run.json / record.jsonl
    return root


def _run(root: Path, name: str) -> Path:
    (hit,) = [p for p in root.iterdir() if p.name.endswith(f"-{name}")]
    return hit


def test_list_shows_every_run_with_its_counts(runs_root: Path,
                                              capsys: pytest.CaptureFixture[str]) -> None:
    listing = list_runs(runs_root)
    assert [r.name.split("-", 1)[1] for r in listing] == ["first", "second"]
    first, second = listing
    assert (first.steps, first.sessions, first.holds, first.sites) == (120, 1, 1, ["spring"])
    assert (second.steps, second.sessions, second.holds) == (80, 1, 0)
    assert first.size_bytes == sum(p.stat().st_size for p in _run(runs_root, "first").iterdir())
    assert cli_main(["runs", "list", "--runs", str(runs_root)]) == 0
    out = capsys.readouterr().out.splitlines()
    assert out[0].split() == ["run", "started", "(UTC)", "state", "sites", "steps", "sessions",
                              "holds", "size"]
    row = out[1].split()
    assert row[0] == first.name and row[2] == "closed" and row[4:7] == ["120", "1", "1"]
    assert len(out) == 3


OTHER_SITE = """
[[sites]]
name = "other"
port = 0
[sites.controller]
model = "elastic"
params = { k = 5.0 }
"""


def test_list_counts_sessions_per_site(tmp_path: Path, capsys: pytest.CaptureFixture[str]
                                       ) -> None:
    """Two sites with one session each are "1 each", not "2" sessions."""
    toml = LAB_TOML.format(name="two-sites", telemetry="") + OTHER_SITE
    one_each = record_sessions(tmp_path / "runs", toml, [("spring", 5), ("other", 5)])
    uneven = record_sessions(tmp_path / "runs", toml.replace("two-sites", "uneven"),
                             [("spring", 5), ("other", 5), ("spring", 5)])
    by_name = {r.name: r for r in list_runs(tmp_path / "runs")}
    assert by_name[one_each.name].site_sessions == {"spring": 1, "other": 1}
    assert by_name[uneven.name].site_sessions == {"spring": 2, "other": 1}
    assert cli_main(["runs", "list", "--runs", str(tmp_path / "runs")]) == 0
    out = capsys.readouterr().out.splitlines()
    sessions_at = out[0].index("sessions")
    rows = {line.split()[0]: line[sessions_at:].split("  ")[0].strip() for line in out[1:]}
    assert rows == {one_each.name: "1 each", uneven.name: "2,1"}, out


def test_list_reports_a_broken_run_instead_of_failing(runs_root: Path, tmp_path: Path,
                                                      capsys: pytest.CaptureFixture[str]) -> None:
    root = tmp_path / "runs"
    shutil.copytree(_run(runs_root, "first"), root / "20260101T000000-broken")
    (root / "20260101T000000-broken" / "run.json").write_text("[1, 2")
    assert cli_main(["runs", "list", "--runs", str(root)]) == 0
    out = capsys.readouterr().out
    assert "unreadable" in out and "run.json: run metadata is not valid JSON" in out
    assert cli_main(["runs", "list", "--runs", str(tmp_path / "missing")]) == 2
    assert "no such runs directory" in capsys.readouterr().err


def test_show_prints_metadata_and_the_site_summary(runs_root: Path,
                                                   capsys: pytest.CaptureFixture[str]) -> None:
    name = _run(runs_root, "first").name
    assert cli_main(["runs", "show", "--runs", str(runs_root), name[:-3]]) == 0  # a prefix
    out = capsys.readouterr().out
    head = [line.split(maxsplit=1) for line in out.split("\n\n")[0].splitlines()]
    assert head[0] == ["run", str(runs_root / name)]
    # the metadata's values start in one column, whatever the longest key
    starts = {len(line) - len(line.split(maxsplit=1)[1])
              for line in out.split("\n\n")[0].splitlines()}
    assert len(starts) == 1 and ["fresco_bridge", __version__] in head
    assert "site spring: 120 committed step(s), 1 session(s), 1 hold(s), 0 limit event(s)" in out
    assert "session 1 actuator 1: 120 steps" in out and "NRMS" in out and "FEI delay" in out


def test_export_csv_equals_export_csv_and_the_alias(runs_root: Path, tmp_path: Path) -> None:
    run_dir = _run(runs_root, "first")
    export_csv(run_dir, tmp_path / "reference.csv")
    assert cli_main(["runs", "export", str(run_dir), "-o", str(tmp_path / "a.csv")]) == 0
    assert cli_main(["export", str(run_dir), "-o", str(tmp_path / "b.csv")]) == 0
    ref = (tmp_path / "reference.csv").read_bytes()
    assert (tmp_path / "a.csv").read_bytes() == (tmp_path / "b.csv").read_bytes()
    # the commands add each row's site kind, which the record's library leaves to them
    rows = (tmp_path / "a.csv").read_bytes().splitlines()
    assert [r.rsplit(b",", 2)[0] for r in rows] == ref.splitlines() and len(rows) == 121
    assert {tuple(r.rsplit(b",", 2)[1:]) for r in rows} == {(b"site_kind", b"predicted"),
                                                            (b"experimental", b"0")}
    assert cli_main(["export", str(run_dir), "--site", "nope", "-o", str(tmp_path / "c.csv")]
                    ) == 2
    assert not (tmp_path / "c.csv").exists()


def test_export_hdf5_reads_back_equal(runs_root: Path, tmp_path: Path) -> None:
    run_dir = _run(runs_root, "first")
    out = tmp_path / "run.h5"
    assert cli_main(["runs", "export", str(run_dir), "-o", str(out)]) == 0  # format from .h5
    steps = committed_steps(run_dir)
    lines = raw_lines(run_dir)
    with h5py.File(out, "r") as f:
        assert json.loads(f.attrs["run_json"])["sites"] == ["spring"]
        assert 'name = "spring"' in f["config"][()].decode()
        g = f["sites/spring"]
        assert g["cmd_disp"].shape == (120, 1)
        np.testing.assert_array_equal(g["time"][()], [s.time for s in steps])
        np.testing.assert_array_equal(g["step"][()], [s.step for s in steps])
        np.testing.assert_array_equal(g["cmd_disp"][:, 0], [s.cmd_disp[0] for s in steps])
        np.testing.assert_array_equal(g["meas_disp"][:, 0], [s.meas_disp[0] for s in steps])
        np.testing.assert_array_equal(g["meas_force"][:, 0], [s.meas_force[0] for s in steps])
        assert {k: g[k].attrs["units"] for k in ("time", "cmd_disp", "meas_disp", "meas_force")
                } == {"time": "s", "cmd_disp": "mm", "meas_disp": "mm", "meas_force": "kN"}
        mons = [r for r in lines if r["kind"] == "monitor"]
        np.testing.assert_array_equal(g["monitor/tracking_error"][()], [m["err"] for m in mons])
        np.testing.assert_array_equal(g["monitor/ti"][()], [m["ti"] for m in mons])
        fei = g["monitor/fei_amplitude"][()]
        expect = [np.nan if m["fei_amp"] is None else m["fei_amp"] for m in mons]
        np.testing.assert_array_equal(fei, expect)
        assert g["monitor/fei_delay"].attrs["units"] == "s"
        events = [r for r in lines if r["kind"] == "event"]
        assert [k.decode() for k in f["events/kind"][()]] == [e["event"] for e in events]
        assert [int(s) for s in f["events/seq"][()]] == [e["seq"] for e in events]


def test_resolve_run_names_and_errors(runs_root: Path) -> None:
    first = _run(runs_root, "first")
    assert resolve_run(first.name, runs_root) == first
    assert resolve_run(str(first), Path("elsewhere")) == first
    with pytest.raises(RunDirError, match="matches 2 runs"):
        resolve_run(first.name[:4], runs_root)
    with pytest.raises(RunDirError, match="no such run"):
        resolve_run("zzz", runs_root)


def test_an_ambiguous_prefix_says_how_many_runs_it_does_not_list(tmp_path: Path) -> None:
    names = [f"2026120{i}T100000-demo" for i in range(1, 10)]
    for name in names:
        (tmp_path / name).mkdir()
    with pytest.raises(RunDirError) as err:
        resolve_run("2026", tmp_path)
    assert f"matches 9 runs under {tmp_path}: {', '.join(names[:5])} and 4 more" in str(err.value)


def test_default_outputs_are_named_where_they_were_written(
        runs_root: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    run_dir = shutil.copytree(_run(runs_root, "second"), tmp_path / _run(runs_root, "second").name)
    assert cli_main(["export", str(run_dir)]) == 0
    assert cli_main(["report", str(run_dir)]) == 0
    out = capsys.readouterr().out.splitlines()
    assert out == [f"wrote {run_dir / 'steps.csv'}: 80 committed step(s)",
                   f"wrote {run_dir / 'report.html'} (report of {run_dir})"]
    assert (run_dir / "steps.csv").exists() and (run_dir / "report.html").exists()
