"""Controller adapter for the MTS-CSI-like line protocol of ``sim_actuator`` (version 1).

One or several actuators (the link's rules are ``network.py``'s; several: one ramp drives every
channel, readings are comma-separated lists). The adapter owns the test (``OPEN``) and
sends each move as one ``RUN <mm> <wait_timeout>`` request (command + execute + wait + acquire
in a round trip), after a ``STATUS`` that checks the state and the heartbeat. A request whose
reply does not come (lost link, timeout, cancelled by the site's deadline) drops the link and
raises ``ControllerError``; a motion command is never re-sent by the adapter. Link loss and
silence raise ``ControllerLinkError``; a refusal (``ERR``), fault or malformed reply a plain
``ControllerError``. Every call reconnects after a loss, with jittered backoff; a *new* command
goes out on a fresh link only after ``STATUS`` shows the controller healthy and idle. ``hold``
engages the program interlock; the next motion command the site forwards releases it only if
this adapter engaged it (never an operator's interlock or a fault). A physical rig cannot report
its stiffness: tangent and initial stiffness are a configured estimate."""

from __future__ import annotations

import asyncio
import contextlib
from typing import Literal

from pydantic import Field

from sim_actuator.wire.mts_lines import (  # the one line format, shared with the server
    PROTOCOL,
    PROTOCOL_VERSION,
    MalformedReply,
    Refused,
    parse_reply,
)

from ._link import NetworkControllerConfig
from .base import ControllerError, ControllerLinkError
from .kind import ControllerKind
from .network import NetworkController

__all__ = ["MtsController", "MtsControllerConfig"]


class MtsControllerConfig(NetworkControllerConfig):
    """A controller speaking the MTS-like stub line protocol (its channels, one per actuator)."""

    kind: Literal["mts"] = "mts"
    port: int = Field(5021, ge=1, le=65535)
    wait_timeout: float = Field(10.0, gt=0.0, le=3600.0)
    """Server-side WAIT bound of a move, s; a ramp still running then is an error."""
    external_field: str | None = Field(None, pattern=r"^[a-z_]+$")
    """The external channel (``Daq.external``): the key of the ``ACQUIRE`` reply that carries
    a second transducer's displacement (mm), read from the same reply (no extra round trip);
    ``sim-actuator serve --protocol mts`` sends the specimen's as ``specimen``. None: none."""

    def external_channel(self) -> str | None:
        return None if self.external_field is None else f"ACQUIRE {self.external_field}"


def _float(fields: dict[str, str], key: str, where: str) -> float:
    try:
        return float(fields[key])
    except (KeyError, ValueError):
        raise ControllerError(f"{where}: reply lacks a numeric {key!r}: {fields}") from None


def _floats(fields: dict[str, str], key: str, where: str, n: int) -> tuple[float, ...]:
    """``key``'s n comma-separated numbers (one channel: one number)."""
    try:
        values = tuple(float(v) for v in fields[key].split(","))
    except (KeyError, ValueError):
        values = ()
    if len(values) != n:
        raise ControllerError(f"{where}: reply lacks {n} numeric {key!r} value(s): {fields}")
    return values


class MtsController(NetworkController):
    """One actuator behind the MTS-like stub; every call is one or two pipelined lines."""

    config: MtsControllerConfig

    def __init__(self, config: MtsControllerConfig, n_actuators: int = 1) -> None:
        super().__init__(config, f"mts controller {config.host}:{config.port}", n_actuators)
        self._reader: asyncio.StreamReader | None = None
        self._writer: asyncio.StreamWriter | None = None
        self._ramp: int | None = None
        """Id of the last ramp this adapter completed (for ``ACQUIRE <id>``)."""
        self._acquired: dict[str, str] = {}
        """The last ``ACQUIRE`` reply (the external channel is read from it)."""
        self.external_channel = config.external_channel()

    # -- the transport -------------------------------------------------------------------------

    @property
    def connected(self) -> bool:
        return self._writer is not None and not self._writer.is_closing()

    @property
    def _has_transport(self) -> bool:
        return self._writer is not None

    def _close_transport(self) -> None:
        writer, self._writer, self._reader = self._writer, None, None
        if writer is not None:
            writer.close()

    async def _goodbye(self) -> None:
        with contextlib.suppress(ControllerError, Refused):
            await self._ask(["CLOSE"])

    async def _open(self) -> None:
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
            if info.get("protocol") != PROTOCOL or info.get("version") != str(PROTOCOL_VERSION):
                raise ControllerError(
                    f"{self.where}: speaks protocol {info.get('protocol')!r} version "
                    f"{info.get('version')!r}; this adapter needs {PROTOCOL} {PROTOCOL_VERSION}")
            if info.get("dofs") != str(self.n_actuators):
                raise ControllerError(f"{self.where}: has {info.get('dofs')} dofs, expected "
                                      f"{self.n_actuators}")
            await self._ask(["OPEN", f"SET_RAMP_TIME {cfg.ramp_time!r}"])
            self._ramp = None  # a restarted controller forgot the old link's ramp ids
            self._heartbeats[0].observe(int(_float(await self._ask(["STATUS"]), "heartbeat",
                                               self.where)))
        except Refused as exc:
            self._drop(failed=False)
            raise ControllerError(f"{self.where}: cannot open the test: {exc}") from None
        except ControllerError:
            self._drop(failed=False)
            raise

    async def _ask(self, lines: list[str], *, timeout: float | None = None,
                   motion: bool = False) -> dict[str, str]:
        """Send ``lines`` pipelined; return the last reply's fields. ERR raises Refused."""
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
            try:
                parsed.append(parse_reply(reply))
            except MalformedReply:
                self._drop()
                raise ControllerError(f"{self.where}: malformed reply to {line!r}: "
                                      f"{reply!r}") from None
        return parsed

    async def _status(self) -> dict[str, str]:
        try:
            status = await self._ask(["STATUS"])
        except Refused as exc:
            raise ControllerError(f"{self.where}: STATUS refused: {exc}") from None
        self._heartbeats[0].observe(int(_float(status, "heartbeat", self.where)))
        return status

    # -- the wire of the controller interface -------------------------------------------------

    async def _move(self, targets: tuple[float, ...]) -> None:
        target: float | list[float] = targets[0] if len(targets) == 1 else list(targets)
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
            reply = await self._ask([f"RUN {' '.join(map(repr, targets))} {wait!r}"],
                                    timeout=wait + self.config.request_timeout, motion=True)
        except Refused as exc:
            if exc.code == "TIMEOUT":
                raise ControllerError(f"{self.where}: move to {target!r} mm still running "
                                      f"after wait_timeout {wait:g} s ({exc})") from None
            raise ControllerError(f"{self.where}: move to {target!r} mm refused: {exc}"
                                  ) from None
        self._ramp = int(_float(reply, "ramp", self.where))
        if _floats(reply, "command", self.where, self.n_actuators) != targets:
            raise ControllerError(f"{self.where}: ramp {self._ramp} ran to "
                                  f"{reply.get('command')} mm, commanded {target!r} mm")

    async def _measure(self) -> tuple[tuple[float, ...], tuple[float, ...]]:
        ramp = -1 if self._ramp is None else self._ramp
        try:
            status, reply = await self._ask_all(["STATUS", f"ACQUIRE {ramp}"])
        except Refused as exc:
            raise ControllerError(f"{self.where}: ACQUIRE {ramp} refused: {exc}") from None
        self._heartbeats[0].observe(int(_float(status, "heartbeat", self.where)))
        n = self.n_actuators
        self._acquired = reply
        return (_floats(reply, "displacement", self.where, n),
                _floats(reply, "force", self.where, n))

    async def _measure_external(self) -> tuple[float, ...]:
        field = self.config.external_field
        assert field is not None  # only called with an external channel
        return _floats(self._acquired, field, self.where, self.n_actuators)

    async def _set_interlock(self, on: bool, reset_fault: bool = False) -> None:
        await self._ask_control(["INTERLOCK ON"] if on
                                else ["INTERLOCK OFF", *(["RESET"] if reset_fault else [])])

    async def _ask_control(self, lines: list[str]) -> None:
        try:
            await self._ask(lines)
        except Refused as exc:
            raise ControllerError(f"{self.where}: {' / '.join(lines)} refused: {exc}"
                                  ) from None


KIND = ControllerKind(
    name="mts",
    config=MtsControllerConfig,
    factory=lambda config, n, _geometry: MtsController(config, n),
    summary="an MTS-CSI-like line controller over TCP, e.g. `sim-actuator serve --protocol mts`, "
    "its channels one ramp",
    max_actuators=None,
)
