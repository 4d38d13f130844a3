"""Protocol handlers: turn protocol events into site calls and replies.

One handler per connection, one method, ``dispatch``, for every event of its protocol. A request
goes to the site's ``*_eager`` method, so with an in-process controller it is answered inside
``data_received`` without a coroutine; what must wait comes back as a coroutine the connection
finishes in a task. Session events (sizes, DIE, EOF, ignored codes) need no site I/O and are
handled at once.
"""

from __future__ import annotations

import logging
import math
from collections.abc import Callable, Coroutine
from typing import Any

from protocol import (
    Action,
    ActorEvent,
    ActorSession,
    CommitReceived,
    ConnectionClosed,
    DaqRequested,
    DieReceived,
    ElementServerEvent,
    ElementServerSession,
    Ignored,
    OpenReceived,
    ProbeReceived,
    ReplyRequested,
    SetupReceived,
    Signals,
    SignalSizes,
    SizeReceived,
    TrialReceived,
)

from ..logs import RateLimitedLog
from ..sites import Site, SiteError

log = logging.getLogger("fresco_bridge.session")
_DAQ_ACTIONS = frozenset(a for a in Action if Action.GET_DAQ_RESPONSE <= a <= Action.GET_TIME)
_TANGENT = Action.GET_TANGENT_STIFF  # a module constant: reading an enum member off its class
# is an attribute lookup through the enum machinery, on the path of every request

Send = Callable[[bytes], None]


class SessionEnded(Exception):
    """The client ended the session (DIE or EOF); the connection closes quietly."""


class ElementHandler:
    """The element-level protocol (OpenSees genericClient, OpenFresco EE*, MATLAB, C clients)."""

    def __init__(self, site: Site, session: ElementServerSession, send: Send, peer: str) -> None:
        self.site = site
        self.session = session
        self.send = send
        self.peer = peer
        self.introduced = False
        self.on_open: Callable[[], None] | None = None
        self._says = RateLimitedLog(log)
        """What the client's messages make us say, once per cause per interval."""
        self._daq_sizes: SignalSizes | None = None  # the client's, from its size ID
        self._constant = {Action.GET_DAMP: site.damping, Action.GET_MASS: site.mass}
        """Requests answered from the site's configuration (GenericClient asks for the damping
        matrix several times per step): no controller call, no coroutine. NaN too when the
        integrator must stop, as every other answer."""
        self._nan_matrix = (math.nan,) * len(site.damping)

    def dispatch(self, ev: ElementServerEvent) -> Coroutine[Any, Any, None] | None:
        """Handle ``ev``: at once when it can be (None), else the coroutine that finishes it.
        The step's events come first, tested by exact type: they are 14 messages of 14."""
        if type(ev) is ReplyRequested:  # 10 of the 14 messages of an OpenSees step
            action = ev.action
            matrix = self._constant.get(action)
            if matrix is not None:
                stop = self.site.stopping()
                self.send(self.session.send_matrix(self._nan_matrix if stop else matrix))
                return None
            if action is _TANGENT:
                k = self.site.tangent_eager()
                if not isinstance(k, tuple):
                    return self._send_matrix_later(k)
                self.send(self.session.send_matrix(k))
                return None
            if action in _DAQ_ACTIONS:
                assert self._daq_sizes is not None
                out = self.site.out_signals_eager(self._daq_sizes)
                if not isinstance(out, Signals):
                    return self._send_daq_later(out)
                self.send(self.session.send_daq(out))
                return None
            # the one reply action left (the protocol's are 6..15): 12, the initial stiffness
            return self._send_matrix_later(self.site.initial())
        if type(ev) is TrialReceived:
            return self.site.set_trial_eager(ev.trial)
        if type(ev) is CommitReceived:
            return self.site.commit_eager()
        self._session_event(ev)
        return None

    async def _send_matrix_later(self, k: Coroutine[Any, Any, tuple[float, ...]]) -> None:
        self.send(self.session.send_matrix(await k))

    async def _send_daq_later(self, out: Coroutine[Any, Any, Signals]) -> None:
        self.send(self.session.send_daq(await out))

    def _session_event(self, ev: ElementServerEvent) -> None:
        site = self.site
        match ev:
            case SizeReceived(size_id=sid):
                site.check_sizes(sid.ctrl, sid.daq, f"client {self.peer}")
                site.open_session(self.peer)
                self.introduced = True
                if self.on_open is not None:
                    self.on_open()
                self._daq_sizes = sid.daq
                log.info("site %s: client %s sizes ctrl=%s daq=%s dataSize=%d", site.name,
                         self.peer, sid.ctrl.as_tuple(), sid.daq.as_tuple(), sid.data_size)
            case DieReceived():
                raise SessionEnded("client sent DIE (99)")
            case ConnectionClosed(clean=True):
                raise SessionEnded("client closed the connection without DIE")
            case ConnectionClosed(pending_bytes=pending):
                raise SiteError(
                    f"client {self.peer} closed the connection in the middle of a message "
                    f"({pending} byte(s) of a partial item discarded)"
                )
            case Ignored(code=code):
                self._says.log(logging.INFO, "ignored",
                               "site %s: ignoring action code %r from %s (no reply, as OpenFresco)",
                               site.name, code, self.peer)


class ActorHandler:
    """The site-level protocol: we play OpenFresco's ActorExpSite for a ShadowExpSite client."""

    def __init__(self, site: Site, session: ActorSession, send: Send, peer: str) -> None:
        self.site = site
        self.session = session
        self.send = send
        self.peer = peer
        self.size_out: SignalSizes | None = None
        self.introduced = False
        self.on_open: Callable[[], None] | None = None
        self._says = RateLimitedLog(log)
        """What the client's messages make us say, once per cause per interval."""

    def dispatch(self, ev: ActorEvent) -> Coroutine[Any, Any, None] | None:
        """Handle ``ev``: at once when it can be (None), else the coroutine that finishes it."""
        site, session = self.site, self.session
        match ev:
            case TrialReceived(trial=trial):
                return site.set_trial_eager(trial)
            case DaqRequested():
                assert self.size_out is not None
                out = site.out_signals_eager(self.size_out)
                if not isinstance(out, Signals):
                    return self._send_daq_later(out)
                self.send(session.send_daq(out))
            case CommitReceived():
                return site.commit_eager()
            case ProbeReceived():
                self.send(session.send_probe_reply())
            case OpenReceived(shadow_tag=shadow_tag, version=version):
                self._says.log(logging.INFO, "open",
                               "site %s: ShadowExpSite %d (OpenFresco %s) opened from %s",
                               site.name, shadow_tag, version, self.peer)
                # The shadow exits on a version mismatch: echo its own version.
                self.send(session.send_open_reply(site.cfg.actor_tag, version))
            case SetupReceived(size_trial=size_trial, size_out=size_out):
                site.check_sizes(size_trial, size_out, f"shadow site {self.peer}")
                if not self.introduced:
                    site.open_session(self.peer)
                    self.introduced = True
                    if self.on_open is not None:
                        self.on_open()
                self.size_out = size_out
            case DieReceived():
                self.send(session.send_die_reply(site.cfg.actor_tag))
                raise SessionEnded("shadow site sent DIE (99)")
            case ConnectionClosed(clean=True):
                raise SessionEnded("shadow site closed the connection without DIE")
            case ConnectionClosed():
                raise SiteError(f"shadow site {self.peer} closed the connection mid-message")
            case Ignored(code=code):
                self._says.log(logging.INFO, "ignored", "site %s: ignoring action code %r from %s",
                               site.name, code, self.peer)
        return None

    async def _send_daq_later(self, out: Coroutine[Any, Any, Signals]) -> None:
        self.send(self.session.send_daq(await out))
