"""A client the bridge will not serve is told to stop the way an integrator understands.

Closing the connection does not stop OpenSees: its genericClient never notices EOF and spins
in its receive loop at full CPU, printing nothing (spec §2.2). So a refused element-protocol
client (a busy site, sizes the site cannot serve, a host not allowed) keeps its connection
for a while and every request it makes is answered with NaN, as a session the bridge stops
is (docs/safety.md): Newton does not converge, ``analyze`` fails with a message, the script
ends and its ``wipe`` or exit sends DIE. Nothing of it reaches a site: the refusal only
parses the protocol (its own sans-IO session) to know how long each reply is.

Bounded: the connection ends at DIE, EOF, a protocol error, a client that does not read its
answers, or ``REFUSAL_WINDOW`` seconds after the refusal, whichever comes first; and at most
``MAX_REFUSALS`` refused clients of a site are answered at once (the transport closes the
others at once, as before), so a flood of refused connections holds no more than that.
"""

from __future__ import annotations

import asyncio
import math
from collections.abc import Callable

from protocol import (
    ConnectionClosed,
    DieReceived,
    ElementServerSession,
    ProtocolError,
    ReplyRequested,
    Sentinel,
)

__all__ = ["MAX_REFUSALS", "REFUSAL_WINDOW", "Refusal"]

REFUSAL_WINDOW = 10.0
"""Seconds a refused client is answered with NaN before its connection is closed: an
OpenSees analysis stops at its first NaN answer (milliseconds); this only bounds a client
that ignores them."""
MAX_REFUSALS = 8
"""Refused clients of one site answered with NaN at once; more are closed."""


class Refusal:
    """One refused client's connection: its requests answered with NaN until it leaves.

    The transport feeds it as it feeds a ``SessionPump`` (``feed``, ``writing_paused``,
    ``peer_lost``, ``closed``); ``session`` is the client's protocol session when its size ID
    was already read (sizes the site cannot serve), else a fresh one reads it.
    """

    def __init__(self, send: Callable[[bytes], None], close: Callable[[], None], *,
                 max_data_size: int, session: ElementServerSession | None = None,
                 ended: Callable[[], None] | None = None) -> None:
        self.session = session if session is not None else ElementServerSession(
            max_data_size=max_data_size)
        self._send = send
        self._close = close
        self._ended = ended
        self.closed = False
        self.answered = 0
        """Requests answered with NaN so far."""
        self._timer: asyncio.TimerHandle | None = asyncio.get_running_loop().call_later(
            REFUSAL_WINDOW, self._end)
        self._run()  # what the session holds already (the requests after a size ID)

    def feed(self, data: bytes) -> None:
        if self.closed:
            return
        self.session.receive_data(data)
        self._run()

    def _run(self) -> None:
        session = self.session
        while not self.closed:
            try:
                ev = session.next_event()
            except ProtocolError:
                self._end()
                return
            if type(ev) is Sentinel:
                return
            if type(ev) is ReplyRequested:
                size = session.size_id
                assert size is not None  # a request follows the size ID
                self._send(session.send_values((math.nan,) * size.data_size))
                self.answered += 1
            elif isinstance(ev, DieReceived | ConnectionClosed):
                self._end()
                return
            # the size ID, trials, commits, ignored codes: nothing is owed

    def writing_paused(self, paused: bool) -> None:
        """A refused client that does not read its answers is not waited for."""
        if paused:
            self._end()

    def peer_lost(self, reason: str) -> None:
        self._end()

    def abort(self, reason: str) -> None:
        self._end()

    def _end(self) -> None:
        if self.closed:
            return
        self.closed = True
        if self._timer is not None:
            self._timer.cancel()
            self._timer = None
        if self._ended is not None:
            self._ended()
        self._close()
