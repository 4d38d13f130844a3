"""Link helpers shared by the networked controller adapters (Modbus, MTS-like stub).

A stale-heartbeat watch (a counter that must keep changing); the reconnect backoff is the one
of ``fresco_bridge/backoff.py``. Pure bookkeeping on a monotonic clock; no I/O.
"""

from __future__ import annotations

import time
from collections.abc import Callable

from pydantic import Field

from .base import ControllerLinkError
from .kind import ControllerConfigBase


class NetworkControllerConfig(ControllerConfigBase):
    """What every networked controller adapter needs (one actuator); subclasses add the rest."""

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
