"""Controller adapter for the MTS-CSI-like line protocol of ``sim_actuator`` (version 1).

One actuator. The adapter owns the test (``OPEN``) and sends each move as one ``RUN <mm>
<wait_timeout>`` request (command + execute + wait + acquire in a round trip), after a
``STATUS`` that checks the state and the heartbeat. A request whose reply does not come (lost
link, timeout, cancelled by the site's deadline) drops the link and raises ``ControllerError``;
a motion command is never re-sent by the adapter. Link loss and silence raise
``ControllerLinkError``; a refusal (``ERR``), fault or malformed reply a plain
``ControllerError``. Every call reconnects after a loss, with jittered backoff;
a *new* command goes out on a fresh link only after ``STATUS`` shows the controller healthy
and idle. ``hold`` engages the program interlock; the next motion command the site forwards
releases it only if this adapter engaged it (never an operator's interlock or a fault).
A physical rig cannot report its stiffness: tangent and initial stiffness are a configured
estimate.
"""

from __future__ import annotations

import asyncio
import contextlib
import math
from typing import Literal

from pydantic import Field

from ._link import Backoff, HeartbeatWatch, NetworkControllerConfig
from .base import Controller, ControllerError, ControllerLinkError, Daq

__all__ = ["MtsController", "MtsControllerConfig"]

PROTOCOL = "mts-stub"
PROTOCOL_VERSION = "1"


class MtsControllerConfig(NetworkControllerConfig):
    """A controller speaking the MTS-like stub line protocol (one actuator)."""

    kind: Literal["mts"] = "mts"
    port: int = Field(5021, ge=1, le=65535)
    wait_timeout: float = Field(10.0, gt=0.0, le=3600.0)
    """Server-side WAIT bound of a move, s; a ramp still running then is an error."""


class _Refused(Exception):
    """An ``ERR <code> <message>`` reply."""

    def __init__(self, code: str, message: str) -> None:
        super().__init__(f"ERR {code} {message}")
        self.code = code


def _float(fields: dict[str, str], key: str, where: str) -> float:
    try:
        return float(fields[key])
    except (KeyError, ValueError):
        raise ControllerError(f"{where}: reply lacks a numeric {key!r}: {fields}") from None


class MtsController(Controller):
    """One actuator behind the MTS-like stub; every call is one or two pipelined lines."""

    inline = False
    n_actuators = 1

    def __init__(self, config: MtsControllerConfig) -> None:
        self.config = config
        self.where = f"mts controller {config.host}:{config.port}"
        self._reader: asyncio.StreamReader | None = None
        self._writer: asyncio.StreamWriter | None = None
        self._lock = asyncio.Lock()
        self._heartbeat = HeartbeatWatch(config.heartbeat_timeout, self.where)
        self._backoff = Backoff(config.reconnect_min, max(config.reconnect_min,
                                                          config.reconnect_max))
        self._ramp: int | None = None
        self._interlock_ours = False
        """This adapter engaged the program interlock (``hold``) and has not released it."""
        """Id of the last ramp this adapter completed (for ``ACQUIRE <id>``)."""

    # -- link ----------------------------------------------------------------------------------

    @property
    def connected(self) -> bool:
        return self._writer is not None and not self._writer.is_closing()

    async def connect(self) -> None:
        async with self._lock:
            await self._ensure_link()

    async def close(self) -> None:
        async with self._lock:
            if self.connected:
                with contextlib.suppress(ControllerError, _Refused):
                    await self._ask(["CLOSE"])
            self._drop(failed=False)

    def _drop(self, *, failed: bool = True) -> None:
        writer, self._writer, self._reader = self._writer, None, None
        if writer is not None:
            writer.close()
        self._heartbeat.reset()
        if failed:
            self._backoff.failed()

    async def _ensure_link(self) -> None:
        """Reconnect if needed (reads and hold only), after the backoff delay."""
        if self.connected:
            return
        if self._writer is not None:
            self._drop()
        delay = self._backoff.wait_time()
        if delay > 0.0:
            await asyncio.sleep(delay)
        cfg = self.config
        try:
            self._reader, self._writer = await asyncio.wait_for(
                asyncio.open_connection(cfg.host, cfg.port), cfg.connect_timeout)
        except (TimeoutError, OSError) as exc:
            self._backoff.failed()
            raise ControllerLinkError(f"{self.where}: cannot connect: {exc or 'timed out'}"
                                  ) from None
        try:
            info = await self._ask(["INFO"])
            if info.get("protocol") != PROTOCOL or info.get("version") != PROTOCOL_VERSION:
                raise ControllerError(
                    f"{self.where}: speaks protocol {info.get('protocol')!r} version "
                    f"{info.get('version')!r}; this adapter needs {PROTOCOL} {PROTOCOL_VERSION}")
            if info.get("dofs") != "1":
                raise ControllerError(f"{self.where}: has {info.get('dofs')} dofs, expected 1")
            await self._ask(["OPEN", f"SET_RAMP_TIME {cfg.ramp_time!r}"])
            self._ramp = None  # a restarted controller forgot the old link's ramp ids
            self._heartbeat.observe(int(_float(await self._ask(["STATUS"]), "heartbeat",
                                               self.where)))
        except _Refused as exc:
            self._drop(failed=False)
            raise ControllerError(f"{self.where}: cannot open the test: {exc}") from None
        except ControllerError:
            self._drop(failed=False)
            raise
        self._backoff.succeeded()

    async def _ask(self, lines: list[str], *, timeout: float | None = None,
                   motion: bool = False) -> dict[str, str]:
        """Send ``lines`` pipelined; return the last reply's fields. ERR raises _Refused."""
        return (await self._ask_all(lines, timeout=timeout, motion=motion))[-1]

    async def _ask_all(self, lines: list[str], *, timeout: float | None = None,
                       motion: bool = False) -> list[dict[str, str]]:
        """Send ``lines`` pipelined, read every reply (the stream stays in step), parse."""
        reader, writer = self._reader, self._writer
        what = " / ".join(lines)
        if reader is None or writer is None or writer.is_closing():
            self._drop()
            raise ControllerLinkError(f"{self.where}: link is down; {what!r} not sent")
        bound = self.config.request_timeout if timeout is None else timeout
        replies: list[str] = []
        try:
            writer.write("".join(f"{line}\n" for line in lines).encode("ascii"))
            await writer.drain()
            for _ in lines:
                raw = await asyncio.wait_for(reader.readline(), bound)
                if not raw.endswith(b"\n"):
                    raise ConnectionError("connection closed by the controller")
                replies.append(raw.decode("ascii", "replace").strip())
        except asyncio.CancelledError:
            self._drop()  # replies may still be in flight: the stream is out of step
            raise
        except (TimeoutError, OSError) as exc:
            self._drop()
            reason = f"no reply within {bound:g} s" if isinstance(exc, TimeoutError) else exc
            unknown = (": the outcome of the motion command is unknown and it is not retried"
                       if motion else "")
            raise ControllerLinkError(f"{self.where}: {what!r} failed, link lost ({reason})"
                                  f"{unknown}") from None
        parsed: list[dict[str, str]] = []
        for line, reply in zip(lines, replies, strict=True):
            head, _, rest = reply.partition(" ")
            if head == "ERR":
                code, _, message = rest.partition(" ")
                raise _Refused(code, message)
            if head != "OK":
                self._drop()
                raise ControllerError(f"{self.where}: malformed reply to {line!r}: {reply!r}")
            try:
                parsed.append(dict(pair.split("=", 1) for pair in rest.split()))
            except ValueError:
                self._drop()
                raise ControllerError(f"{self.where}: malformed reply to {line!r}: "
                                      f"{reply!r}") from None
        return parsed

    async def _status(self) -> dict[str, str]:
        try:
            status = await self._ask(["STATUS"])
        except _Refused as exc:
            raise ControllerError(f"{self.where}: STATUS refused: {exc}") from None
        self._heartbeat.observe(int(_float(status, "heartbeat", self.where)))
        return status

    # -- the controller interface -------------------------------------------------------------

    async def set_ctrl(self, disp: tuple[float, ...]) -> None:
        if len(disp) != 1:
            raise ControllerError(f"{self.where}: drives 1 actuator, got {len(disp)} ctrl "
                                  f"values {list(disp)}")
        target = float(disp[0])
        if not math.isfinite(target):
            raise ControllerError(f"{self.where}: ctrl displacement {target!r} is not finite; "
                                  "not sent")
        async with self._lock:
            await self._ensure_link()  # a fresh link reads STATUS before any motion
            status = await self._status()
            if status.get("state") == "INTERLOCK" and self._interlock_ours:
                await self._ask_control(["INTERLOCK OFF"])
                self._interlock_ours = False
                status = await self._status()
            if status.get("state") != "INTERLOCK":
                self._interlock_ours = False  # released elsewhere, or a restarted controller
            else:
                raise ControllerError(
                    f"{self.where}: cannot move to {target!r} mm: the program interlock is "
                    "engaged and not by this bridge (operator or another master); release it "
                    "at the controller")
            if status.get("state") in ("FAULT", "INTERLOCK", "MOVING"):
                raise ControllerError(
                    f"{self.where}: cannot move to {target!r} mm: state {status.get('state')}, "
                    f"fault {status.get('fault')}")
            wait = self.config.wait_timeout
            try:
                reply = await self._ask([f"RUN {target!r} {wait!r}"],
                                        timeout=wait + self.config.request_timeout, motion=True)
            except _Refused as exc:
                if exc.code == "TIMEOUT":
                    raise ControllerError(f"{self.where}: move to {target!r} mm still running "
                                          f"after wait_timeout {wait:g} s ({exc})") from None
                raise ControllerError(f"{self.where}: move to {target!r} mm refused: {exc}"
                                      ) from None
            self._ramp = int(_float(reply, "ramp", self.where))
            if _float(reply, "command", self.where) != target:
                raise ControllerError(f"{self.where}: ramp {self._ramp} ran to "
                                      f"{reply.get('command')} mm, commanded {target!r} mm")

    async def get_daq(self) -> Daq:
        async with self._lock:
            await self._ensure_link()
            ramp = -1 if self._ramp is None else self._ramp
            try:
                status, reply = await self._ask_all(["STATUS", f"ACQUIRE {ramp}"])
            except _Refused as exc:
                raise ControllerError(f"{self.where}: ACQUIRE {ramp} refused: {exc}") from None
            self._heartbeat.observe(int(_float(status, "heartbeat", self.where)))
        disp = _float(reply, "displacement", self.where)
        force = _float(reply, "force", self.where)
        if not (math.isfinite(disp) and math.isfinite(force)):
            raise ControllerError(f"{self.where}: non-finite measurement: displacement "
                                  f"{disp!r} mm, force {force!r} kN")
        return Daq((disp,), (force,))

    async def commit(self) -> None:
        """A physical rig has no trial state to commit."""

    async def tangent_stiffness(self) -> tuple[float, ...]:
        return (self.config.stiffness,)

    async def initial_stiffness(self) -> tuple[float, ...]:
        return (self.config.stiffness,)

    async def hold(self) -> None:
        """Engage the program interlock (stops a running ramp where it is)."""
        self._interlock_ours = True  # set first: a request whose reply is lost may have engaged it
        await self._control(["INTERLOCK ON"])

    async def release(self, *, reset_fault: bool = False) -> None:
        """Release the program interlock (and optionally reset a latched fault)."""
        await self._control(["INTERLOCK OFF", *(["RESET"] if reset_fault else [])])
        self._interlock_ours = False

    async def _control(self, lines: list[str]) -> None:
        async with self._lock:
            await self._ensure_link()  # safe on a fresh link: it never starts motion
            await self._ask_control(lines)

    async def _ask_control(self, lines: list[str]) -> None:
        try:
            await self._ask(lines)
        except _Refused as exc:
            raise ControllerError(f"{self.where}: {' / '.join(lines)} refused: {exc}"
                                  ) from None
