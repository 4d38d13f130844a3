"""A lab's own controller server, reached as OpenFresco's ``expControl GenericTCP`` reaches it.

The bridge is the client (``protocol/generic_tcp.py`` holds the wire, shared with the simulated
server of ``sim-actuator serve --protocol generic-tcp``): on every new link the 11-int size ID
and the parameter file's lines, then per move a ctrl vector (code 3, no reply) and per
measurement a daq request (code 6) answered with the daq vector; DIE (99) when the bridge
leaves. TCP, UDP (OpenFresco's ``UDP_Socket``: no handshake, 9126-byte datagrams) or mutual TLS
(OpenFresco's ``TCP_SocketSSL``).

What the bridge adds to OpenFresco's client, which has no timeout and no error check: a deadline
on every reply, reconnect with jittered backoff, and the rules that keep the lab's server from
an unsafe command. The protocol has no status and no acknowledgement, so:

* a link that replaced a lost one carries no motion command until a daq request answered on it
  (the site's recovery reads first, checks the move from the *measured* position against its
  limits, then re-sends the same absolute setpoint once — ``sites/guard.py``); a lost ctrl
  vector is never re-sent by the adapter itself;
* ``hold`` sends nothing: the server moves only on a ctrl vector, so the last command holds;
* nothing is sent on connecting but the ID and the lines (OpenFresco's own ``setup()`` then
  sends a zero ctrl vector, a move to 0 mm from wherever the actuator is: the bridge does not).
"""

from __future__ import annotations

import asyncio
import contextlib
import math
import ssl
from pathlib import Path
from typing import Annotated, Literal

from pydantic import Field, model_validator

from protocol import LocalProtocolError, ProtocolError, SignalSizes, SizeID
from protocol.events import ConnectionClosed
from protocol.generic_tcp import (
    GENERIC_TCP_DATA_SIZE,
    DaqReplyReceived,
    GenericTcpClientSession,
    parameter_file_lines,
)
from protocol.udp import chunk_datagrams
from protocol.wire import SIGNAL_NAMES, Signals

from ..backoff import Backoff
from ..config_model import ConfigPath
from .base import ControllerError, ControllerLinkError, Daq, PhysicalController, wrong_count
from .kind import ControllerConfigBase, ControllerKind

__all__ = ["GenericTcpController", "GenericTcpControllerConfig"]

Mode = Annotated[int, Field(ge=0, le=1)]
Modes = Annotated[tuple[Mode, Mode, Mode, Mode, Mode], Field(strict=False)]
"""Five 0/1 flags in OpenFresco's order disp, vel, accel, force, time (a TOML array)."""


class GenericTcpControllerConfig(ControllerConfigBase):
    """``kind = "generic-tcp"``: OpenFresco's ``expControl GenericTCP tag ipAddr ipPort
    -ctrlModes ... -daqModes ... <-initFile f> <-ssl|-udp>``."""

    kind: Literal["generic-tcp"] = "generic-tcp"
    host: str = "127.0.0.1"
    port: int = Field(5022, ge=1, le=65535)
    transport: Literal["tcp", "udp", "ssl"] = "tcp"
    """``tcp``, ``udp`` (OpenFresco ``-udp``) or ``ssl`` (``-ssl``: mutual TLS)."""
    ctrl_modes: Modes = (1, 0, 0, 0, 0)
    """disp, vel, accel, force, time sent with each ctrl vector (1 = sent). The bridge commands
    displacements: disp must be 1 and the others 0."""
    daq_modes: Modes = (1, 0, 0, 1, 0)
    """disp, vel, accel, force, time the server answers (1 = expected). force must be 1; with
    disp 0 the measured displacement is taken as the command."""
    init_file: ConfigPath | None = None
    """Parameter file (``-initFile``): each line is sent to the server on every new link."""
    data_size: int = Field(GENERIC_TCP_DATA_SIZE, ge=2, le=65536)
    """Doubles per vector (OpenFresco: always 256)."""
    cert_file: ConfigPath | None = None
    """``ssl``: the bridge's certificate (OpenFresco: client.crt)."""
    key_file: ConfigPath | None = None
    """``ssl``: its key (client.key)."""
    ca_file: ConfigPath | None = None
    """``ssl``: the CA the server's certificate must be issued by (client_ca.crt)."""
    stiffness: float = Field(68.0, gt=0.0, allow_inf_nan=False)
    """Stiffness estimate reported as tangent and initial stiffness per actuator, kN/mm."""
    connect_timeout: float = Field(2.0, gt=0.0, allow_inf_nan=False)
    request_timeout: float = Field(5.0, gt=0.0, allow_inf_nan=False)
    """Deadline of a daq reply, s: the server answers once its move is done."""
    reconnect_min: float = Field(0.05, ge=0.0, allow_inf_nan=False)
    reconnect_max: float = Field(2.0, ge=0.0, allow_inf_nan=False)

    @model_validator(mode="after")
    def _modes_and_files(self) -> GenericTcpControllerConfig:
        if self.ctrl_modes != (1, 0, 0, 0, 0):
            sent = [n for n, m in zip(SIGNAL_NAMES, self.ctrl_modes, strict=True) if m]
            raise ValueError(f"ctrl_modes {list(self.ctrl_modes)} sends {sent or 'nothing'}: "
                             "the bridge commands actuator displacements only, so ctrl_modes "
                             "must be [1, 0, 0, 0, 0]")
        if not self.daq_modes[3]:
            raise ValueError(f"daq_modes {list(self.daq_modes)}: force (the 4th flag) must be "
                             "1, the site answers the integrator with the measured force")
        if self.init_file is not None:
            try:
                parameter_file_lines(Path(self.init_file).read_bytes())
            except OSError as exc:
                raise ValueError(f"init_file: cannot read {self.init_file}: "
                                 f"{exc.strerror or exc}") from None
            except LocalProtocolError as exc:
                raise ValueError(f"init_file {self.init_file}: {exc}") from None
        tls = {"cert_file": self.cert_file, "key_file": self.key_file, "ca_file": self.ca_file}
        if self.transport == "ssl":
            missing = [k for k, v in tls.items() if v is None]
            if missing:
                raise ValueError(f"transport = \"ssl\" (mutual TLS) needs {', '.join(missing)}")
            self.tls_context()  # an unreadable certificate is a config error, now
        elif any(v is not None for v in tls.values()):
            given = [k for k, v in tls.items() if v is not None]
            raise ValueError(f"{', '.join(given)}: only with transport = \"ssl\"")
        return self

    def tls_context(self) -> ssl.SSLContext:
        """The client side of OpenFresco's mutual TLS: our certificate, the server's CA."""
        ctx = ssl.SSLContext(ssl.PROTOCOL_TLS_CLIENT)
        ctx.minimum_version = ssl.TLSVersion.TLSv1_2
        ctx.check_hostname = False  # OpenFresco checks the certificate chain, not a name
        try:
            ctx.load_cert_chain(str(self.cert_file), str(self.key_file))
            ctx.load_verify_locations(cafile=str(self.ca_file))
        except (OSError, ssl.SSLError) as exc:
            raise ValueError(f"cannot load the TLS files {self.cert_file}, {self.key_file}, "
                             f"{self.ca_file}: {exc}") from None
        return ctx

    def size_id(self, n_actuators: int) -> SizeID:
        """What the bridge announces for ``n_actuators`` control points (time: one value)."""
        def sizes(modes: Modes) -> SignalSizes:
            return SignalSizes(*(m * (1 if i == 4 else n_actuators) for i, m in enumerate(modes)))
        return SizeID(sizes(self.ctrl_modes), sizes(self.daq_modes), self.data_size)


class _Datagrams(asyncio.DatagramProtocol):
    """The UDP link's receiving end: datagrams and errors in arrival order."""

    def __init__(self) -> None:
        self.queue: asyncio.Queue[bytes | OSError] = asyncio.Queue()

    def datagram_received(self, data: bytes, addr: object) -> None:
        if data:
            self.queue.put_nowait(data)

    def error_received(self, exc: Exception) -> None:
        self.queue.put_nowait(exc if isinstance(exc, OSError) else OSError(str(exc)))


class _Link:
    """One open transport: TCP/TLS streams or a connected UDP endpoint."""

    def __init__(self, stream: tuple[asyncio.StreamReader, asyncio.StreamWriter] | None = None,
                 udp: tuple[asyncio.DatagramTransport, _Datagrams] | None = None) -> None:
        self.stream, self.udp = stream, udp

    @property
    def alive(self) -> bool:
        if self.stream is not None:
            return not (self.stream[1].is_closing() or self.stream[0].at_eof())
        return self.udp is not None and not self.udp[0].is_closing()

    async def send(self, data: bytes) -> None:
        if self.stream is not None:
            self.stream[1].write(data)
            await self.stream[1].drain()
        elif self.udp is not None:
            for chunk in chunk_datagrams(data):
                self.udp[0].sendto(chunk)

    async def receive(self) -> bytes:
        """Next bytes (``b""``: the server closed the connection)."""
        if self.stream is not None:
            return await self.stream[0].read(65536)
        assert self.udp is not None
        item = await self.udp[1].queue.get()
        if isinstance(item, OSError):
            raise item
        return item

    def close(self) -> None:
        if self.stream is not None:
            self.stream[1].close()
        elif self.udp is not None:
            self.udp[0].close()


class GenericTcpController(PhysicalController):
    """``n_actuators`` control points behind a lab's GenericTCP server."""

    inline = False

    def __init__(self, config: GenericTcpControllerConfig, n_actuators: int) -> None:
        self.config = config
        self.n_actuators = n_actuators
        self.stiffness = config.stiffness
        self.where = f"generic-tcp controller {config.host}:{config.port} ({config.transport})"
        self._size_id = config.size_id(n_actuators)
        self._lines = ([] if config.init_file is None
                       else parameter_file_lines(Path(config.init_file).read_bytes()))
        self._tls = config.tls_context() if config.transport == "ssl" else None
        self._lock = asyncio.Lock()
        self._backoff = Backoff(config.reconnect_min,
                                max(config.reconnect_min, config.reconnect_max))
        self._link: _Link | None = None
        self._session: GenericTcpClientSession | None = None
        self._lost = False
        """A link was lost and no daq reply has come over a new one yet: no motion command."""
        self._answered = False
        """A daq reply came over the current link."""
        self._sent: tuple[float, ...] = (0.0,) * n_actuators
        self.links_opened = 0
        self.last_daq: Signals | None = None
        """The last daq vector as the server sent it (every block it answers)."""

    # -- the link -------------------------------------------------------------------------------
    async def connect(self) -> None:
        async with self._lock:
            await self._ensure_link()

    async def close(self) -> None:
        async with self._lock:
            link, session = self._link, self._session
            if link is not None and session is not None and link.alive:
                with contextlib.suppress(OSError, ProtocolError):
                    await asyncio.wait_for(link.send(session.send_die()),
                                           self.config.request_timeout)
            self._drop(lost=False)

    def _drop(self, *, lost: bool = True) -> None:
        link, self._link, self._session = self._link, None, None
        if link is not None:
            link.close()
        if lost:
            self._lost = True
            self._backoff.failed()

    async def _ensure_link(self) -> None:
        if self._link is not None and self._link.alive:
            return
        if self._link is not None:
            self._drop()  # the server closed it
        delay = self._backoff.wait_time()
        if delay > 0.0:
            await asyncio.sleep(delay)
        cfg = self.config
        try:
            link = await asyncio.wait_for(self._open(), cfg.connect_timeout)
        except (TimeoutError, OSError) as exc:
            self._backoff.failed()
            raise ControllerLinkError(f"{self.where}: cannot connect: "
                                      f"{exc or 'timed out'}") from None
        session = GenericTcpClientSession(self._size_id)
        try:
            await link.send(session.start())
            for line in self._lines:
                await link.send(session.send_setup_line(line))
        except OSError as exc:
            link.close()
            self._backoff.failed()
            raise ControllerLinkError(f"{self.where}: link lost while sending the size ID and "
                                      f"the parameter file: {exc}") from None
        self._link, self._session = link, session
        self._answered = False
        self.links_opened += 1
        self._backoff.succeeded()

    async def _open(self) -> _Link:
        cfg = self.config
        if cfg.transport == "udp":
            transport, proto = await asyncio.get_running_loop().create_datagram_endpoint(
                _Datagrams, remote_addr=(cfg.host, cfg.port))
            return _Link(udp=(transport, proto))
        return _Link(stream=await asyncio.open_connection(cfg.host, cfg.port, ssl=self._tls))

    # -- the controller interface ---------------------------------------------------------------
    def _command(self, disp: tuple[float, ...]) -> tuple[float, ...]:
        if len(disp) != self.n_actuators:
            raise wrong_count(self.where, self.n_actuators, disp)
        if not all(math.isfinite(d) for d in disp):
            raise ControllerError(f"{self.where}: ctrl displacement {list(disp)} is not finite; "
                                  "not sent")
        return tuple(float(d) for d in disp)

    async def set_ctrl(self, disp: tuple[float, ...]) -> None:
        command = self._command(disp)
        async with self._lock:
            await self._ensure_link()
            if self._lost:
                raise ControllerLinkError(
                    f"{self.where}: the link was lost; a motion command goes out on the new "
                    f"link only after a measurement answered on it ({list(command)} not sent)")
            link, session = self._link, self._session
            assert link is not None and session is not None
            try:
                await link.send(session.send_ctrl(Signals(disp=command)))
            except (OSError, asyncio.CancelledError) as exc:
                self._drop()
                if isinstance(exc, asyncio.CancelledError):
                    raise
                raise ControllerLinkError(f"{self.where}: ctrl {list(command)} failed, link lost "
                                          f"({exc}): its outcome is unknown and it is not "
                                          "retried") from None
            self._sent = command

    async def get_daq(self) -> Daq:
        async with self._lock:
            await self._ensure_link()
            daq = await self._request_daq()
            self._lost = False
        self.last_daq = daq
        disp = daq.disp if daq.disp else self._sent
        force = daq.force
        if not all(math.isfinite(v) for v in (*disp, *force)):
            raise ControllerError(f"{self.where}: non-finite measurement: displacement "
                                  f"{list(disp)} mm, force {list(force)} kN")
        return Daq(disp, force)

    async def _request_daq(self) -> Signals:
        link, session = self._link, self._session
        assert link is not None and session is not None
        bound = self.config.request_timeout
        try:
            async with asyncio.timeout(bound):
                await link.send(session.send_daq_request())
                while True:
                    event = session.next_event()
                    if isinstance(event, DaqReplyReceived):
                        self._answered = True
                        return event.daq
                    if isinstance(event, ConnectionClosed):
                        raise ConnectionError(
                            "connection closed by the server" if self._answered else
                            "connection closed by the server before any reply on this link: a "
                            "server closes it when it refuses the client (busy with another "
                            f"master, or the size ID: this site's {self._size_id.ctrl.disp} "
                            f"actuator(s), daq_modes {list(self.config.daq_modes)}); its log "
                            "says why")
                    session.receive_data(await link.receive())
        except asyncio.CancelledError:
            self._drop()  # a reply may still be in flight: the stream is out of step
            raise
        except (TimeoutError, OSError) as exc:
            self._drop()
            reason = f"no reply within {bound:g} s" if isinstance(exc, TimeoutError) else exc
            raise ControllerLinkError(f"{self.where}: daq request failed, link lost "
                                      f"({reason})") from None
        except ProtocolError as exc:
            self._drop()
            raise ControllerError(f"{self.where}: malformed daq reply: {exc}") from None

    async def hold(self) -> None:
        """Nothing to send: the server moves only on a ctrl vector, the last one holds."""

    def status_fields(self) -> dict[str, object]:
        return {"controller_links": self.links_opened}


KIND = ControllerKind(
    name="generic-tcp",
    config=GenericTcpControllerConfig,
    factory=GenericTcpController,
    summary="a lab's own controller server speaking OpenFresco's `expControl GenericTCP` "
    "protocol (TCP, UDP or mutual TLS), e.g. `sim-actuator serve --protocol generic-tcp`",
    max_actuators=None,
)
