"""Side taps of the step loop: MQTT telemetry, Prometheus metrics, message schema.

Nothing here is on the critical path: the step loop only appends to bounded queues and
increments counters. ``NullTelemetry`` is the default; see README.md for topics and payloads.
"""

from fresco_bridge.telemetry.base import (
    CommandHandler,
    NullTelemetry,
    OperatorCommand,
    Telemetry,
    TelemetryConfigError,
    TelemetryStats,
)
from fresco_bridge.telemetry.mqtt import MqttTelemetry
from fresco_bridge.telemetry.schema import (
    SCHEMA_VERSION,
    SiteEvent,
    SiteStatus,
    StepSample,
    TelemetrySchemaError,
)

__all__ = [
    "SCHEMA_VERSION",
    "CommandHandler",
    "MqttTelemetry",
    "NullTelemetry",
    "OperatorCommand",
    "SiteEvent",
    "SiteStatus",
    "StepSample",
    "Telemetry",
    "TelemetryConfigError",
    "TelemetrySchemaError",
    "TelemetryStats",
]
