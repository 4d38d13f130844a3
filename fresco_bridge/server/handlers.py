"""Protocol handlers: turn protocol events into site calls and replies.

One handler per connection. ``handle`` is a coroutine that the connection drives eagerly, so
with an in-process controller a request is answered inside ``data_received``.
"""

from __future__ import annotations

import logging
from collections.abc import Callable

from protocol import (
    Action,
    ActorSession,
    CommitReceived,
    ConnectionClosed,
    DaqRequested,
    DieReceived,
    ElementServerSession,
    Ignored,
    OpenReceived,
    ProbeReceived,
    ReplyRequested,
    SetupReceived,
    SizeReceived,
    TrialReceived,
)

from ..sites import ExperimentalSite, SiteError

log = logging.getLogger("fresco_bridge.session")

Send = Callable[[bytes], None]


class SessionEnded(Exception):
    """The client ended the session (DIE or EOF); the connection closes quietly."""


class ElementHandler:
    """The element-level protocol (OpenSees genericClient, OpenFresco EE*, MATLAB, C clients)."""

    def __init__(self, site: ExperimentalSite, session: ElementServerSession, send: Send,
                 peer: str) -> None:
        self.site = site
        self.session = session
        self.send = send
        self.peer = peer

    async def handle(self, ev: object) -> None:
        site = self.site
        kind = type(ev)
        if kind is TrialReceived:
            await site.set_trial(ev.trial)  # type: ignore[attr-defined]
        elif kind is ReplyRequested:
            await self._reply(ev.action)  # type: ignore[attr-defined]
        elif kind is CommitReceived:
            await site.commit()
        elif kind is SizeReceived:
            sid = ev.size_id  # type: ignore[attr-defined]
            site.check_sizes(sid.ctrl, sid.daq, f"client {self.peer}")
            log.info("site %s: client %s sizes ctrl=%s daq=%s dataSize=%d", site.name, self.peer,
                     sid.ctrl.as_tuple(), sid.daq.as_tuple(), sid.data_size)
        elif kind is DieReceived:
            raise SessionEnded("client sent DIE (99)")
        elif kind is ConnectionClosed:
            if ev.clean:  # type: ignore[attr-defined]
                raise SessionEnded("client closed the connection without DIE")
            raise SiteError(
                f"client {self.peer} closed the connection in the middle of a message "
                f"({ev.pending_bytes} byte(s) of a partial item discarded)"  # type: ignore[attr-defined]
            )
        elif kind is Ignored:
            log.info("site %s: ignoring action code %r from %s (no reply, as OpenFresco)",
                     site.name, ev.code, self.peer)  # type: ignore[attr-defined]

    async def _reply(self, action: Action) -> None:
        site, session = self.site, self.session
        if action is Action.GET_TANGENT_STIFF:
            self.send(session.send_matrix(await site.tangent()))
        elif action is Action.GET_DAMP:
            self.send(session.send_matrix(site.damping))
        elif action is Action.GET_INITIAL_STIFF:
            self.send(session.send_matrix(await site.initial()))
        elif action is Action.GET_MASS:
            self.send(session.send_matrix(site.mass))
        else:  # 6..11: measured signals
            sid = session.size_id
            assert sid is not None
            self.send(session.send_daq(await site.out_signals(sid.daq)))


class ActorHandler:
    """The site-level protocol: we play OpenFresco's ActorExpSite for a ShadowExpSite client."""

    def __init__(self, site: ExperimentalSite, session: ActorSession, send: Send,
                 peer: str) -> None:
        self.site = site
        self.session = session
        self.send = send
        self.peer = peer
        self.size_out = None

    async def handle(self, ev: object) -> None:
        site, session = self.site, self.session
        kind = type(ev)
        if kind is TrialReceived:
            await site.set_trial(ev.trial)  # type: ignore[attr-defined]
        elif kind is DaqRequested:
            assert self.size_out is not None
            self.send(session.send_daq(await site.out_signals(self.size_out)))
        elif kind is CommitReceived:
            await site.commit()
        elif kind is ProbeReceived:
            self.send(session.send_probe_reply())
        elif kind is OpenReceived:
            log.info("site %s: ShadowExpSite %d (OpenFresco %s) opened from %s", site.name,
                     ev.shadow_tag, ev.version, self.peer)  # type: ignore[attr-defined]
            # The shadow exits on a version mismatch: echo its own version.
            self.send(session.send_open_reply(site.cfg.actor_tag, ev.version))  # type: ignore[attr-defined]
        elif kind is SetupReceived:
            site.check_sizes(ev.size_trial, ev.size_out, f"shadow site {self.peer}")  # type: ignore[attr-defined]
            self.size_out = ev.size_out  # type: ignore[attr-defined]
        elif kind is DieReceived:
            self.send(session.send_die_reply(site.cfg.actor_tag))
            raise SessionEnded("shadow site sent DIE (99)")
        elif kind is ConnectionClosed:
            if ev.clean:  # type: ignore[attr-defined]
                raise SessionEnded("shadow site closed the connection without DIE")
            raise SiteError(f"shadow site {self.peer} closed the connection mid-message")
        elif kind is Ignored:
            log.info("site %s: ignoring action code %r from %s", site.name,
                     ev.code, self.peer)  # type: ignore[attr-defined]
