"""Prometheus metrics for the daemon, in a registry of its own (never the process-global one).

Hot-path calls (``Counter.inc``, ``Histogram.observe``) are small next to a step; ``for_site``
binds the label children once so the step loop skips label lookups.
Telemetry counters are read from the telemetry's own ``stats`` at scrape time, so there is
a single source of truth for drops.
"""

from __future__ import annotations

import math
import threading
from collections.abc import Callable, Iterator
from dataclasses import dataclass, field
from wsgiref.simple_server import WSGIServer

from prometheus_client import CollectorRegistry, Counter, Gauge, Histogram, start_http_server
from prometheus_client.core import CounterMetricFamily, GaugeMetricFamily, Metric
from prometheus_client.registry import Collector

from fresco_bridge.indicators import MonitorSample
from fresco_bridge.telemetry.base import TelemetryStats
from protocol import (
    Action,
    CommitReceived,
    DaqRequested,
    OpenReceived,
    ReplyRequested,
    SetupReceived,
    TrialReceived,
)

NAMESPACE = "fresco"
# Per-message latency on the bridge: tens of µs in-process, ms over a network controller.
LATENCY_BUCKETS = (25e-6, 50e-6, 100e-6, 250e-6, 500e-6, 1e-3, 2.5e-3, 5e-3, 10e-3, 25e-3,
                   50e-3, 0.1, 0.25, 0.5, 1.0, 2.5, 5.0)
UPDATER_BUCKETS = (1e-4, 5e-4, 1e-3, 5e-3, 0.01, 0.025, 0.05, 0.1, 0.25, 0.5, 1.0, 2.5, 5.0)

__all__ = ["ACTION_NAMES", "LATENCY_BUCKETS", "Metrics", "MetricsServer", "SiteMetrics"]

ACTION_NAMES: dict[Action, str] = {
    Action.OPEN: "open", Action.SETUP: "setup", Action.SET_TRIAL_RESPONSE: "setTrialResponse",
    Action.EXECUTE: "execute", Action.COMMIT_STATE: "commitState",
    Action.GET_DAQ_RESPONSE: "getDaqResponse", Action.GET_DISP: "getDisp",
    Action.GET_VEL: "getVel", Action.GET_ACCEL: "getAccel", Action.GET_FORCE: "getForce",
    Action.GET_TIME: "getTime", Action.GET_INITIAL_STIFF: "getInitialStiff",
    Action.GET_TANGENT_STIFF: "getTangentStiff", Action.GET_DAMP: "getDamp",
    Action.GET_MASS: "getMass", Action.SHUTDOWN: "shutdown", Action.DIE: "DIE",
}
"""The ``action`` label: OpenFresco's ``OF_RemoteTest_<name>`` for each action code."""

# Protocol events that carry their action in their type (element and site protocol alike).
_EVENT_ACTIONS: dict[type, str] = {
    TrialReceived: ACTION_NAMES[Action.SET_TRIAL_RESPONSE],
    CommitReceived: ACTION_NAMES[Action.COMMIT_STATE],
    DaqRequested: ACTION_NAMES[Action.GET_DAQ_RESPONSE],
    OpenReceived: ACTION_NAMES[Action.OPEN],
    SetupReceived: ACTION_NAMES[Action.SETUP],
}


@dataclass(slots=True)
class SiteMetrics:
    """One site's pre-bound metric children for the step loop."""

    site: str
    steps: Counter
    holds: Counter
    _latency: Histogram
    _limits: Counter
    _events: Counter
    _monitor: tuple[Gauge, ...] = ()
    _record_writable: Gauge | None = None
    _correction_gauges: tuple[Gauge, ...] = ()
    _correction: tuple[Gauge, ...] = ()
    _latency_children: dict[str, Histogram] = field(default_factory=dict)
    _limit_children: dict[str, Counter] = field(default_factory=dict)
    _event_children: dict[str, Counter] = field(default_factory=dict)

    def step(self) -> None:
        self.steps.inc()

    def monitor(self, sample: MonitorSample) -> None:
        """The online error monitors after the latest step (NaN where there is no value yet)."""
        nan = math.nan
        for gauge, value in zip(self._monitor, (
                sample.tracking_error, sample.ti, sample.nrms, sample.fei_amplitude,
                sample.fei_delay), strict=True):
            gauge.set(nan if value is None else value)

    def hold(self) -> None:
        self.holds.inc()

    def correction(self, corrections: int, residual: float) -> None:
        """The last trial's displacement correction: corrected commands and residual (mm)."""
        if not self._correction:  # labelled at the first: a site without correction has none
            self._correction = tuple(g.labels(self.site) for g in self._correction_gauges)
        if self._correction:
            self._correction[0].set(corrections)
            self._correction[1].set(residual)

    def record_writable(self, writable: bool) -> None:
        """1: the run record takes this site's commits; 0: it cannot be written (a full disk,
        below ``record.min_free_mb``): the site HOLDs and refuses clients (``ctl status``
        says why)."""
        if self._record_writable is not None:
            self._record_writable.set(1.0 if writable else 0.0)

    def latency(self, action: str, seconds: float) -> None:
        child = self._latency_children.get(action)
        if child is None:
            child = self._latency_children[action] = self._latency.labels(self.site, action)
        child.observe(seconds)

    def limit_event(self, signal: str) -> None:
        child = self._limit_children.get(signal)
        if child is None:
            child = self._limit_children[signal] = self._limits.labels(self.site, signal)
        child.inc()

    def message(self, event: object, seconds: float) -> None:
        """Latency of one handled protocol event, labelled by its action; others are ignored."""
        kind = type(event)
        if kind is ReplyRequested:
            action = ACTION_NAMES.get(event.action)  # type: ignore[attr-defined]
        else:
            action = _EVENT_ACTIONS.get(kind)
        if action is not None:
            self.latency(action, seconds)

    def event(self, kind: str, signal: object = None) -> None:
        """A site event (the run record's ``event`` lines): counted per kind; ``hold`` and
        ``limit*`` kinds also feed ``holds_total`` and ``limit_events_total{signal}``."""
        child = self._event_children.get(kind)
        if child is None:
            child = self._event_children[kind] = self._events.labels(self.site, kind)
        child.inc()
        if kind == "hold":
            self.holds.inc()
        elif kind.startswith("limit"):
            self.limit_event(str(signal) if signal is not None else kind)


class _TelemetryCollector(Collector):
    """Exposes a telemetry's ``stats`` at scrape time (called from the HTTP thread)."""

    def __init__(self, source: Callable[[], TelemetryStats]) -> None:
        self._source = source

    def collect(self) -> Iterator[Metric]:
        s = self._source()
        for name, doc, value in (
            ("telemetry_dropped", "Telemetry messages dropped (queue full or broker down)",
             s.dropped),
            ("telemetry_published", "Telemetry messages published", s.published),
            ("telemetry_reconnects", "Reconnections to the MQTT broker", s.reconnects),
            ("telemetry_commands_rejected", "Inbound MQTT command messages ignored",
             s.commands_rejected),
        ):
            yield CounterMetricFamily(f"{NAMESPACE}_{name}", doc, value=value)
        yield GaugeMetricFamily(f"{NAMESPACE}_telemetry_connected", "1 while connected",
                                value=float(s.connected))
        yield GaugeMetricFamily(f"{NAMESPACE}_telemetry_queued", "Messages waiting to publish",
                                value=s.queued)

    def describe(self) -> Iterator[Metric]:
        return iter(())  # values are only known at scrape time


@dataclass(frozen=True, slots=True)
class MetricsServer:
    """A running /metrics endpoint; ``close()`` stops it."""

    server: WSGIServer
    thread: threading.Thread

    @property
    def port(self) -> int:
        return int(self.server.server_address[1])

    def close(self) -> None:
        self.server.shutdown()
        self.server.server_close()
        self.thread.join(timeout=5.0)


class Metrics:
    """All daemon metrics, prefixed ``fresco_``.

    ``steps_total{site}``, ``message_latency_seconds{site,action}``, ``holds_total{site}``,
    ``limit_events_total{site,signal}``, ``events_total{site,kind}``, ``updater_step_seconds``
    (present, with zero counts, before any updater runs), the online monitors as gauges
    ``monitor_tracking_error_mm{site}``, ``monitor_tracking_indicator``, ``monitor_nrms``,
    ``monitor_fei_amplitude``, ``monitor_fei_delay_seconds``, ``record_writable{site}``,
    ``correction_iterations{site}`` and ``correction_residual_mm{site}`` (sites with
    ``[sites.correction]``, from their first corrected trial) and,
    once ``track_telemetry`` is called, ``telemetry_dropped_total`` and friends.
    """

    def __init__(self, registry: CollectorRegistry | None = None) -> None:
        self.registry = registry if registry is not None else CollectorRegistry(auto_describe=True)
        r = self.registry
        self.steps_total = Counter("steps", "Steps answered per site", ["site"],
                                   namespace=NAMESPACE, registry=r)
        self.message_latency_seconds = Histogram(
            "message_latency_seconds", "Time from request received to reply sent, per action",
            ["site", "action"], namespace=NAMESPACE, registry=r, buckets=LATENCY_BUCKETS)
        self.holds_total = Counter("holds", "Times a site entered HOLD", ["site"],
                                   namespace=NAMESPACE, registry=r)
        self.limit_events_total = Counter("limit_events", "Limit checks that tripped",
                                          ["site", "signal"], namespace=NAMESPACE, registry=r)
        self.monitor_gauges = tuple(
            Gauge(name, doc, ["site"], namespace=NAMESPACE, registry=r) for name, doc in (
                ("monitor_tracking_error_mm", "Online monitor: measured - command, last step"),
                ("monitor_tracking_indicator", "Online monitor: tracking indicator (mm^2)"),
                ("monitor_nrms", "Online monitor: NRMS tracking error since the start"),
                ("monitor_fei_amplitude", "Online monitor: FEI amplitude ratio (window)"),
                ("monitor_fei_delay_seconds", "Online monitor: FEI equivalent delay (window)"),
            ))
        self.record_writable = Gauge(
            "record_writable", "1: the run record takes the site's commits; 0: it cannot be "
            "written (the site HOLDs and refuses clients; ctl status says why)", ["site"],
            namespace=NAMESPACE, registry=r)
        self.correction_gauges = tuple(
            Gauge(name, doc, ["site"], namespace=NAMESPACE, registry=r) for name, doc in (
                ("correction_iterations", "Displacement correction: corrected commands of the "
                 "last trial"),
                ("correction_residual_mm", "Displacement correction: largest |target - "
                 "measured| of the last trial at its end"),
            ))
        self.events_total = Counter("events", "Site events (as in the run record) per kind",
                                    ["site", "kind"], namespace=NAMESPACE, registry=r)
        self.updater_step_seconds = Histogram(
            "updater_step_seconds", "Wall time of one model-updater step",
            namespace=NAMESPACE, registry=r, buckets=UPDATER_BUCKETS)
        self._sites: dict[str, SiteMetrics] = {}
        self._telemetry: _TelemetryCollector | None = None

    def for_site(self, site: str) -> SiteMetrics:
        """Label children bound to ``site`` (created once, then cached)."""
        bound = self._sites.get(site)
        if bound is None:
            bound = SiteMetrics(
                site=site, steps=self.steps_total.labels(site), holds=self.holds_total.labels(site),
                _latency=self.message_latency_seconds, _limits=self.limit_events_total,
                _events=self.events_total,
                _monitor=tuple(g.labels(site) for g in self.monitor_gauges),
                _record_writable=self.record_writable.labels(site),
                _correction_gauges=self.correction_gauges)
            bound.record_writable(True)
            self._sites[site] = bound
        return bound

    def observe_updater_step(self, seconds: float) -> None:
        self.updater_step_seconds.observe(seconds)

    def track_telemetry(self, source: Callable[[], TelemetryStats]) -> None:
        """Export a telemetry's counters, e.g. ``metrics.track_telemetry(lambda: tel.stats)``."""
        if self._telemetry is not None:
            self.registry.unregister(self._telemetry)
        self._telemetry = _TelemetryCollector(source)
        self.registry.register(self._telemetry)

    def start_http_server(self, host: str = "127.0.0.1", port: int = 9464) -> MetricsServer:
        """Serve ``/metrics`` from a daemon thread; ``port=0`` picks a free port."""
        server, thread = start_http_server(port, addr=host, registry=self.registry)
        return MetricsServer(server, thread)
