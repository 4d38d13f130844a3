"""``fresco-bridge report``: a real recorded run becomes a self-contained HTML report."""

from __future__ import annotations

import base64
import io
import json
import math
import shutil
import subprocess
import sys
from html.parser import HTMLParser
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from matplotlib.image import imread

from fresco_bridge.cli import main as cli_main
from fresco_bridge.demo import run_demo
from fresco_bridge.record import RunRecord
from fresco_bridge.report.html import write_report
from fresco_bridge.runs import RunDirError, load_run
from tests.support.recorded_run import LAB_TOML, raw_lines, record_run, record_sessions

PNG_SIGNATURE = b"\x89PNG\r\n\x1a\n"


class _Report(HTMLParser):
    """Section ids, images, data-key cells and the embedded summary JSON of a report."""

    def __init__(self) -> None:
        super().__init__()
        self.sections: list[str] = []
        self.images: list[tuple[str, bytes]] = []
        self.cells: list[tuple[str, str, str]] = []  # (site, key, text)
        self.events: list[str] = []
        self.text: list[str] = []
        self._site = ""
        self._key: str | None = None
        self._json: bool = False
        self.summary: dict[str, Any] = {}
        self.figures: dict[str, tuple[str, str]] = {}  # overview: key -> (exact value, text)
        self._fig: tuple[str, str] | None = None

    def handle_starttag(self, tag: str, attrs: list[tuple[str, str | None]]) -> None:
        a = dict(attrs)
        if tag == "section" and a.get("id"):
            self.sections.append(str(a["id"]))
        elif tag == "img":
            src = str(a.get("src", ""))
            assert src.startswith("data:image/png;base64,"), "images must be inlined PNG"
            self.images.append((str(a.get("alt")), base64.b64decode(src.split(",", 1)[1])))
        elif tag == "tr":
            self._site = str(a.get("data-site") or "")
            if a.get("data-event"):
                self.events.append(str(a["data-event"]))
        elif tag == "td" and a.get("data-key"):
            self._key = str(a["data-key"])
        elif tag == "span" and a.get("data-key"):
            self._fig = (str(a["data-key"]), str(a.get("data-value", "")))
        elif tag == "script" and a.get("id") == "summary-data":
            self._json = True

    def handle_data(self, data: str) -> None:
        self.text.append(data)
        if self._fig is not None:
            self.figures[self._fig[0]] = (self._fig[1], data)
            self._fig = None
        if self._key is not None:
            self.cells.append((self._site, self._key, data))
            self._key = None
        elif self._json:
            self.summary = json.loads(data)
            self._json = False


def parse(path: Path) -> _Report:
    p = _Report()
    p.feed(path.read_text(encoding="utf-8"))
    return p


@pytest.fixture(scope="module")
def recorded(tmp_path_factory: pytest.TempPathFactory) -> Path:
    run_dir, _ = record_run(tmp_path_factory.mktemp("runs"), 300)
    return run_dir


def test_report_of_a_real_run_has_every_section_and_the_record_numbers(recorded: Path,
                                                                          tmp_path: Path) -> None:
    out = write_report(recorded, tmp_path / "r.html")
    rep = parse(out)
    assert rep.sections == ["overview", "summary", "site-spring", "events", "run", "config"]
    assert [alt for alt, _ in rep.images] == [
        "spring hysteresis", "spring command vs measured", "spring error monitors",
        "spring synchronization subspace"]
    for alt, png in rep.images:
        assert png.startswith(PNG_SIGNATURE), alt
        assert imread(io.BytesIO(png), format="png").shape[0] > 200, alt
    # the numbers, against the record decoded independently
    lines = raw_lines(recorded)
    commits = [r for r in lines if r["kind"] == "commit"]
    trials = {r["step"]: r for r in lines if r["kind"] == "trial"}
    daqs = {r["step"]: r for r in lines if r["kind"] == "daq"}
    steps = [c["step"] - 1 for c in commits]  # trial/daq carry the step before the commit's +1
    cmd = np.array([trials[s]["ctrl"][0] for s in steps])
    meas = np.array([daqs[s]["disp"][0] for s in steps])
    force = np.array([daqs[s]["force"][0] for s in steps])
    site = rep.summary["sites"]["spring"]
    assert site["steps"] == len(commits) == 300
    assert site["holds"] == 1 and site["sessions"] == 1
    (d,) = site["detail"]
    assert d["peak_cmd"] == pytest.approx(np.max(np.abs(cmd)), rel=1e-12)
    assert d["force_max"] == pytest.approx(force.max(), rel=1e-12)
    assert d["force_min"] == pytest.approx(force.min(), rel=1e-12)
    assert d["max_tracking_error"] == pytest.approx(np.max(np.abs(meas - cmd)), abs=1e-12)
    assert d["time_end"] == pytest.approx(3.0)
    cells = {(s, k): v for s, k, v in rep.cells}
    assert cells[("spring", "steps")] == "300"
    assert cells[("spring", "holds")] == "1"
    assert float(cells[("spring", "peak_cmd")]) == pytest.approx(d["peak_cmd"], rel=1e-5)
    # events table: every event line of the record, in order
    assert rep.events == [r["event"] for r in lines if r["kind"] == "event"]
    assert "hold" in rep.events
    text = "".join(rep.text)
    assert 'name = "spring"' in text  # the config snapshot
    assert "non-finite trial" in text  # the HOLD reason


def test_report_of_the_demo_run_via_the_cli(tmp_path: Path, capsys: pytest.CaptureFixture[str]
                                             ) -> None:
    summary = run_demo(duration=6.0, runs=tmp_path)
    run_dir = Path(summary["run_dir"])
    assert cli_main(["report", str(run_dir)]) == 0
    rep = parse(run_dir / "report.html")
    assert "site-damper" in rep.sections and len(rep.images) == 4
    site = rep.summary["sites"]["damper"]
    assert site["steps"] == summary["committed_steps_in_record"]
    (d,) = site["detail"]
    assert d["peak_meas"] == pytest.approx(summary["peak_story_drift_mm"][0], abs=1e-3)
    assert d["force_max"] == pytest.approx(summary["peak_damper_force_kN"][0], abs=1e-3)
    # 601 steps > the 512-step window: the online FEI was recorded and plotted
    assert any(r["kind"] == "monitor" and r["fei_amp"] is not None for r in raw_lines(run_dir))
    assert f"{run_dir / 'report.html'}" in capsys.readouterr().out


def test_indicators_in_the_report_see_a_known_lag(tmp_path: Path) -> None:
    """A record written by the real writer whose measurement lags the command by 3 steps."""
    rec = RunRecord.create(tmp_path, "lag", '[[sites]]\nname = "a"\nport = 0\n',
                           {"sites": ["a"]}, fsync="off")
    dt, lag, n = 0.01, 3, 800
    t = np.arange(n) * dt
    cmd = 4.0 * np.sin(2 * np.pi * 1.0 * t) * np.minimum(1.0, t / 2.0)
    meas = np.concatenate([np.zeros(lag), cmd[:-lag]])
    rec.event("a", 1, "session-open", "client test")
    for i in range(n):
        rec.trial("a", 1, i, float(t[i]), (float(cmd[i]),), (float(cmd[i]),))
        rec.measurement("a", 1, i, (float(meas[i]),), (2.0 * float(meas[i]),))
        rec.commit("a", 1, i + 1, float(t[i]))
    rec.close()
    rep = parse(write_report(rec.directory))
    (d,) = rep.summary["sites"]["a"]["detail"]
    assert d["steps"] == n
    assert d["dt"] == pytest.approx(dt)
    assert d["fei_delay"] == pytest.approx(lag * dt, rel=0.1)
    assert d["xcorr_delay"] == pytest.approx(lag * dt, rel=0.05)
    assert d["ti_final"] < 0  # lag: TI decreases
    assert d["nrms"] == pytest.approx(
        math.sqrt(np.sum((meas - cmd) ** 2) / np.sum(cmd**2)), rel=1e-9)


def test_a_torn_last_line_still_reports(recorded: Path, tmp_path: Path) -> None:
    run_dir = tmp_path / recorded.name
    shutil.copytree(recorded, run_dir)
    record = run_dir / "record.jsonl"
    whole = record.read_text().splitlines()
    with record.open("a") as fh:  # a kill -9 in the middle of a write
        fh.write(whole[-5][: len(whole[-5]) // 2])
    rep = parse(write_report(run_dir))
    assert rep.summary["sites"]["spring"]["steps"] == 300
    assert "torn line" in "".join(rep.text)


def test_bad_run_directories_get_clear_errors(recorded: Path, tmp_path: Path,
                                              capsys: pytest.CaptureFixture[str]) -> None:
    with pytest.raises(RunDirError, match="no such run directory"):
        load_run(tmp_path / "nope")
    empty = tmp_path / "empty"
    empty.mkdir()
    with pytest.raises(RunDirError, match=r"not a run directory: record\.jsonl is missing"):
        load_run(empty)
    corrupt = tmp_path / "corrupt"
    shutil.copytree(recorded, corrupt)
    lines = (corrupt / "record.jsonl").read_text().splitlines(keepends=True)
    lines[10] = "{garbage\n"
    (corrupt / "record.jsonl").write_text("".join(lines))
    with pytest.raises(RunDirError, match=r"record\.jsonl:11: not a JSON record line"):
        load_run(corrupt)
    badmeta = tmp_path / "badmeta"
    shutil.copytree(recorded, badmeta)
    (badmeta / "run.json").write_text("{")
    with pytest.raises(RunDirError, match=r"run\.json: run metadata is not valid JSON"):
        load_run(badmeta)
    assert cli_main(["report", str(corrupt)]) == 2
    err = capsys.readouterr().err
    assert "error:" in err and "record.jsonl:11" in err and not (corrupt / "report.html").exists()


def test_two_sessions_and_two_sites_each_get_their_rows(tmp_path: Path) -> None:
    toml = LAB_TOML.format(name="two", telemetry="") + """
[[sites]]
name = "story2"
port = 0
[sites.controller]
model = "elastic"
params = { k = 4.0 }
"""
    # two integrator sessions on the same site, then one on the other
    run_dir = record_sessions(tmp_path, toml, [("spring", 40), ("spring", 25), ("story2", 30)])
    rep = parse(write_report(run_dir))
    assert rep.sections == ["overview", "summary", "site-spring", "site-story2", "events", "run",
                            "config"]
    assert len(rep.images) == 8
    spring, story2 = rep.summary["sites"]["spring"], rep.summary["sites"]["story2"]
    assert (spring["steps"], spring["sessions"]) == (65, 2)
    assert [(d["session"], d["steps"]) for d in spring["detail"]] == [(1, 40), (2, 25)]
    assert story2["steps"] == 30 and story2["detail"][0]["force_max"] == pytest.approx(
        4.0 * story2["detail"][0]["peak_cmd"], rel=1e-9)


def test_the_daemon_and_cli_never_import_matplotlib_or_h5py() -> None:
    code = ("import sys, fresco_bridge.daemon, fresco_bridge.cli; "
            "print(sorted(m for m in ('matplotlib', 'h5py') if m in sys.modules))")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                         check=True).stdout
    assert out.strip() == "[]"
