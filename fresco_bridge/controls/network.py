"""What the networked controller adapters (Modbus, MTS-like) share: the link and its rules.

Actuators behind a controller over TCP (``n_actuators`` channels where the wire has them).
Every call takes the adapter's lock, reconnects after
a loss with jittered backoff (``backoff.py``), and checks a heartbeat that must keep changing
(``_link.HeartbeatWatch``). A motion command whose outcome is unknown (timeout, lost link,
cancelled by the site's deadline) raises and is never re-sent by the adapter; a *new* command
goes out on a fresh link only after a status read shows the controller healthy and idle.
``hold`` engages the program interlock; the next motion command the site forwards releases it
only if this adapter engaged it (never an operator's interlock or a latched fault). A physical
rig cannot report its stiffness: tangent and initial stiffness are a configured estimate.

A subclass provides the wire: open and close the transport (``_open``/``_close_transport``,
``connected``), the status read, the move, the measurement and the interlock words.
"""

from __future__ import annotations

import abc
import asyncio
import math

from ..backoff import Backoff
from ._link import HeartbeatWatch, NetworkControllerConfig
from .base import ControllerError, Daq, PhysicalController, wrong_count

__all__ = ["NetworkController"]


class NetworkController(PhysicalController, abc.ABC):
    """Actuators behind a networked controller; every call is a network round trip."""

    inline = False

    def __init__(self, config: NetworkControllerConfig, where: str,
                 n_actuators: int = 1) -> None:
        self.config = config
        self.stiffness = config.stiffness
        self.where = where
        self.n_actuators = n_actuators
        self._lock = asyncio.Lock()
        self._heartbeats = [HeartbeatWatch(config.heartbeat_timeout, where if n_actuators == 1
                                           else f"{where} channel {c + 1}")
                            for c in range(n_actuators)]
        """One per channel: each channel's counter must keep changing."""
        self._backoff = Backoff(config.reconnect_min,
                                max(config.reconnect_min, config.reconnect_max))
        self._interlock_ours = False
        """This adapter engaged the program interlock (``hold``) and has not released it."""

    # -- the wire (subclasses) ------------------------------------------------------------------
    @property
    @abc.abstractmethod
    def connected(self) -> bool: ...

    @abc.abstractmethod
    async def _open(self) -> None:
        """Open the transport and check the controller speaks our version; raise
        ``ControllerLinkError`` if it cannot be reached, ``ControllerError`` otherwise."""

    @property
    @abc.abstractmethod
    def _has_transport(self) -> bool:
        """A transport exists (open, or lost and not yet dropped)."""

    @abc.abstractmethod
    def _close_transport(self) -> None: ...

    async def _goodbye(self) -> None:
        """Tell the controller the bridge leaves (the lock is held, the link alive)."""

    @abc.abstractmethod
    async def _move(self, targets: tuple[float, ...]) -> None:
        """Move every actuator to its target, mm (the lock is held, the link is fresh or
        alive)."""

    @abc.abstractmethod
    async def _measure(self) -> tuple[tuple[float, ...], tuple[float, ...]]:
        """(displacements mm, forces kN) of the last move (the lock is held)."""

    async def _measure_external(self) -> tuple[float, ...]:
        """The external channel's displacements, mm (the lock is held, right after
        ``_measure``); only called when ``external_channel`` is set."""
        raise ControllerError(f"{self.where}: this controller kind has no external channel")

    @abc.abstractmethod
    async def _set_interlock(self, on: bool, reset_fault: bool = False) -> None:
        """Engage or release the program interlock (the lock is held)."""

    # -- the link -------------------------------------------------------------------------------
    async def connect(self) -> None:
        async with self._lock:
            await self._ensure_link()

    async def close(self) -> None:
        async with self._lock:
            if self.connected:
                await self._goodbye()
            self._drop(failed=False)

    def _drop(self, *, failed: bool = True) -> None:
        self._close_transport()
        for watch in self._heartbeats:
            watch.reset()
        if failed:
            self._backoff.failed()

    async def _ensure_link(self) -> None:
        """Reconnect if needed (reads and hold only), after the backoff delay."""
        if self.connected:
            return
        if self._has_transport:
            self._drop()  # the link was lost
        delay = self._backoff.wait_time()
        if delay > 0.0:
            await asyncio.sleep(delay)
        await self._open()
        self._backoff.succeeded()

    # -- the controller interface --------------------------------------------------------------
    def _targets(self, disp: tuple[float, ...]) -> tuple[float, ...]:
        if len(disp) != self.n_actuators:
            raise wrong_count(self.where, self.n_actuators, disp)
        targets = tuple(float(d) for d in disp)
        if not all(math.isfinite(t) for t in targets):
            shown = targets[0] if len(targets) == 1 else list(targets)
            raise ControllerError(f"{self.where}: ctrl displacement {shown!r} is not finite; "
                                  "not sent")
        return targets

    async def set_ctrl(self, disp: tuple[float, ...]) -> None:
        targets = self._targets(disp)
        async with self._lock:
            await self._ensure_link()  # a fresh link reads the status before any motion
            await self._move(targets)

    async def get_daq(self) -> Daq:
        async with self._lock:
            await self._ensure_link()
            disp, force = await self._measure()
            external = None if self.external_channel is None else \
                await self._measure_external()
        if not all(math.isfinite(v) for v in (*disp, *force, *(external or ()))):
            one = len(disp) == 1
            also = "" if external is None else \
                f", {self.external_channel} {external[0] if one else list(external)!r} mm"
            raise ControllerError(f"{self.where}: non-finite measurement: displacement "
                                  f"{disp[0] if one else list(disp)!r} mm, force "
                                  f"{force[0] if one else list(force)!r} kN{also}")
        return Daq(disp, force, external)

    async def hold(self) -> None:
        """Engage the program interlock (stops a running move where it is)."""
        self._interlock_ours = True  # set first: a request whose reply is lost may have engaged it
        async with self._lock:
            await self._ensure_link()  # safe on a fresh link: it never starts motion
            await self._set_interlock(True)

    async def release(self, *, reset_fault: bool = False) -> None:
        """Release the program interlock (and optionally reset a latched fault)."""
        async with self._lock:
            await self._ensure_link()
            await self._set_interlock(False, reset_fault)
        self._interlock_ours = False

