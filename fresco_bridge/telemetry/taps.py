"""One site's telemetry taps and online monitors, as a listener of its committed steps and
events: MQTT, Prometheus and the monitor lines of the run record.

Per committed step: the online monitor's sample (a warning becomes a ``monitor-warning`` event of
the site), the metrics counters, the monitor line (through the site's record writer) and the
MQTT step message. Each is a counter increment, a bounded-queue append or a buffered record line
(flushed with the next commit), so the step loop never waits.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import TYPE_CHECKING

from fresco_bridge.telemetry.base import Telemetry
from fresco_bridge.telemetry.schema import SiteEvent, SiteStatus, StepSample

if TYPE_CHECKING:
    from fresco_bridge.indicators import OnlineMonitor
    from fresco_bridge.record.site import SiteRecorder
    from fresco_bridge.sites.listeners import SiteNotice
    from fresco_bridge.steps import CommittedStep
    from fresco_bridge.telemetry.metrics import SiteMetrics

__all__ = ["SiteTaps"]


class SiteTaps:
    """The taps of one site: MQTT (optional), metrics (optional), monitor samples to the record
    (optional), online monitors (optional; ``warn(reason, step)`` raises the site's event)."""

    def __init__(
        self,
        mqtt: Telemetry | None,
        metrics: SiteMetrics | None,
        recorder: SiteRecorder | None,
        monitor: OnlineMonitor | None = None,
        warn: Callable[[str, int], None] | None = None,
    ) -> None:
        self._mqtt = mqtt
        self._metrics = metrics
        self._recorder = recorder
        self._monitor = monitor
        self._warn = warn

    def step_committed(self, step: CommittedStep) -> None:
        sample = None
        if self._monitor is not None:
            sample = self._monitor.update(step.ctrl[0], step.daq_disp[0])
            if sample.warning and self._warn is not None:
                self._warn(sample.warning, step.step)
        if self._metrics is not None:
            self._metrics.step()
            if sample is not None:
                self._metrics.monitor(sample)
        if sample is not None and self._recorder is not None:
            self._recorder.monitor(step.session, step.step, sample)
        if self._mqtt is not None:
            self._mqtt.publish_step(StepSample(
                step.site, step.session, step.step, step.time, step.trial, step.ctrl,
                step.daq_disp, step.daq_force, step.state, None, sample,
            ))

    def site_event(self, notice: SiteNotice, status: SiteStatus) -> None:
        if self._metrics is None and self._mqtt is None:
            return
        event = SiteEvent(
            site=notice.site, kind=notice.kind, reason=notice.reason, session=notice.session,
            step=notice.step, time=notice.time,
            extra={k: v for k, v in notice.extra.items()
                   if isinstance(v, str | int | float | bool)},
        )
        if self._metrics is not None:
            self._metrics.event(event.kind, event.extra.get("signal"))
        if self._mqtt is not None:
            self._mqtt.publish_event(event)
            self._mqtt.publish_status(status)

    def publish_status(self, status: SiteStatus) -> None:
        """The site's status now (when the taps are attached)."""
        if self._mqtt is not None:
            self._mqtt.publish_status(status)
