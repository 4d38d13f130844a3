"""One site's telemetry taps and online monitors, as a listener of its committed steps and
events: MQTT, Prometheus and the monitor lines of the run record.

Per committed step: the online monitor's sample (a warning becomes a ``monitor-warning`` event of
the site), the metrics counters, the monitor line (through the site's record writer) and the
MQTT step message. Each is a counter increment, a bounded-queue append or a buffered record line
(flushed with the next commit), so the step loop never waits.
"""

from __future__ import annotations

import time
from collections.abc import Callable
from typing import TYPE_CHECKING

from fresco_bridge.telemetry.base import Telemetry
from fresco_bridge.telemetry.schema import CorrectionSample, SiteEvent, SiteStatus, StepSample

if TYPE_CHECKING:
    from fresco_bridge.indicators import OnlineMonitor
    from fresco_bridge.record.site import SiteRecorder
    from fresco_bridge.site_output import CommittedStep, SiteNotice
    from fresco_bridge.telemetry.metrics import SiteMetrics

__all__ = ["MONITOR_BATCH_DELAY", "MONITOR_BATCH_STEPS", "MonitorBatch", "SiteTaps"]

MONITOR_BATCH_STEPS = 32
"""``MonitorBatch``: at most this many committed steps wait for their monitor sample."""
MONITOR_BATCH_DELAY = 0.05
"""``MonitorBatch``: a step's monitor sample reaches the record at the first commit at least
this many seconds after it (or sooner), as the group commit's default ``sync_interval``: what
``kill -9`` or a power loss can cost of the (derived) monitor lines is of the same order."""
_monotonic = time.monotonic


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
        *,
        predicted: bool = False,
        correction: Callable[[], CorrectionSample | None] | None = None,
    ) -> None:
        """``predicted``: the site is updatable, its measured force is the twin's prediction
        (published as ``predicted_force``); ``correction``: the committed step's displacement
        correction (``Site.correction_sample``), published with the step."""
        self._correction = correction
        self._mqtt = mqtt
        self._predicted = predicted
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
                step.daq_disp, step.daq_force, step.state,
                step.daq_force[0] if self._predicted else None, sample,
                None if self._correction is None else self._correction(),
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


class MonitorBatch:
    """The online monitor of a site when the run record is its only consumer (no MQTT, no
    metrics): a step listener that keeps each committed step's (command, measurement) pair
    and runs the monitor over them in batches, one monitors line (``record/lines.py``, format
    4) per batch.

    Why: per step, the monitor's update, its sample and its share of the step line are a
    visible share of the step loop's CPU, more between the client's context switches
    (BENCHMARKS.md, "Telemetry"); in a batch they run in a warm loop, and a step costs one
    append and three comparisons.

    The same samples, warnings and record values as ``SiteTaps`` (the same ``OnlineMonitor``
    fed the same pairs in the same order). What changes is *when* a sample is computed and
    written:

    - a batch runs at the commit that makes it ``MONITOR_BATCH_STEPS`` long, at the first commit
      ``MONITOR_BATCH_DELAY`` s or more after its first step, before any event of the site is
      recorded (a HOLD, a session's end: ``SiteRecorder.before_event``), when the steps stop
      being consecutive, and at ``flush`` (the bridge's close);
    - **a warning is never delayed**: a step whose tracking error exceeds the monitor's
      ``warn_tracking_error`` (the same comparison ``OnlineMonitor`` makes) runs the batch at
      its own commit, so the ``monitor-warning`` event is raised at that step's commit, as
      ``SiteTaps`` raises it. A monitor with ``warn_ti_rate`` (a rate over the window, not a
      per-step test) is not batched: ``ValueError``.
    """

    def __init__(self, monitor: OnlineMonitor, recorder: SiteRecorder,
                 warn: Callable[[str, int], None] | None = None, *,
                 steps: int = MONITOR_BATCH_STEPS, delay: float = MONITOR_BATCH_DELAY) -> None:
        if monitor.warn_ti_rate is not None:
            raise ValueError("MonitorBatch: a monitor with warn_ti_rate is updated every step "
                             "(SiteTaps)")
        if steps < 1:
            raise ValueError(f"MonitorBatch: steps must be >= 1, got {steps}")
        self._monitor = monitor
        self._recorder = recorder
        self._warn = warn
        self._steps = steps
        self._delay = delay
        self._limit = monitor.warn_tracking_error
        self._pairs: list[tuple[float, float]] = []
        self._session = 0  # of the pending pairs
        self._first = 0  # committed step of the first pending pair
        self._next = 0  # the step the next pair must have to join them
        self._due = 0.0  # monotonic time the pending pairs must be written by (next commit)
        recorder.before_event = self.flush

    def step_committed(self, step: CommittedStep) -> None:
        self.step_values(step.session, step.step, step.time, step.ctrl, step.daq_disp)

    def step_values(self, session: int, step: int, time_: float, ctrl: tuple[float, ...],
                    daq_disp: tuple[float, ...]) -> None:
        """Committed ``step``: its pair joins the batch (``StepValuesListener``)."""
        cmd, meas = ctrl[0], daq_disp[0]
        pairs = self._pairs
        if step != self._next or session != self._session or not pairs:
            self._start(session, step)
            pairs = self._pairs
        pairs.append((cmd, meas))
        self._next = step + 1
        limit = self._limit
        if (len(pairs) >= self._steps or _monotonic() >= self._due
                or (limit is not None and abs(meas - cmd) > limit)):
            self.flush()

    def _start(self, session: int, step: int) -> None:
        """A new batch from committed ``step`` (what is held first: another session's, or steps
        that are not consecutive)."""
        self.flush()
        self._session, self._first, self._due = session, step, _monotonic() + self._delay

    def flush(self) -> None:
        """Run the monitor over the pending pairs and write their monitors line (a warning:
        the samples up to its step first, then the site's event)."""
        pairs = self._pairs
        if not pairs:
            return
        self._pairs = []  # a warning's event comes back here (``before_event``): nothing left
        values, warnings = self._monitor.update_many(pairs)
        session, first, done = self._session, self._first, 0
        warn = self._warn
        if warn is not None:
            for index, warning in warnings:
                self._recorder.monitors(session, first + done, values[done:index + 1])
                done = index + 1
                warn(warning, first + index)
        self._recorder.monitors(session, first + done, values[done:])
