"""One site's side taps behind the ``Telemetry`` interface: MQTT, Prometheus and the run record.

A site calls ``publish_step`` once per committed step and ``publish_event`` per event; this
fans each call out to whichever taps are on. Each tap is a counter increment, a bounded-queue
append or a buffered record line (flushed with the next commit), so the step loop never waits.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

from fresco_bridge.telemetry.base import NullTelemetry, Telemetry, TelemetryStats
from fresco_bridge.telemetry.schema import SiteEvent, SiteStatus, StepSample

if TYPE_CHECKING:
    from fresco_bridge.record import RunRecord
    from fresco_bridge.telemetry.metrics import SiteMetrics

__all__ = ["SiteTaps"]


class SiteTaps:
    """``Telemetry`` for one site: MQTT (optional), metrics (optional), monitor samples to the
    record (optional). ``run``/``stop``/``stats`` belong to the shared MQTT connection, which
    the bridge drives itself, so here they only delegate."""

    def __init__(
        self,
        mqtt: Telemetry | None,
        metrics: SiteMetrics | None,
        record: RunRecord | None,
    ) -> None:
        self._mqtt = mqtt
        self._metrics = metrics
        self._record = record

    def publish_step(self, sample: StepSample) -> None:
        m = sample.monitor
        if self._metrics is not None:
            self._metrics.step()
            if m is not None:
                self._metrics.monitor(m)
        if m is not None and self._record is not None:
            self._record.monitor(sample.site, sample.session, sample.step, m.tracking_error,
                                 m.ti, m.nrms, m.fei_amplitude, m.fei_delay)
        if self._mqtt is not None:
            self._mqtt.publish_step(sample)

    def publish_status(self, status: SiteStatus) -> None:
        if self._mqtt is not None:
            self._mqtt.publish_status(status)

    def publish_event(self, event: SiteEvent) -> None:
        if self._metrics is not None:
            self._metrics.event(event.kind, event.extra.get("signal"))
        if self._mqtt is not None:
            self._mqtt.publish_event(event)

    async def run(self) -> None:
        """The bridge runs the shared MQTT connection; nothing per site."""

    def stop(self) -> None:
        """See ``run``."""

    @property
    def stats(self) -> TelemetryStats:
        return (self._mqtt or NullTelemetry()).stats
