"""The daemon's /metrics endpoint, scraped over real HTTP after a real run, against the record."""

from __future__ import annotations

import asyncio
import socket
import urllib.request
from pathlib import Path

import pytest
from prometheus_client.parser import text_string_to_metric_families

from fresco_bridge.config import parse_config
from fresco_bridge.daemon import Bridge, BridgeThread
from fresco_bridge.integrator.link import GenericClientLink
from tests.support.bridge import RunningBridge
from tests.support.recorded_run import LAB_TOML, drive, raw_lines, record_run

Samples = dict[tuple[str, tuple[tuple[str, str], ...]], float]


def scrape(port: int) -> Samples:
    with urllib.request.urlopen(f"http://127.0.0.1:{port}/metrics", timeout=5) as reply:
        text = reply.read().decode()
    return {
        (s.name, tuple(sorted(s.labels.items()))): s.value
        for family in text_string_to_metric_families(text)
        for s in family.samples
    }


def _latency_count(values: Samples, action: str) -> float:
    return values.get(("fresco_message_latency_seconds_count",
                       (("action", action), ("site", "spring"))), 0.0)


def test_metrics_scraped_after_a_real_run_match_the_record(tmp_path: Path) -> None:
    def during(bridge: BridgeThread) -> tuple[Samples, int]:
        assert bridge.bridge.metrics_server is not None
        port = bridge.bridge.metrics_server.port
        return scrape(port), port

    steps = 120
    run_dir, (values, port) = record_run(tmp_path, steps, telemetry="metrics_port = 0",
                                         during=during)
    lines = raw_lines(run_dir)
    commits = [r for r in lines if r["kind"] == "commit"]
    events = [r for r in lines if r["kind"] == "event"]
    assert len(commits) == steps
    assert values[("fresco_steps_total", (("site", "spring"),))] == len(commits)
    holds = sum(1 for e in events if e["event"] == "hold")
    assert holds == 1
    assert values[("fresco_holds_total", (("site", "spring"),))] == holds
    for kind in ("session-open", "session-close", "hold"):
        assert values[("fresco_events_total", (("kind", kind), ("site", "spring")))] == sum(
            1 for e in events if e["event"] == kind)
    # one latency sample per message the client sent: steps + the NaN trial, per action
    assert _latency_count(values, "setTrialResponse") == steps + 1
    assert _latency_count(values, "commitState") == steps
    assert _latency_count(values, "getDisp") == steps
    assert _latency_count(values, "getForce") == steps + 1
    assert _latency_count(values, "getInitialStiff") == 1
    lat_sum = values[("fresco_message_latency_seconds_sum",
                      (("action", "getForce"), ("site", "spring")))]
    assert 0 < lat_sum < 5.0
    # the updater histogram exists before any updater runs
    assert values[("fresco_updater_step_seconds_count", ())] == 0
    # monitors were on: one monitor line per committed step, the last one also as gauges
    monitors = [r for r in lines if r["kind"] == "monitor"]
    assert len(monitors) == len(commits)
    last, site = monitors[-1], (("site", "spring"),)
    for gauge, key in (("tracking_error_mm", "err"), ("tracking_indicator", "ti"),
                       ("nrms", "nrms"), ("fei_amplitude", "fei_amp"),
                       ("fei_delay_seconds", "fei_delay")):
        assert values[(f"fresco_monitor_{gauge}", site)] == pytest.approx(last[key]), gauge
    assert last["fei_amp"] is not None  # 120 steps > the 64-step window of the test config
    # the endpoint is gone with the bridge
    with pytest.raises(OSError):
        urllib.request.urlopen(f"http://127.0.0.1:{port}/metrics", timeout=2)


def test_metrics_are_off_by_default_and_monitors_follow_the_config(tmp_path: Path) -> None:
    run_dir, metrics = record_run(tmp_path / "a", 20, telemetry="monitors = false",
                                  hold_at_end=False, during=lambda b: b.bridge.metrics)
    assert metrics is None
    assert not any(r["kind"] == "monitor" for r in raw_lines(run_dir))
    run_dir, _ = record_run(tmp_path / "b", 20, hold_at_end=False)
    assert sum(r["kind"] == "monitor" for r in raw_lines(run_dir)) == 20


def test_a_metrics_port_in_use_fails_start_cleanly(tmp_path: Path) -> None:
    with socket.socket() as busy:
        busy.bind(("127.0.0.1", 0))
        busy.listen()
        port = busy.getsockname()[1]
        toml = LAB_TOML.format(name="busy", telemetry=f"metrics_port = {port}")
        bridge = Bridge(parse_config(toml), toml, run_dir=tmp_path)
        with pytest.raises(OSError, match=f"metrics endpoint 127.0.0.1:{port}"):
            asyncio.run(bridge.start())
        assert bridge.record is not None and bridge.record.closed
        assert not bridge._servers  # listeners closed again


def test_metrics_scraped_during_a_session_follow_the_record(tmp_path: Path) -> None:
    toml = LAB_TOML.format(name="live", telemetry="metrics_port = 0")
    with RunningBridge(toml, tmp_path) as bridge:
        assert bridge.bridge.metrics_server is not None
        port = bridge.bridge.metrics_server.port
        with GenericClientLink("127.0.0.1", bridge.ports["spring"], 1, data_size=1) as link:
            for done in (30, 75):
                drive(link, done - int(scrape(port).get(
                    ("fresco_steps_total", (("site", "spring"),)), 0)))
                link.force()  # answered in order: the last commit has been handled
                values = scrape(port)  # the session is still open
                commits = sum(r["kind"] == "commit" for r in raw_lines(bridge.run_dir))
                assert values[("fresco_steps_total", (("site", "spring"),))] == commits == done
                assert _latency_count(values, "commitState") == done
