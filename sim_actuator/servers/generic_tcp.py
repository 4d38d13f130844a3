"""A lab controller server speaking OpenFresco's ``expControl GenericTCP`` protocol.

What a lab built for OpenFresco (a LabVIEW program, a real-time target, the Simulink
``SFun_OPF_TCPServer``): it listens, takes one client at a time, and serves N channels, one
simulated rig each (``RigController``). The wire is ``protocol/generic_tcp.py`` (the same
layer the bridge's ``generic-tcp`` controller uses). Per connection: the size ID (ctrl disp =
N, daq disp/force = N or 0, daq time = 1 or 0; anything else closes the connection with a
logged reason: the protocol has no error reply), the parameter-file lines (``ramp_time <s>``
is understood, ``#`` lines are comments, anything else is logged and ignored), then ctrl
vectors (every channel starts its move at once; non-finite or refused commands move nothing
and are logged) and daq requests (answered when every move is done, with fresh readings).
DIE or EOF ends the connection; the rigs keep their state for the next one (a reconnect).

UDP: datagrams from one peer are one stream (OpenFresco sends no handshake; a 1-byte ``a``
first is answered ``b`` all the same); a new peer replaces the old one (a reconnect). TLS:
the caller passes a server context requiring a client certificate.
"""

from __future__ import annotations

import asyncio
import contextlib
import logging
import math
import ssl
from typing import cast

from protocol import (
    ConnectionClosed,
    DieReceived,
    GenericTcpServerSession,
    ReplyRequested,
    SetupLineReceived,
    Signals,
    SizeReceived,
    TrialReceived,
    UdpServerFraming,
    chunk_datagrams,
)
from protocol.errors import ProtocolError
from protocol.events import NEED_DATA, PAUSED
from protocol.wire import Action
from sim_actuator.servers.controller import ControllerError, RigController

__all__ = ["GenericTcpRigServer"]

log = logging.getLogger("sim_actuator.generic_tcp")
MOVE_WAIT = 600.0
"""Longest a daq request waits for the moves to finish, s."""


class _Refused(Exception):
    """The client asked for something this server cannot serve; the connection ends."""


class _Channels:
    """The N rigs one connection drives, and what a connection negotiated."""

    def __init__(self, controllers: list[RigController]) -> None:
        self.controllers = controllers
        self.ramp_time: float | None = None
        self.daq_sizes = (0, 0, 0, 0, 0)

    def accept(self, event: SizeReceived) -> None:
        n = len(self.controllers)
        ctrl, daq = event.size_id.ctrl, event.size_id.daq
        if ctrl.as_tuple() not in ((n, 0, 0, 0, 0), (n, 0, 0, 0, 1)):
            raise _Refused(f"ctrl sizes {list(ctrl.as_tuple())}: this server takes {n} "
                           "displacement(s) (ctrlModes 1 0 0 0 0, time optional)")
        if daq.disp not in (0, n) or daq.force not in (0, n) or daq.vel or daq.accel \
                or daq.time not in (0, 1):
            raise _Refused(f"daq sizes {list(daq.as_tuple())}: this server measures {n} "
                           "displacement(s), force(s) and the time (daqModes d 0 0 f t)")
        self.daq_sizes = daq.as_tuple()
        self.ramp_time = None

    def setup_line(self, line: bytes) -> None:
        text = line.decode("utf-8", "replace").strip()
        words = text.split()
        if not words or text.startswith("#"):
            return
        if words[0] == "ramp_time" and len(words) == 2:
            try:
                value = float(words[1])
            except ValueError:
                value = math.nan
            if math.isfinite(value) and value >= 0.0:
                self.ramp_time = value
                log.info("parameter file: ramp_time %g s", value)
                return
        log.warning("parameter file line ignored (understood: 'ramp_time <s>'): %r", text)

    def move(self, targets: tuple[float, ...]) -> None:
        if not all(math.isfinite(t) for t in targets):
            log.error("ctrl %s is not finite: nothing moved", list(targets))
            return
        for channel, (rig, target) in enumerate(zip(self.controllers, targets, strict=True), 1):
            ramp = rig.rig.default_ramp_time if self.ramp_time is None else self.ramp_time
            try:
                rig.execute(target, ramp)
            except ControllerError as exc:
                log.error("channel %d: move to %r mm refused: %s", channel, target, exc)

    async def daq(self) -> Signals:
        for rig in self.controllers:
            if not await rig.wait(MOVE_WAIT):
                log.error("a move still runs after %g s; answering the readings now", MOVE_WAIT)
        readings = [rig.feedback(-1)[1] for rig in self.controllers]
        d, _, _, f, t = self.daq_sizes
        return Signals(disp=tuple(m.displacement for m in readings) if d else (),
                       force=tuple(m.force for m in readings) if f else (),
                       time=(readings[0].time,) if t else ())


async def _serve_events(session: GenericTcpServerSession, channels: _Channels,
                        peer: str) -> tuple[list[bytes], bool]:
    """Handle every buffered event: (replies to send, the connection ends)."""
    replies: list[bytes] = []
    while True:
        event = session.next_event()
        if event is NEED_DATA:
            return replies, False
        if event is PAUSED:  # pragma: no cover - every owed reply is sent below
            return replies, False
        if isinstance(event, SizeReceived):
            channels.accept(event)
            log.info("%s: size ID %s", peer, event.size_id)
        elif isinstance(event, SetupLineReceived):
            channels.setup_line(event.line)
        elif isinstance(event, TrialReceived):
            channels.move(event.trial.disp)
        elif isinstance(event, ReplyRequested):
            if event.action is not Action.GET_DAQ_RESPONSE:
                raise _Refused(f"request {event.action.name}: a GenericTCP server answers "
                               "only code 6 (getDaqResponse)")
            replies.append(session.send_daq(await channels.daq()))
        elif isinstance(event, DieReceived):
            log.info("%s: DIE", peer)
            return replies, True
        elif isinstance(event, ConnectionClosed):
            return replies, True
        # Ignored codes (1, 4, 5, ...) get no reply, as in the element protocol


class GenericTcpRigServer:
    """N channels behind one GenericTCP listener (TCP, TLS or UDP)."""

    def __init__(self, controllers: list[RigController], *, host: str = "127.0.0.1",
                 port: int = 0, transport: str = "tcp",
                 tls: ssl.SSLContext | None = None) -> None:
        if not controllers:
            raise ValueError("a GenericTCP server needs at least one channel")
        if transport not in ("tcp", "udp"):
            raise ValueError(f"transport must be tcp or udp, got {transport!r}")
        self.channels = _Channels(controllers)
        self.host, self.port, self.transport, self.tls = host, port, transport, tls
        self.connections = 0
        self._server: asyncio.Server | None = None
        self._udp: asyncio.DatagramTransport | None = None
        self._busy = asyncio.Lock()
        self._writers: set[asyncio.StreamWriter] = set()

    async def start(self) -> tuple[str, int]:
        if self.transport == "udp":
            loop = asyncio.get_running_loop()
            transport, _ = await loop.create_datagram_endpoint(
                lambda: _UdpPeer(self), local_addr=(self.host, self.port))
            self._udp = transport
            self.host, self.port = transport.get_extra_info("sockname")[:2]
        else:
            self._server = await asyncio.start_server(self._handle, self.host, self.port,
                                                      ssl=self.tls)
            self.host, self.port = self._server.sockets[0].getsockname()[:2]
        return self.host, self.port

    async def stop(self) -> None:
        if self._udp is not None:
            self._udp.close()
            self._udp = None
        if self._server is not None:
            self._server.close()
            for writer in list(self._writers):
                writer.close()
            await self._server.wait_closed()
            self._server = None

    async def _handle(self, reader: asyncio.StreamReader, writer: asyncio.StreamWriter) -> None:
        peer = str(writer.get_extra_info("peername"))
        if self._busy.locked():
            log.warning("%s refused: a client is connected (one master at a time)", peer)
            writer.close()
            return
        async with self._busy:
            self._writers.add(writer)
            self.connections += 1
            session = GenericTcpServerSession()
            try:
                while True:
                    data = await reader.read(65536)
                    session.receive_data(data)
                    replies, done = await _serve_events(session, self.channels, peer)
                    for reply in replies:
                        writer.write(reply)
                    await writer.drain()
                    if done or not data:
                        break
            except (_Refused, ProtocolError) as exc:
                log.error("%s: connection closed: %s", peer, exc)
            except OSError as exc:
                log.warning("%s: connection lost: %s", peer, exc)
            finally:
                self._writers.discard(writer)
                writer.close()
                with contextlib.suppress(OSError, ssl.SSLError):
                    await writer.wait_closed()


class _UdpPeer(asyncio.DatagramProtocol):
    """One UDP peer at a time; a new peer address starts a new session."""

    def __init__(self, server: GenericTcpRigServer) -> None:
        self.server = server
        self.transport: asyncio.DatagramTransport | None = None
        self.peer: object = None
        self.framing = UdpServerFraming()
        self.session = GenericTcpServerSession()
        self.queue: asyncio.Queue[tuple[GenericTcpServerSession, object, bytes]] = \
            asyncio.Queue()
        self.task: asyncio.Task[None] | None = None

    def connection_made(self, transport: asyncio.BaseTransport) -> None:
        self.transport = cast(asyncio.DatagramTransport, transport)
        self.task = asyncio.get_running_loop().create_task(self._run())

    def connection_lost(self, exc: Exception | None) -> None:
        if self.task is not None:
            self.task.cancel()

    def datagram_received(self, data: bytes, addr: object) -> None:
        if addr != self.peer:
            self.peer, self.framing = addr, UdpServerFraming()
            self.session = GenericTcpServerSession()
            self.server.connections += 1
            log.info("%s: new UDP peer", addr)
        payload, handshake = self.framing.datagram_received(data)
        if handshake is not None and self.transport is not None:
            self.transport.sendto(handshake, addr)  # type: ignore[arg-type]
        if payload:
            self.queue.put_nowait((self.session, addr, payload))

    async def _run(self) -> None:
        while True:
            session, peer, payload = await self.queue.get()
            try:
                session.receive_data(payload)
                replies, done = await _serve_events(session, self.server.channels, str(peer))
            except (_Refused, ProtocolError) as exc:
                log.error("%s: session dropped: %s", peer, exc)
                self._end(session)
                continue
            if self.transport is not None:
                for reply in replies:
                    for chunk in chunk_datagrams(reply):
                        self.transport.sendto(chunk, peer)  # type: ignore[arg-type]
            if done:
                self._end(session)

    def _end(self, session: GenericTcpServerSession) -> None:
        """The session is over: the next datagram, from any peer, starts a new one."""
        if session is self.session:
            self.session, self.peer = GenericTcpServerSession(), None
