"""The telemetry interface the daemon and the sites use, independent of any broker.

``Telemetry`` is what a site calls on its step path; ``NullTelemetry`` (telemetry off) and
``MqttTelemetry`` (``mqtt.py``) provide it. Operator commands are typed here so the control
socket and MQTT hand the same ``OperatorCommand`` to one handler.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from typing import Literal, Protocol, get_args

from fresco_bridge.telemetry.schema import SiteEvent, SiteStatus, StepSample

CommandName = Literal["pause", "resume", "abort"]
COMMANDS: frozenset[str] = frozenset(get_args(CommandName))


class TelemetryConfigError(ValueError):
    """The telemetry configuration is unusable or unsafe (checked at construction)."""


@dataclass(frozen=True, slots=True)
class TelemetryStats:
    """Counters since construction; ``dropped`` counts every message that was not sent.

    ``failures`` counts failed connection attempts and sessions ended by an error.
    """

    published: int
    dropped: int
    reconnects: int
    connected: bool
    queued: int = 0
    failures: int = 0
    commands_accepted: int = 0
    commands_rejected: int = 0


@dataclass(frozen=True, slots=True)
class OperatorCommand:
    """An authenticated operator command for one site, handed to the daemon's handler."""

    site: str
    command: CommandName
    request_id: str | None = None


CommandHandler = Callable[[OperatorCommand], None]


class Telemetry(Protocol):
    """What the daemon calls; ``NullTelemetry`` and ``MqttTelemetry`` both provide it."""

    def publish_step(self, sample: StepSample) -> None: ...
    def publish_status(self, status: SiteStatus) -> None: ...
    def publish_event(self, event: SiteEvent) -> None: ...
    async def run(self) -> None: ...
    def stop(self) -> None: ...
    @property
    def stats(self) -> TelemetryStats: ...


class NullTelemetry:
    """Telemetry off (the default): every call is a no-op and ``run`` returns at once."""

    def publish_step(self, sample: StepSample) -> None:
        """Discard the sample."""

    def publish_status(self, status: SiteStatus) -> None:
        """Discard the status."""

    def publish_event(self, event: SiteEvent) -> None:
        """Discard the event."""

    async def run(self) -> None:
        """Nothing to run."""

    def stop(self) -> None:
        """Nothing to stop."""

    @property
    def stats(self) -> TelemetryStats:
        return TelemetryStats(published=0, dropped=0, reconnects=0, connected=False)
