"""A blocking genericClient: our integrator's element, byte-for-byte what OpenSees sends.

Used by the built-in demo integrator, the benchmarks and tests. Unlike genericClient it has a
deadline on every receive and raises ``LinkError`` instead of spinning on a dead peer.
"""

from __future__ import annotations

import contextlib
import math
import socket

from protocol import (
    NEED_DATA,
    Action,
    ClientState,
    ElementClientSession,
    ReplyReceived,
    Signals,
    SizeID,
    chunk_datagrams,
)

UDP_HANDSHAKE_REQUEST = b"a"  # OpenSees UDP_Socket: client 'a', server 'b' (spec §2.3)
UDP_HANDSHAKE_REPLY = b"b"


class LinkError(ConnectionError):
    """The bridge did not answer in time or closed the connection."""


class SessionRefused(LinkError):
    """The bridge refused the session: it closed the connection, or answered NaN, before any
    measurement.

    A bridge refuses a client whose size ID does not fit the site (another number of DOFs), an
    address it does not allow, or a client while the site is busy: it answers NaN (what makes
    OpenSees stop) or closes; the protocol has no message for a reason, so the reason is in the
    bridge's log."""


class GenericClientLink:
    def __init__(
        self,
        host: str,
        port: int,
        n_dof: int,
        *,
        data_size: int = 256,
        transport: str = "tcp",
        timeout: float = 10.0,
    ) -> None:
        self.address = (host, port)
        self.n = n_dof
        self.size_id = SizeID.for_generic_client(n_dof, data_size)
        self.session = ElementClientSession(self.size_id)
        self.transport = transport
        self.timeout = timeout
        self.sock: socket.socket | None = None
        self._answered = False  # any reply received: a close before one is a refusal
        self._measured = False  # a finite answer received: NaN before one is a refusal

    # -- connection --------------------------------------------------------------------------
    def connect(self) -> GenericClientLink:
        if self.transport == "tcp":
            sock = socket.create_connection(self.address, timeout=self.timeout)
            sock.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
        else:
            sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
            sock.settimeout(self.timeout)
            sock.connect(self.address)
            sock.send(UDP_HANDSHAKE_REQUEST)
            if sock.recv(16) != UDP_HANDSHAKE_REPLY:
                raise LinkError(f"bridge at {self.address} did not answer the UDP handshake")
        self.sock = sock
        self._send(self.session.start())
        return self

    def close(self) -> None:
        if self.sock is None:
            return
        # DIE only where the protocol allows it: not while a reply is outstanding (the bridge
        # went away mid-request), not after an error
        if self.session.state is ClientState.READY:
            with contextlib.suppress(OSError):  # the bridge may already be gone
                self._send(self.session.send_die())
        self.sock.close()
        self.sock = None

    def __enter__(self) -> GenericClientLink:
        return self.connect()

    def __exit__(self, *exc: object) -> None:
        self.close()

    # -- messages ----------------------------------------------------------------------------
    def _send(self, data: bytes) -> None:
        assert self.sock is not None, "link not connected"
        try:
            if self.transport == "tcp":
                self.sock.sendall(data)
            else:
                for chunk in chunk_datagrams(data):
                    self.sock.send(chunk)
        except (BrokenPipeError, ConnectionResetError):
            raise self._closed() from None

    def _reply(self) -> ReplyReceived:
        assert self.sock is not None
        while True:
            ev = self.session.next_event()
            if ev is not NEED_DATA:
                assert isinstance(ev, ReplyReceived)
                return ev
            try:
                data = self.sock.recv(65536)
            except TimeoutError:
                raise LinkError(f"no reply from the bridge at {self.address} "
                                f"within {self.timeout:g} s") from None
            except ConnectionResetError:  # closed with our next message unread: a reset
                data = b""
            if not data:
                raise self._closed()
            self.session.receive_data(data)
            self._answered = True

    def _closed(self) -> LinkError:
        """The bridge closed the connection: a refusal before its first answer."""
        host, port = self.address
        if self._answered:
            return LinkError(f"the bridge at {host}:{port} closed the connection")
        sid = self.size_id
        return SessionRefused(
            f"the bridge at {host}:{port} refused the session: it closed the connection "
            f"before answering this client ({self.n}-DOF genericClient, sizes "
            f"ctrl={sid.ctrl.as_tuple()} daq={sid.daq.as_tuple()} dataSize={sid.data_size}); "
            "its log says why (a site serving another number of DOFs, an address not in "
            "allowed_clients, a site busy with another client)")

    def set_trial(
        self, disp: tuple[float, ...], vel: tuple[float, ...] | None = None,
        accel: tuple[float, ...] | None = None, time: float = 0.0,
    ) -> None:
        zeros = (0.0,) * self.n
        self._send(self.session.send_trial(
            Signals(disp=disp, vel=vel or zeros, accel=accel or zeros, time=(time,))
        ))

    def request(self, action: Action) -> ReplyReceived:
        self._send(self.session.send_request(action))
        reply = self._reply()
        if not self._measured:
            if reply.values and all(math.isnan(v) for v in reply.values):
                raise self._told_to_stop()
            self._measured = True
        return reply

    def _told_to_stop(self) -> SessionRefused:
        """NaN before any measurement: the bridge's way to tell an integrator to stop."""
        host, port = self.address
        sid = self.size_id
        return SessionRefused(
            f"the bridge at {host}:{port} refused the session: it answered NaN (its way to tell "
            f"an integrator to stop) before any measurement ({self.n}-DOF genericClient, sizes "
            f"ctrl={sid.ctrl.as_tuple()} daq={sid.daq.as_tuple()} dataSize={sid.data_size}); "
            "its log says why (a site serving another number of DOFs, an address not in "
            "allowed_clients, a site busy with another client, a HOLD at the first command)")

    def force(self) -> tuple[float, ...]:
        return self.request(Action.GET_FORCE).values[: self.n]

    def matrix(self, action: Action) -> tuple[tuple[float, ...], ...]:
        return self.request(action).matrix(self.n)

    def commit(self) -> None:
        self._send(self.session.send_commit())


class SiteElement:
    """A bridge site as a story element of the coupling loop (``integrator/coupling.py``).

    The story drift goes out as the element's trial displacement, the measured force comes back;
    ``commit`` sends the commit. The element's basic DOFs are the link's: 1 (``NoTransformation``:
    ``disp = (drift,)``) or 2 (``OneActuator`` on a two-node element whose node i is the
    reference: ``disp = (0, drift)``, the force is that of node j). Explicit integration needs no
    tangent, so none is asked of the bridge: ``set_trial`` answers ``stiffness``, the estimate.
    """

    def __init__(self, link: GenericClientLink, stiffness: float = 0.0) -> None:
        if link.n not in (1, 2):
            raise ValueError(f"a story element has 1 or 2 basic DOFs, the link has {link.n}")
        self.link = link
        self.stiffness = stiffness
        self._time = 0.0

    @property
    def initial_tangent(self) -> float:
        return self.stiffness

    def begin_step(self, step: int, time: float) -> None:
        """The step's time, sent with the trial (the bridge records it)."""
        self._time = time

    def set_trial(self, d: float) -> tuple[float, float]:
        self.link.set_trial((d,) if self.link.n == 1 else (0.0, d), time=self._time)
        return self.link.force()[-1], self.stiffness

    def commit(self) -> None:
        self.link.commit()
