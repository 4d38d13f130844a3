"""MTS-CSI-like controller stub over TCP: a line-based request/response protocol.

It mirrors the calls OpenFresco's ``ECMtsCsi`` makes on an MTS CSI controller (start the test,
``runRamp`` with a ramp time, wait until completion, ``acquireFeedback``, reset) on top of a
:class:`~sim_actuator.servers.controller.RigController`. The exact message format is in
``sim_actuator/README.md`` ("MTS-like stub protocol"); in short:

* ASCII lines ending in LF (CR LF accepted), at most ``max_line`` (1024) bytes; tokens are
  separated by spaces; verbs are case-insensitive. One request line gets exactly one reply line.
* Replies: ``OK`` followed by ``key=value`` pairs, or ``ERR <CODE> <message>``.
* Floats in replies use Python's shortest round-trip repr, so they parse back exactly.
* Several channels (``sim-actuator serve --protocol mts --channels N``): one ramp drives every
  channel, as CSI's ``runRamp`` with a command vector: ``COMMAND`` and ``RUN`` take N
  displacements, every reading is a comma-separated list in channel order, and ``STATUS``
  reports the most severe channel state (with ``states=`` per channel). A ramp starts only when
  every channel accepts its target (nothing moves otherwise).
"""

from __future__ import annotations

import asyncio
import contextlib
import math
from collections.abc import Callable
from dataclasses import dataclass

from sim_actuator.rig import Measurement, MoveOutcome, RigError, RigFault
from sim_actuator.servers.controller import (
    ControllerBusy,
    ControllerError,
    ControllerFaulted,
    ControllerInterlocked,
    ControllerState,
    LimitExceeded,
    RigController,
)
from sim_actuator.wire.mts_lines import MAX_LINE, PROTOCOL, PROTOCOL_VERSION, err, ok, split_request

__all__ = ["PROTOCOL_VERSION", "MtsStubServer", "ProtocolError"]

_MAX_TIMEOUT = 3600.0
_TOO_LONG = object()  # marker returned by _read_line for a discarded over-long line


class ProtocolError(Exception):
    """A request the stub refuses; rendered as ``ERR <code> <message>``."""

    def __init__(self, code: str, message: str) -> None:
        super().__init__(message)
        self.code = code


@dataclass
class _Session:
    """Per-connection state: the test it owns, its ramp time and pending command."""

    test_id: int = 0
    ramp_time: float | None = None
    command: tuple[float, ...] | None = None
    peer: str = "?"


def _number(token: str, what: str) -> float:
    try:
        value = float(token)
    except ValueError:
        raise ProtocolError("SYNTAX", f"{what} must be a number, got {token!r}") from None
    if not math.isfinite(value):
        raise ProtocolError("BAD_VALUE", f"{what} must be finite, got {token!r}")
    return value


def _integer(token: str, what: str) -> int:
    try:
        return int(token)
    except ValueError:
        raise ProtocolError("SYNTAX", f"{what} must be an integer, got {token!r}") from None


def _timeout(token: str) -> float:
    value = _number(token, "timeout")
    if not 0.0 <= value <= _MAX_TIMEOUT:
        raise ProtocolError("BAD_VALUE", f"timeout must be within [0, {_MAX_TIMEOUT:g}] s")
    return value


def _values(values: list[float]) -> float | str:
    """One float as itself, several as a comma-separated list of shortest reprs."""
    return values[0] if len(values) == 1 else ",".join(repr(v) for v in values)


def _feedback(move_id: int, ms: list[Measurement]) -> str:
    return ok(ramp=move_id, time=ms[0].time, displacement=_values([m.displacement for m in ms]),
              force=_values([m.force for m in ms]), command=_values([m.command for m in ms]),
              specimen=_values([m.specimen_displacement for m in ms]))


_SEVERITY = (ControllerState.MOVING, ControllerState.FAULT, ControllerState.INTERLOCK,
             ControllerState.IDLE, ControllerState.DONE)
"""The state STATUS reports for several channels: the first of these any channel is in."""


class MtsStubServer:
    """asyncio TCP server speaking the stub protocol; one client may own the test at a time."""

    def __init__(self, controller: RigController | list[RigController], *,
                 host: str = "127.0.0.1", port: int = 0, max_line: int = MAX_LINE) -> None:
        self.controllers = controller if isinstance(controller, list) else [controller]
        if not self.controllers:
            raise ValueError("an MTS stub server needs at least one channel")
        self.controller = self.controllers[0]
        n = len(self.controllers)
        self._ramp_ids: tuple[int, ...] = (0,) * n
        """Each channel's move id of the last ramp (equal unless a channel refused midway)."""
        self.host = host
        self.port = port
        self.max_line = max_line
        self._server: asyncio.Server | None = None
        self._owner: _Session | None = None
        self._tests_opened = 0
        self._writers: set[asyncio.StreamWriter] = set()
        self._handlers: set[asyncio.Task[None]] = set()
        self._verbs: dict[str, tuple[int, int, bool, Callable[..., object]]] = {
            # verb: (min args, max args, needs an open test, handler)
            "INFO": (0, 0, False, self._info),
            "STATUS": (0, 0, False, self._status),
            "OPEN": (0, 0, False, self._open),
            "CLOSE": (0, 0, False, self._close),
            "SET_RAMP_TIME": (1, 1, True, self._set_ramp_time),
            "COMMAND": (n, n, True, self._command),
            "EXECUTE": (0, 0, True, self._execute),
            "WAIT": (2, 2, True, self._wait),
            "ACQUIRE": (0, 1, False, self._acquire),
            "RUN": (n + 1, n + 1, True, self._run),
            "RESET": (0, 0, True, self._reset),
            "INTERLOCK": (1, 1, True, self._interlock),
        }

    async def start(self) -> tuple[str, int]:
        """Listen; return the bound (host, port) (port 0 picks a free one)."""
        self._server = await asyncio.start_server(
            self._handle, self.host, self.port, limit=self.max_line + 2
        )
        self.host, self.port = self._server.sockets[0].getsockname()[:2]
        return self.host, self.port

    async def stop(self) -> None:
        """Stop listening and close every connection."""
        if self._server is not None:
            self._server.close()
            for writer in list(self._writers):
                writer.close()  # the handler sees EOF and returns
            if self._handlers:
                await asyncio.wait(list(self._handlers), timeout=5.0)
            await self._server.wait_closed()
            self._server = None

    # -- connection loop ---------------------------------------------------------------------

    async def _handle(self, reader: asyncio.StreamReader, writer: asyncio.StreamWriter) -> None:
        peer = writer.get_extra_info("peername")
        session = _Session(peer=str(peer))
        task = asyncio.current_task()
        if task is not None:
            self._handlers.add(task)
            task.add_done_callback(self._handlers.discard)
        self._writers.add(writer)
        try:
            while True:
                line = await self._read_line(reader)
                if line is None:
                    break
                reply = await self._reply(session, line)
                writer.write(reply.encode("ascii") + b"\n")
                await writer.drain()
        except (ConnectionError, asyncio.IncompleteReadError):
            pass
        finally:
            self._writers.discard(writer)
            if self._owner is session:
                self._owner = None
            writer.close()
            with contextlib.suppress(ConnectionError):
                await writer.wait_closed()

    async def _read_line(self, reader: asyncio.StreamReader) -> bytes | object | None:
        """One line without its terminator, None at EOF, _TOO_LONG for a discarded line."""
        try:
            return (await reader.readuntil(b"\n")).rstrip(b"\r\n")
        except asyncio.IncompleteReadError as exc:
            return exc.partial.rstrip(b"\r\n") if exc.partial.strip() else None
        except asyncio.LimitOverrunError as exc:
            await reader.readexactly(exc.consumed)
            while True:  # drop the rest of the over-long line
                try:
                    await reader.readuntil(b"\n")
                    break
                except asyncio.LimitOverrunError as more:
                    await reader.readexactly(more.consumed)
            return _TOO_LONG

    async def _reply(self, session: _Session, raw: bytes | object) -> str:
        try:
            if not isinstance(raw, bytes):
                raise ProtocolError("TOO_LONG", f"request line exceeds {self.max_line} bytes")
            try:
                text = raw.decode("ascii")
            except UnicodeDecodeError:
                raise ProtocolError("SYNTAX", "request is not ASCII text") from None
            verb, args = split_request(text)
            if not verb:
                raise ProtocolError("SYNTAX", "empty request")
            if verb not in self._verbs:
                raise ProtocolError(
                    "SYNTAX", f"unknown request {text.split()[0]!r}; known: "
                    f"{', '.join(self._verbs)}"
                )
            low, high, needs_open, handler = self._verbs[verb]
            if not low <= len(args) <= high:
                expected = str(low) if low == high else f"{low} to {high}"
                raise ProtocolError(
                    "SYNTAX", f"{verb} takes {expected} argument(s), got {len(args)}"
                )
            if needs_open and self._owner is not session:
                raise ProtocolError("NOT_OPEN", f"{verb} needs an open test; send OPEN first")
            result = handler(session, *args)
            if asyncio.iscoroutine(result):
                result = await result
            return str(result)
        except (ProtocolError, ControllerError) as exc:
            return err(exc.code, str(exc))

    # -- requests ------------------------------------------------------------------------------

    def _info(self, session: _Session) -> str:
        rig = self.controller.rig
        return (
            f"OK protocol={PROTOCOL} version={PROTOCOL_VERSION} dofs={len(self.controllers)} "
            "channels=displacement,force,command,time units=mm,kN,mm,s "
            f"stroke={rig.actuator.stroke!r} force_capacity={rig.actuator.force_capacity!r} "
            f"max_ramp_time={rig.max_ramp_time!r} default_ramp_time={rig.default_ramp_time!r}"
        )

    def _state(self) -> ControllerState:
        """The most severe state of the channels (the one channel's state, for one)."""
        states = [x.state for x in self.controllers]
        return next(s for s in _SEVERITY if s in states)

    def _status(self, session: _Session) -> str:
        c, cs = self.controller, self.controllers
        states = [x.state for x in cs]
        state = self._state()
        fault = next((x.fault for x in cs if x.fault.name != "NONE"), c.fault)
        several = "" if len(cs) == 1 else (
            f" states={','.join(s.name for s in states)} "
            f"sequences={','.join(str(x.sequence) for x in cs)}")
        return (
            f"OK state={state.name} fault={fault.name} ramp={c.move_id} "
            f"sequence={c.sequence} heartbeat={c.heartbeat} time={c.rig.time!r} "
            f"interlock={int(any(x.interlock for x in cs))} "
            f"open={int(self._owner is not None)}{several}"
        )

    def _open(self, session: _Session) -> str:
        if self._owner is not None and self._owner is not session:
            raise ProtocolError("BUSY", f"a test is already open by {self._owner.peer}")
        if self._owner is None:
            self._tests_opened += 1
            session.test_id = self._tests_opened
            session.ramp_time, session.command = None, None
            self._owner = session
        return f"OK test={session.test_id}"

    def _close(self, session: _Session) -> str:
        if self._owner is session:
            self._owner = None
        return "OK"

    def _set_ramp_time(self, session: _Session, token: str) -> str:
        value = _number(token, "ramp time")
        rig = self.controller.rig
        if not 0.0 <= value <= rig.max_ramp_time:
            raise ProtocolError(
                "BAD_VALUE", f"ramp time must be within [0, {rig.max_ramp_time!r}] s, got {token}"
            )
        session.ramp_time = value
        return f"OK ramp_time={value!r}"

    def _command(self, session: _Session, *tokens: str) -> str:
        session.command = tuple(_number(t, "command displacement") for t in tokens)
        return ok(command=_values(list(session.command)))

    def _execute(self, session: _Session) -> str:
        return f"OK ramp={self._start_ramp(session)}"

    def _start_ramp(self, session: _Session) -> int:
        if session.command is None:
            raise ProtocolError("NO_COMMAND", "send COMMAND <mm> before EXECUTE")
        ramp = session.ramp_time
        if ramp is None:
            ramp = self.controller.rig.default_ramp_time
        if len(self.controllers) == 1:
            self._ramp_ids = (self.controller.execute(session.command[0], ramp),)
            return self._ramp_ids[0]
        for channel, (c, target) in enumerate(zip(self.controllers, session.command,
                                                  strict=True), 1):
            self._accepts(channel, c, target, ramp)  # every channel first: all or nothing
        self._ramp_ids = tuple(c.execute(t, ramp) for c, t in zip(self.controllers,
                                                                  session.command, strict=True))
        return self._ramp_ids[0]

    @staticmethod
    def _accepts(channel: int, c: RigController, target: float, ramp: float) -> None:
        """Refuse (as ``execute`` would) a target channel ``channel`` cannot start now."""
        if c.state is ControllerState.MOVING and (target, ramp) != (c.target, c.ramp_time):
            raise ControllerBusy(f"channel {channel}: move {c.move_id} is still running")
        if c.interlock:
            raise ControllerInterlocked(f"channel {channel}: the program interlock is engaged")
        if c.state is ControllerState.MOVING:
            return
        try:
            c.rig.validate(target, ramp)
        except RigFault as exc:
            if c.fault.name != "NONE" and "latched" in str(exc):
                raise ControllerFaulted(f"channel {channel}: {exc}") from None
            raise LimitExceeded(f"channel {channel}: {exc}") from None
        except RigError as exc:
            raise ProtocolError("BAD_VALUE", f"channel {channel}: {exc}") from None

    async def _wait(self, session: _Session, ramp_token: str, timeout_token: str) -> str:
        return await self._wait_for(_integer(ramp_token, "ramp id"), _timeout(timeout_token))

    async def _wait_for(self, move_id: int, timeout: float) -> str:
        c = self.controller
        if move_id != c.move_id or move_id <= 0:
            raise ProtocolError(
                "UNKNOWN_RAMP", f"ramp {move_id} is not the last ramp ({c.move_id})"
            )
        for channel, x in enumerate(self.controllers, 1):
            which = "" if len(self.controllers) == 1 else f" (channel {channel})"
            if not await x.wait(timeout):
                raise ProtocolError("TIMEOUT", f"ramp {move_id} still running after "
                                    f"{timeout:g} s{which}")
            if x.outcome is MoveOutcome.TRIPPED:
                raise ProtocolError("FAULT", f"ramp {move_id} tripped{which}: {x.fault.name}")
            if x.outcome is MoveOutcome.ABORTED:
                raise ProtocolError("INTERLOCK", f"ramp {move_id} stopped by the "
                                    f"interlock{which}")
        return f"OK ramp={move_id} state={c.state.name}"

    def _readings(self, move_id: int) -> tuple[int, list[Measurement]]:
        """Every channel's feedback of ramp ``move_id`` (-1: fresh readings now)."""
        first, _ = self.controller.feedback(move_id)  # raises for an unknown ramp
        if move_id == -1:
            return first, [c.feedback(-1)[1] for c in self.controllers]
        ids = self._ramp_ids if move_id == self._ramp_ids[0] else (move_id,) * len(
            self.controllers)
        return move_id, [c.feedback(i)[1] for c, i in zip(self.controllers, ids, strict=True)]

    def _acquire(self, session: _Session, ramp_token: str = "-1") -> str:
        return _feedback(*self._readings(_integer(ramp_token, "ramp id")))

    async def _run(self, session: _Session, *tokens: str) -> str:
        timeout = _timeout(tokens[-1])
        self._command(session, *tokens[:-1])
        move_id = self._start_ramp(session)
        await self._wait_for(move_id, timeout)
        return _feedback(*self._readings(move_id))

    def _reset(self, session: _Session) -> str:
        for c in self.controllers:
            c.reset()
        return f"OK state={self._state().name}"

    def _interlock(self, session: _Session, token: str) -> str:
        flag = token.upper()
        if flag not in ("ON", "OFF"):
            raise ProtocolError("SYNTAX", f"INTERLOCK takes ON or OFF, got {token!r}")
        for c in self.controllers:  # every channel
            c.set_interlock(flag == "ON")
        return f"OK state={self._state().name}"
