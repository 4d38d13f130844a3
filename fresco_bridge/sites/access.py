"""Who may open a session of a site, and a bounded account of those refused (pure: clock
injected). A site's own: the transports (``server/``) enforce it, the site reports the refusals
(``ctl status``), so it sits with the sites, below the transports.

``Allowlist`` matches a client address against the configured addresses and CIDR networks
(empty = anyone, which the config only allows with ``allow_any_client = true``).
``RejectionLog`` counts every refused connection and decides which ones are logged and
recorded: the first of a burst at once, then at most one summary per ``interval`` with the
number suppressed, so hostile connection churn grows neither the log nor the run record per
connection.
"""

from __future__ import annotations

import ipaddress
import time
from collections.abc import Callable, Iterable
from dataclasses import dataclass

REJECTION_LOG_INTERVAL = 10.0
"""Seconds between two logged (and recorded) refusals of one site; the rest are counted."""


class Allowlist:
    """Client addresses and networks allowed to connect to one site."""

    def __init__(self, entries: Iterable[str]) -> None:
        self.entries = tuple(entries)
        nets = [ipaddress.ip_network(e, strict=False) for e in self.entries]
        self._hosts = frozenset(str(n.network_address) for n in nets if n.num_addresses == 1)
        self._nets = tuple(n for n in nets if n.num_addresses > 1)
        self.any = not self.entries

    def admits(self, host: str) -> bool:
        if self.any or host in self._hosts:
            return True
        if not self._nets:
            return False
        try:
            addr = ipaddress.ip_address(host)
        except ValueError:
            return False
        return any(addr in net for net in self._nets)

    def __str__(self) -> str:
        return "any address" if self.any else ", ".join(self.entries)


@dataclass(frozen=True, slots=True)
class Rejection:
    """A refusal to report now: ``suppressed`` earlier ones were only counted."""

    kind: str
    detail: str
    suppressed: int

    def message(self) -> str:
        more = (f" ({self.suppressed} more refused connection(s) not logged in the last "
                f"{REJECTION_LOG_INTERVAL:g} s)") if self.suppressed else ""
        return f"{self.detail}{more}"


class RejectionLog:
    """Counts refused connections per kind; ``refused`` says when one should be reported."""

    def __init__(self, interval: float = REJECTION_LOG_INTERVAL,
                 clock: Callable[[], float] = time.monotonic) -> None:
        self.interval = interval
        self._clock = clock
        self.counts: dict[str, int] = {}
        self._last_report: float | None = None
        self._suppressed = 0

    @property
    def total(self) -> int:
        return sum(self.counts.values())

    def refused(self, kind: str, detail: str) -> Rejection | None:
        """Count one refusal; a Rejection to log and record, or None (rate limit)."""
        self.counts[kind] = self.counts.get(kind, 0) + 1
        now = self._clock()
        if self._last_report is not None and now - self._last_report < self.interval:
            self._suppressed += 1
            return None
        self._last_report = now
        suppressed, self._suppressed = self._suppressed, 0
        return Rejection(kind, detail, suppressed)
