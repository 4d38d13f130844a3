"""An updatable site's record (format 5): a real bridge run writes an update line after each
committed twin step, and every reader (export, ``runs``, the report with its updating
section) reads it; a format-4 record of an updatable site (no update lines) still reads."""

from __future__ import annotations

import json
import math
import shutil
from pathlib import Path
from typing import Any

import h5py  # type: ignore[import-untyped]
import pytest

from fresco_bridge.cli import main as cli_main
from fresco_bridge.integrator.link import GenericClientLink
from fresco_bridge.record import read_record
from fresco_bridge.record.export import committed_steps
from fresco_bridge.runs import load_run
from protocol import Action
from tests.bridge.twins.test_twin_bridge import TOML
from tests.support.bridge import RunningBridge
from tests.support.recorded_run import raw_lines

FORMAT4 = Path(__file__).parents[1] / "record" / "data" / "format4-twin-run"
"""A run of the updatable site ``twin1`` (updater ``none``, 12 steps) written by the bridge
before format 5: no update lines."""


def _readers(run: Path, tmp_path: Path, capsys: Any) -> str:
    """Export, ``runs show``, ``runs list`` and the report of ``run``; the report's HTML."""
    assert cli_main(["export", str(run), "-o", str(tmp_path / "steps.csv")]) == 0
    assert cli_main(["runs", "show", str(run)]) == 0
    assert cli_main(["runs", "list", "--runs", str(run.parent)]) == 0
    assert "twin1" in capsys.readouterr().out
    assert cli_main(["report", str(run), "-o", str(tmp_path / "report.html")]) == 0
    return (tmp_path / "report.html").read_text()


def test_a_served_twin_records_what_each_step_was_learned_through(tmp_path: Path,
                                                                   capsys: Any) -> None:
    pytest.importorskip("filterpy")
    steps = 30
    with RunningBridge(TOML.replace("[telemetry]\nmetrics_port = 0\n", ""), tmp_path / "runs"
                       ) as bridge, \
            GenericClientLink("127.0.0.1", bridge.ports["damper"], 1) as source, \
            GenericClientLink("127.0.0.1", bridge.ports["twin1"], 1) as twin:
        for i in range(1, steps + 1):
            d = 1.5 * math.sin(i / 4.0)
            source.set_trial((d,), time=0.01 * i)
            source.force()
            twin.set_trial((0.8 * d,), time=0.01 * i)
            twin.force()
            twin.force()  # a repeated request: the same answer, the same update line
            source.commit()
            twin.commit()
        twin.request(Action.GET_DISP)
        source.request(Action.GET_DISP)
        run_dir = bridge.run_dir
    assert json.loads((run_dir / "run.json").read_text())["format"] >= 5  # update lines
    updates = [r for r in read_record(run_dir) if r["kind"] == "update"]
    assert [u["site"] for u in updates] == ["twin1"] * steps
    assert [u["step"] for u in updates] == list(range(1, steps + 1))
    # previous-step: the twin's step k answers from the source's steps through k - 1
    assert [u["through"] for u in updates] == list(range(steps))
    seconds = [u["secs"] for u in updates]
    assert all(math.isfinite(s) and s >= 0.0 for s in seconds)
    assert seconds[0] == 0.0 and all(s > 0.0 for s in seconds[1:])  # the UKF learned each
    assert not any("err" in u for u in updates)  # the UKF makes no one-step prediction
    # each follows its step line; the independent decoder of the rules of docs/run-record.md agrees
    assert [r for r in raw_lines(run_dir) if r["kind"] == "update"] == updates
    kinds = [(r["kind"], r["site"]) for r in read_record(run_dir)]
    for n, (kind, site) in enumerate(kinds):
        if kind == "update":
            assert kinds[n - 1] == ("commit", site)
    run = load_run(run_dir)
    assert run.updates == updates and run.sources() == {"twin1": "damper"}
    assert [s.step for s in committed_steps(run_dir) if s.site == "twin1"] == list(
        range(1, steps + 1))
    report = _readers(run_dir, tmp_path, capsys)
    section = report.split('<section id="updating-twin1">')[1].split("</section>")[0]
    assert "twin1 learns from damper" in section and "data:image/png;base64," in section
    assert f"<th>update lines</th><td class=\"n\">{steps}</td>" in section
    assert cli_main(["export", str(run_dir), "-o", str(tmp_path / "run.h5")]) == 0
    with h5py.File(tmp_path / "run.h5", "r") as f:
        assert list(f["sites/twin1/update/through"][:]) == list(range(steps))
        assert list(f["sites/twin1/update/secs"][:]) == seconds
        assert "update" not in f["sites/damper"]
    assert "no update lines" not in section and "not predicted by this updater" in section


def test_a_format4_record_of_an_updatable_site_still_reads(tmp_path: Path,
                                                           capsys: Any) -> None:
    run = tmp_path / "runs" / FORMAT4.name
    shutil.copytree(FORMAT4, run)
    assert json.loads((run / "run.json").read_text())["format"] == 4
    assert list(read_record(run)) == raw_lines(run)
    steps = committed_steps(run)
    assert [s.step for s in steps if s.site == "twin1"] == list(range(1, 13))
    assert all(s.meas_force[0] == pytest.approx(7.0 * s.meas_disp[0])
               for s in steps if s.site == "twin1")
    assert load_run(run).updates == []
    report = _readers(run, tmp_path, capsys)
    assert '<section id="updating-twin1">' in report
    assert "no update lines" in report
