"""One site's writer of the run record: the only code that writes that site's lines.

Trials and measurements are recorded as they happen and reach the file with the site's next
commit or event (a committed step is one line, ``record/lines.py``); committed steps and events
arrive as a listener (``sites/listeners.py``; the values: ``site_output.py``); monitor samples
from the telemetry taps (after the commit: they go out with the next one); refused connections
from the transport, through the site.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import TYPE_CHECKING

from .lines import DAQ, MONITOR, TRIAL
from .writer import PENDING_LIMIT, RecordError, RunRecord

if TYPE_CHECKING:
    from ..indicators import MonitorSample
    from ..site_output import CommittedStep, SiteNotice

__all__ = ["SiteRecorder"]


class SiteRecorder:
    """The record lines of site ``site`` (a step and event listener of that site)."""

    __slots__ = ("_commit", "_pending", "_record", "before_event", "failed", "site")

    def __init__(self, record: RunRecord, site: str) -> None:
        self._record = record
        self.site = site
        self.before_event: Callable[[], None] | None = None
        """Called before an event of the site is recorded (the monitor batch writes the
        samples it holds first: ``telemetry.taps.MonitorBatch``)."""
        self.failed: Callable[[RecordError], None] | None = None
        """Told when a line other than a commit could not be written (the site HOLDs)."""
        self._pending = record.pending(site)
        self._commit = record.commit_items

    def trial(self, session: int, step: int, time_: float, trial: tuple[float, ...],
              ctrl: tuple[float, ...]) -> None:
        """A command on its way to the controller (``RunRecord.trial`` without the site's
        lookup: several times a step)."""
        items = self._pending
        items.append((TRIAL, session, step, time_, trial, ctrl))
        if len(items) > PENDING_LIMIT:
            try:
                self._record.trial_overflow(self.site)
            except RecordError as exc:
                self._failed(exc)

    def _failed(self, exc: RecordError) -> None:
        if self.failed is not None:
            self.failed(exc)

    @property
    def failure(self) -> RecordError | None:
        """Why the record cannot take commits now (None: it can)."""
        return self._record.failure

    def check_writable(self) -> RecordError | None:
        """``RunRecord.check_writable``: a new session asks it first."""
        return self._record.check_writable()

    def measurement(self, session: int, step: int, disp: tuple[float, ...],
                    force: tuple[float, ...]) -> None:
        """What the controller measured (``RunRecord.measurement`` without the lookup)."""
        self._pending.append((DAQ, session, step, disp, force))

    def step_committed(self, step: CommittedStep) -> None:
        self._commit(self.site, self._pending, step.session, step.step, step.time)

    def step_values(self, session: int, step: int, time_: float, ctrl: tuple[float, ...],
                    daq_disp: tuple[float, ...]) -> None:
        """``step_committed`` without the ``CommittedStep`` (``StepValuesListener``)."""
        self._commit(self.site, self._pending, session, step, time_)

    def site_event(self, notice: SiteNotice, status: object) -> None:
        """The event (``status``, telemetry's retained message, is not the record's)."""
        if self.before_event is not None:
            self.before_event()
        self.event(notice.session, notice.kind, notice.reason, **notice.extra)

    def event(self, session: int, kind: str, reason: str, **extra: object) -> None:
        try:
            self._record.event(self.site, session, kind, reason, **extra)
        except RecordError as exc:
            self._failed(exc)

    def update(self, session: int, step: int, through: int, seconds: float,
               error: float | None, upto: tuple[int, int] | None = None) -> None:
        """An updatable site's committed ``step``: the source step its answer was learned
        through, the update time of the step and the source's one-step error, and the
        source (session, step) it was learned through when its learner was catching up
        (``RunRecord.update``)."""
        self._record.update(self.site, session, step, through, seconds, error, upto)

    def correction(self, session: int, step: int, target: tuple[float, ...], outcome: str,
                   residual: float,
                   iterations: list[tuple[tuple[float, ...], tuple[float, ...]]]) -> None:
        """A trial's displacement correction ends (``RunRecord.correction``)."""
        try:
            self._record.correction(self.site, session, step, target, outcome, residual,
                                    iterations)
        except RecordError as exc:
            self._failed(exc)

    def monitors(self, session: int, step: int,
                 samples: list[tuple[float, float, float | None, float | None, float | None]]
                 ) -> None:
        """The monitors after committed steps ``step``, ``step + 1``… (a batch: one line,
        written at once; ``RunRecord.monitors``)."""
        try:
            self._record.monitors(self.site, session, step, samples)
        except RecordError as exc:
            self._failed(exc)

    def monitor(self, session: int, step: int, sample: MonitorSample) -> None:
        """The monitors after committed ``step`` (``RunRecord.monitor`` without its frame:
        once a step; the sample's first five fields are the recorded values)."""
        self._pending.append((MONITOR, session, step, sample[:5]))
