"""The online monitor in batches: when the run record is its only consumer, ``MonitorBatch``
runs it over several committed steps at once and writes one monitors line (format 4). The
record must read back exactly as with ``SiteTaps`` (the monitor fed every step), a warning
must be raised at the commit of the step that trips it (never later), the samples a batch
holds must reach the file before the site's next event, within ``MONITOR_BATCH_STEPS`` steps
and within ``MONITOR_BATCH_DELAY`` s, and the daemon must batch only when nothing else (MQTT,
metrics) needs each step's sample at once.
"""

from __future__ import annotations

import asyncio
import json
import math
from pathlib import Path
from typing import Any

import pytest

from fresco_bridge.config import parse_config
from fresco_bridge.daemon import Bridge
from fresco_bridge.indicators import OnlineMonitor
from fresco_bridge.record import RunRecord, read_record
from fresco_bridge.record.export import monitor_lines
from fresco_bridge.record.lines import FORMAT_VERSION, RecordFormatError, expand
from fresco_bridge.record.site import SiteRecorder
from fresco_bridge.site_output import CommittedStep, SiteNotice
from fresco_bridge.telemetry.schema import SiteStatus
from fresco_bridge.telemetry.taps import MONITOR_BATCH_STEPS, MonitorBatch, SiteTaps
from tests.support.recorded_run import LAB_TOML, raw_lines

LIMIT = 0.05


def monitor() -> OnlineMonitor:
    return OnlineMonitor(0.01, 16, warn_tracking_error=LIMIT)  # FEI every 4 steps


def pairs(n: int) -> list[tuple[float, float]]:
    """Commands and lagging measurements: a few steps at rest (all-zero samples: ``0`` entries),
    then a sine whose lag error crosses ``LIMIT`` now and then (edge-triggered warnings that
    re-arm after the 16-step window)."""
    out = [(0.0, 0.0)] * 3
    for i in range(n - 3):
        lag = 0.2 if (i // 40) % 2 else 0.01
        out.append((math.sin(0.1 * i), math.sin(0.1 * i - lag)))
    return out


class Run:
    """A site's record calls for committed steps, with one listener for the monitors."""

    def __init__(self, root: Path, batched: bool, **batch: Any) -> None:
        self.record = RunRecord.create(root, "s", "", {}, fsync="off")
        self.recorder = SiteRecorder(self.record, "s")
        self.warnings: list[tuple[str, int, int]] = []  # (reason, step named, step committing)
        self.committing = 0
        self.session = 1
        self.listener: MonitorBatch | SiteTaps = (
            MonitorBatch(monitor(), self.recorder, self.warn, **batch) if batched
            else SiteTaps(None, None, self.recorder, monitor(), self.warn))

    def warn(self, reason: str, step: int) -> None:
        self.warnings.append((reason, step, self.committing))
        self.event("monitor-warning", reason, step)

    def event(self, kind: str, reason: str, step: int) -> None:
        notice = SiteNotice("s", self.session, step, 0.0, kind, reason, {"step": step})
        self.recorder.site_event(notice, SiteStatus(site="s", state="RUNNING",
                                                    session=self.session, step=step, time=0.0))

    def step(self, session: int, step: int, cmd: float, meas: float) -> None:
        self.recorder.trial(session, step - 1, 0.01 * step, (cmd,), (cmd,))
        self.recorder.measurement(session, step - 1, (meas,), (2.0 * meas,))
        committed = CommittedStep("s", session, step, 0.01 * step, (cmd,), (cmd,), (meas,),
                                  (2.0 * meas,), "RUNNING")
        self.committing, self.session = step, session
        if isinstance(self.listener, MonitorBatch) and step % 2:  # the site's lean path
            self.recorder.step_values(session, step, 0.01 * step, (cmd,), (meas,))
            self.listener.step_values(session, step, 0.01 * step, (cmd,), (meas,))
            return
        self.recorder.step_committed(committed)
        self.listener.step_committed(committed)

    def lines(self) -> list[dict[str, Any]]:
        """The file's lines, each with the session it is in (written when it changes)."""
        out, session = [], 0
        for line in (self.record.directory / "record.jsonl").read_text().splitlines():
            rec = json.loads(line)
            session = rec.setdefault("session", session)
            out.append(rec)
        return out


def drive(run: Run, sessions: tuple[int, ...] = (150, 70)) -> None:
    for session, n in enumerate(sessions, 1):
        for step, (cmd, meas) in enumerate(pairs(n), 1):
            run.step(session, step, cmd, meas)
        run.event("session-close", "client sent DIE", n)
    run.record.close()


def test_batched_monitors_read_back_as_the_per_step_ones(tmp_path: Path) -> None:
    each, batched = Run(tmp_path / "a", False), Run(tmp_path / "b", True)
    drive(each)
    drive(batched)
    meta = json.loads((batched.record.directory / "run.json").read_text())
    assert meta["format"] == FORMAT_VERSION
    kinds = [r["kind"] for r in batched.lines()]
    assert "monitors" in kinds and "monitor" not in kinds
    assert not any("mon" in r for r in batched.lines() if r["kind"] == "step")
    assert any(v == 0 for r in batched.lines() if r["kind"] == "monitors" for v in r["v"])
    assert any(v != 0 and len(v) == 3 for r in batched.lines() if r["kind"] == "monitors"
               for v in r["v"])
    want, got = monitor_lines(read_record(each.record.directory)), monitor_lines(
        read_record(batched.record.directory))
    assert len(got) == 150 + 70 and [(m.session, m.step) for m in got] == [
        (1, s) for s in range(1, 151)] + [(2, s) for s in range(1, 71)]
    assert repr(got) == repr(want)  # NaN-proof: every value identical
    assert monitor_lines(raw_lines(batched.record.directory)) == got  # docs/run-record.md
    # the warnings: the same, each at the commit of the step it names
    assert len(each.warnings) >= 3
    assert batched.warnings == each.warnings
    assert all(named == committing for _, named, committing in batched.warnings)
    # and every line but the monitors' (and t) as before
    a = [{k: v for k, v in r.items() if k not in ("t", "seq")}
         for r in read_record(each.record.directory) if r["kind"] != "monitor"]
    b = [{k: v for k, v in r.items() if k not in ("t", "seq")}
         for r in read_record(batched.record.directory) if r["kind"] != "monitor"]
    assert a == b


def test_a_batch_reaches_the_file_before_an_event_and_within_its_bound(tmp_path: Path) -> None:
    run = Run(tmp_path, True, delay=1e9)
    steps = pairs(MONITOR_BATCH_STEPS + 5)
    for step, (cmd, meas) in enumerate(steps[:MONITOR_BATCH_STEPS], 1):
        run.step(1, step, cmd * 0.01, meas * 0.01)  # no warning
        held = [r for r in run.lines() if r["kind"] == "monitors"]
        assert held == [] if step < MONITOR_BATCH_STEPS else len(held[0]["v"]) == step
    run.step(1, MONITOR_BATCH_STEPS + 1, 0.0, 0.0)
    run.step(1, MONITOR_BATCH_STEPS + 2, 0.0, 0.0)
    run.event("hold", "operator", MONITOR_BATCH_STEPS + 2)
    kinds = [r["kind"] for r in run.lines()]
    assert kinds[-2:] == ["monitors", "event"]  # the samples before the event that follows them
    assert run.lines()[-2]["step"] == MONITOR_BATCH_STEPS + 1
    run.step(2, 1, 0.0, 0.0)  # another session: its steps are a batch of their own
    run.step(2, 2, 0.0, 0.0)
    run.step(3, 1, 0.0, 0.0)
    run.record.close()
    mons = [(r["session"], r["step"], len(r["v"])) for r in run.lines() if r["kind"] == "monitors"]
    assert mons[-1] == (2, 1, 2)  # the third session's sample is still held...
    run.listener.flush()  # ...until the bridge's close flushes it (after its record: dropped)
    assert [m.session for m in monitor_lines(read_record(run.record.directory))][-1] == 2


def test_the_delay_bound_writes_each_sample_by_the_next_commit(tmp_path: Path) -> None:
    run = Run(tmp_path, True, delay=0.0)
    for step, (cmd, meas) in enumerate(pairs(10), 1):
        run.step(1, step, cmd * 0.01, meas * 0.01)
        mons = [r for r in run.lines() if r["kind"] == "monitors"]
        assert len(mons) == step and mons[-1]["step"] == step and len(mons[-1]["v"]) == 1
    run.record.close()


def test_a_monitor_with_a_rate_warning_is_not_batched(tmp_path: Path) -> None:
    record = RunRecord.create(tmp_path, "s", "", {}, fsync="off")
    with pytest.raises(ValueError, match="warn_ti_rate"):
        MonitorBatch(OnlineMonitor(0.01, 16, warn_ti_rate=1.0), SiteRecorder(record, "s"))
    record.close()


def test_a_monitors_line_relative_to_nothing_is_refused() -> None:
    lines = [{"t": 0.0, "kind": "monitors", "site": "s", "session": 1, "step": 1,
              "v": [[0.5, 0.25, 0.125]]}]
    with pytest.raises(RecordFormatError, match="monitors line"):
        list(expand(lines))
    lines[0]["v"] = [[0.5, 0.25, 0.125, None, None], 0, [0.25, 0.25, 0.125]]
    got = list(expand(lines))
    assert [(r["seq"], r["step"], r["err"], r["fei_amp"]) for r in got] == [
        (1, 1, 0.5, None), (2, 2, 0.5, None), (3, 3, 0.25, None)]


@pytest.mark.parametrize(("telemetry", "batched"), [
    ("", True), ("monitors = false", False), ("metrics_port = 0", False)])
def test_the_bridge_batches_only_for_the_record_alone(
        tmp_path: Path, telemetry: str, batched: bool) -> None:
    text = LAB_TOML.format(name="batch", telemetry=telemetry)

    async def listeners() -> list[str]:
        bridge = Bridge(parse_config(text), text, run_dir=tmp_path / "runs")
        await bridge.start()
        try:
            return [type(x).__name__ for x in bridge.sites["spring"].listeners.steps]
        finally:
            await bridge.close()

    kinds = asyncio.run(listeners())
    assert ("MonitorBatch" in kinds) is batched
    assert ("SiteTaps" in kinds) is (telemetry == "metrics_port = 0")
