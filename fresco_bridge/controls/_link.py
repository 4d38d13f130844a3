"""Link helpers shared by the networked controller adapters (Modbus, MTS-like stub).

A stale-heartbeat watch (a counter that must keep changing) and a jittered exponential
reconnect backoff. Pure bookkeeping on a monotonic clock; no I/O.
"""

from __future__ import annotations

import math
import random
import time
from collections.abc import Callable

from pydantic import BaseModel, ConfigDict, Field

from .base import ControllerLinkError

STATE_NAMES = {0: "IDLE", 1: "MOVING", 2: "DONE", 3: "FAULT", 4: "INTERLOCK"}
FAULT_NAMES = {0: "NONE", 1: "STROKE_LIMIT", 2: "FORCE_LIMIT"}


class NetworkControllerConfig(BaseModel):
    """What every networked controller adapter needs (one actuator); subclasses add the rest."""

    model_config = ConfigDict(extra="forbid", frozen=True)

    host: str = "127.0.0.1"
    ramp_time: float = Field(0.1, ge=0.0, le=3600.0)
    """Ramp time of every move, s (sent with each command)."""
    stiffness: float = Field(68.0, gt=0.0, allow_inf_nan=False)
    """Stiffness estimate reported as tangent and initial stiffness, kN/mm."""
    heartbeat_timeout: float | None = Field(1.0, gt=0.0, allow_inf_nan=False)
    """An unchanged heartbeat for this long is a stale controller (None: not checked)."""
    connect_timeout: float = Field(2.0, gt=0.0, allow_inf_nan=False)
    request_timeout: float = Field(1.0, gt=0.0, allow_inf_nan=False)
    reconnect_min: float = Field(0.05, ge=0.0, allow_inf_nan=False)
    reconnect_max: float = Field(2.0, ge=0.0, allow_inf_nan=False)


def state_name(code: int) -> str:
    """The controller state word as a name (both sim servers share the numbering)."""
    return STATE_NAMES.get(code, f"UNKNOWN({code})")


def fault_name(code: int) -> str:
    """The fault code as a name."""
    return FAULT_NAMES.get(code, f"UNKNOWN({code})")


class HeartbeatWatch:
    """Raises when a controller's heartbeat counter has not changed for ``timeout`` seconds.

    The first observation (and every change) restarts the clock, so a long pause between
    calls never trips it on its own: only an unchanged value observed after ``timeout`` does.
    """

    def __init__(self, timeout: float | None, what: str,
                 clock: Callable[[], float] = time.monotonic) -> None:
        self.timeout = timeout
        self.what = what
        self._clock = clock
        self._value: int | None = None
        self._since = 0.0

    def reset(self) -> None:
        """Forget the last value (a new connection)."""
        self._value = None

    def observe(self, value: int) -> None:
        """Record a heartbeat reading; raise ControllerLinkError if it is stale."""
        now = self._clock()
        if value != self._value:
            self._value, self._since = value, now
            return
        if self.timeout is not None and now - self._since > self.timeout:
            raise ControllerLinkError(
                f"{self.what}: stale heartbeat: the counter stayed at {value} for "
                f"{now - self._since:.3g} s (> heartbeat_timeout {self.timeout:g} s); "
                "the controller is not running"
            )


class Backoff:
    """Jittered exponential reconnect delay between ``low`` and ``high`` seconds."""

    def __init__(self, low: float, high: float, clock: Callable[[], float] = time.monotonic,
                 rng: random.Random | None = None) -> None:
        if not (math.isfinite(low) and math.isfinite(high) and 0.0 <= low <= high):
            raise ValueError(f"reconnect delays need 0 <= min <= max, got {low!r}, {high!r}")
        self.low, self.high = low, high
        self._clock = clock
        self._rng = rng or random.Random()
        self._delay = 0.0
        self._not_before = 0.0

    def failed(self) -> None:
        """A link was lost or an attempt failed: schedule the next attempt later."""
        self._delay = self.low if self._delay == 0.0 else min(self.high, 2.0 * self._delay)
        jittered = self._delay * self._rng.uniform(0.5, 1.0)
        self._not_before = self._clock() + jittered

    def succeeded(self) -> None:
        """Connected: the next loss starts again from the minimum delay."""
        self._delay = 0.0
        self._not_before = 0.0

    def wait_time(self) -> float:
        """Seconds to wait before the next attempt (0 when it may go now)."""
        return max(0.0, self._not_before - self._clock())
