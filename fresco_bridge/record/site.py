"""One site's writer of the run record: the only code that writes that site's lines.

Trials and measurements are written as they happen (crash safety: what reached the controller
is on record before the answer goes out); committed steps and events arrive as a listener
(``sites/listeners.py``); monitor samples from the telemetry taps; refused connections from
the transport, through the site.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

from .writer import RunRecord

if TYPE_CHECKING:
    from ..indicators import MonitorSample
    from ..sites.listeners import SiteNotice
    from ..steps import CommittedStep
    from ..telemetry.schema import SiteStatus

__all__ = ["SiteRecorder"]


class SiteRecorder:
    """The record lines of site ``site`` (a step and event listener of that site)."""

    __slots__ = ("_record", "site")

    def __init__(self, record: RunRecord, site: str) -> None:
        self._record = record
        self.site = site

    def trial(self, session: int, step: int, time: float, trial: tuple[float, ...],
              ctrl: tuple[float, ...]) -> None:
        self._record.trial(self.site, session, step, time, trial, ctrl)

    def measurement(self, session: int, step: int, disp: tuple[float, ...],
                    force: tuple[float, ...]) -> None:
        self._record.measurement(self.site, session, step, disp, force)

    def step_committed(self, step: CommittedStep) -> None:
        self._record.commit(self.site, step.session, step.step, step.time)

    def site_event(self, notice: SiteNotice, status: SiteStatus) -> None:
        self.event(notice.session, notice.kind, notice.reason, **notice.extra)

    def event(self, session: int, kind: str, reason: str, **extra: object) -> None:
        self._record.event(self.site, session, kind, reason, **extra)

    def monitor(self, session: int, step: int, sample: MonitorSample) -> None:
        self._record.monitor(self.site, session, step, sample.tracking_error, sample.ti,
                             sample.nrms, sample.fei_amplitude, sample.fei_delay)
