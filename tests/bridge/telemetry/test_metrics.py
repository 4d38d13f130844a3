"""Prometheus metrics: own registry, scraped over real HTTP."""

from __future__ import annotations

import urllib.request

from prometheus_client import REGISTRY
from prometheus_client.parser import text_string_to_metric_families

from fresco_bridge.telemetry import TelemetryStats
from fresco_bridge.telemetry.metrics import Metrics


def scrape(port: int) -> dict[tuple[str, tuple[tuple[str, str], ...]], float]:
    with urllib.request.urlopen(f"http://127.0.0.1:{port}/metrics", timeout=5) as reply:
        text = reply.read().decode()
    return {
        (s.name, tuple(sorted(s.labels.items()))): s.value
        for family in text_string_to_metric_families(text)
        for s in family.samples
    }


def test_metrics_are_served_from_their_own_registry() -> None:
    metrics = Metrics()
    site = metrics.for_site("s1")
    for _ in range(3):
        site.step()
    site.hold()
    site.limit_event("ctrl_disp")
    site.limit_event("ctrl_disp")
    site.latency("setTrialResponse", 40e-6)
    site.latency("setTrialResponse", 3e-3)
    site.latency("getDaqResponse", 0.2)
    metrics.observe_updater_step(0.02)
    stats = TelemetryStats(published=10, dropped=4, reconnects=1, connected=True, queued=2)
    metrics.track_telemetry(lambda: stats)

    server = metrics.start_http_server("127.0.0.1", 0)
    try:
        values = scrape(server.port)
    finally:
        server.close()

    assert values[("fresco_steps_total", (("site", "s1"),))] == 3
    assert values[("fresco_holds_total", (("site", "s1"),))] == 1
    assert values[("fresco_limit_events_total", (("signal", "ctrl_disp"), ("site", "s1")))] == 2
    lat = (("action", "setTrialResponse"), ("site", "s1"))
    assert values[("fresco_message_latency_seconds_count", lat)] == 2
    assert values[("fresco_message_latency_seconds_bucket", (*lat[:1], ("le", "5e-05"),
                                                              *lat[1:]))] == 1
    assert values[("fresco_updater_step_seconds_count", ())] == 1
    assert values[("fresco_telemetry_dropped_total", ())] == 4
    assert values[("fresco_telemetry_published_total", ())] == 10
    assert values[("fresco_telemetry_connected", ())] == 1
    # nothing leaked into the process-global registry; a second instance does not collide
    assert REGISTRY.get_sample_value("fresco_steps_total", {"site": "s1"}) is None
    Metrics().for_site("s1").step()
