"""One site's writer of the run record: the only code that writes that site's lines.

Trials and measurements are recorded as they happen and reach the file with the site's next
commit or event (a committed step is one line, ``record/lines.py``); committed steps and events
arrive as a listener (``sites/listeners.py``); monitor samples from the telemetry taps (after
the commit: they go out with the next one); refused connections from the transport, through
the site.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

from .lines import DAQ, MONITOR, TRIAL
from .writer import PENDING_LIMIT, RunRecord

if TYPE_CHECKING:
    from ..indicators import MonitorSample
    from ..sites.listeners import SiteNotice
    from ..steps import CommittedStep
    from ..telemetry.schema import SiteStatus

__all__ = ["SiteRecorder"]


class SiteRecorder:
    """The record lines of site ``site`` (a step and event listener of that site)."""

    __slots__ = ("_commit", "_pending", "_record", "site")

    def __init__(self, record: RunRecord, site: str) -> None:
        self._record = record
        self.site = site
        self._pending = record.pending(site)
        self._commit = record.commit_items

    def trial(self, session: int, step: int, time_: float, trial: tuple[float, ...],
              ctrl: tuple[float, ...]) -> None:
        """A command on its way to the controller (``RunRecord.trial`` without the site's
        lookup: several times a step)."""
        items = self._pending
        items.append((TRIAL, session, step, time_, trial, ctrl))
        if len(items) > PENDING_LIMIT:
            self._record.trial_overflow(self.site)

    def measurement(self, session: int, step: int, disp: tuple[float, ...],
                    force: tuple[float, ...]) -> None:
        """What the controller measured (``RunRecord.measurement`` without the lookup)."""
        self._pending.append((DAQ, session, step, disp, force))

    def step_committed(self, step: CommittedStep) -> None:
        self._commit(self.site, self._pending, step.session, step.step, step.time)

    def site_event(self, notice: SiteNotice, status: SiteStatus) -> None:
        self.event(notice.session, notice.kind, notice.reason, **notice.extra)

    def event(self, session: int, kind: str, reason: str, **extra: object) -> None:
        self._record.event(self.site, session, kind, reason, **extra)

    def monitor(self, session: int, step: int, sample: MonitorSample) -> None:
        """The monitors after committed ``step`` (``RunRecord.monitor`` without its frame:
        once a step; the sample's first five fields are the recorded values)."""
        self._pending.append((MONITOR, session, step, sample[:5]))
