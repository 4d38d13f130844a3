"""Events, states and constants of the site-level protocol (spec §4).

Kept apart from the sessions in :mod:`protocol.site` so both roles share one definition.
"""

from __future__ import annotations

import enum
from dataclasses import dataclass
from typing import Final, Literal, TypeAlias

from protocol.events import (
    CommitReceived,
    ConnectionClosed,
    DieReceived,
    Ignored,
    TrialReceived,
)
from protocol.wire import Signals, SignalSizes

__all__ = [
    "OPENFRESCO_VERSION",
    "PROBE_BYTES",
    "SITE_OPEN_DOUBLES",
    "STATUS_COMPLETED",
    "STATUS_RECEIVED",
    "ActorEvent",
    "DaqReceived",
    "DaqRequested",
    "DieReplyReceived",
    "OpenReceived",
    "OpenReplyReceived",
    "ProbeReceived",
    "ProbeReplyReceived",
    "SetupReceived",
    "ShadowEvent",
    "SiteState",
    "SiteTransport",
    "site_data_size",
]

STATUS_COMPLETED: Final = 0.0
"""Slot 0 of the open reply (``OF_ReturnType_completed``)."""
STATUS_RECEIVED: Final = 4.0
"""Slot 0 of the DIE reply (``OF_ReturnType_received``)."""

OPENFRESCO_VERSION: Final = 2.8
"""``atof("2.8.0 (Build 250501)")``: what OpenFresco 2.8.x puts in the open vectors."""
SITE_OPEN_DOUBLES: Final = 256
"""``OF_Network_dataSize``: length of the open/setup vectors whatever D is."""
PROBE_BYTES: Final = 4
SiteTransport: TypeAlias = Literal["tcp", "udp"]


class SiteState(enum.Enum):
    """States of :class:`ActorSession` and :class:`ShadowSession`."""

    AWAIT_PROBE = "AWAIT_PROBE"
    """TCP: the endianness probe has not been exchanged yet."""
    AWAIT_OPEN = "AWAIT_OPEN"
    """The open exchange has not happened yet."""
    AWAIT_SETUP = "AWAIT_SETUP"
    """Opened; the setup vector and its two IDs are not complete yet."""
    READY = "READY"
    MUST_REPLY = "MUST_REPLY"
    """Actor: a reply is owed (probe, open, daq or DIE)."""
    AWAIT_REPLY = "AWAIT_REPLY"
    """Shadow: waiting for the actor's reply."""
    CLOSED = "CLOSED"
    ERROR = "ERROR"


@dataclass(frozen=True, slots=True)
class ProbeReceived:
    """TCP endianness probe (int32 1). Reply with ``send_probe_reply()``."""

    peer_byte_order: Literal["little", "big"]


@dataclass(frozen=True, slots=True)
class OpenReceived:
    """Code 1: ``[1, shadowTag, version]``. Reply with ``send_open_reply()``."""

    shadow_tag: int
    version: float


@dataclass(frozen=True, slots=True)
class SetupReceived:
    """Code 2 and the two IDs: from now on every vector is ``data_size`` doubles."""

    data_size: int
    size_trial: SignalSizes
    size_out: SignalSizes


@dataclass(frozen=True, slots=True)
class DaqRequested:
    """Code 6 (getDaqResponse). Reply with ``send_daq(out)``."""


@dataclass(frozen=True, slots=True)
class ProbeReplyReceived:
    """Shadow side: the actor answered the endianness probe."""

    peer_byte_order: Literal["little", "big"]


@dataclass(frozen=True, slots=True)
class OpenReplyReceived:
    """Shadow side: ``[status 0, actorTag, version]``."""

    actor_tag: int
    version: float
    status: float = STATUS_COMPLETED


@dataclass(frozen=True, slots=True)
class DaqReceived:
    """Shadow side: the out blocks of a code-6 reply."""

    out: Signals


@dataclass(frozen=True, slots=True)
class DieReplyReceived:
    """Shadow side: ``[4 (received), actorTag]``; the connection is finished."""

    actor_tag: int
    status: float = STATUS_RECEIVED


ActorEvent: TypeAlias = (
    ProbeReceived
    | OpenReceived
    | SetupReceived
    | TrialReceived
    | DaqRequested
    | CommitReceived
    | DieReceived
    | Ignored
    | ConnectionClosed
)
ShadowEvent: TypeAlias = (
    ProbeReplyReceived | OpenReplyReceived | DaqReceived | DieReplyReceived | ConnectionClosed
)


def site_data_size(
    size_trial: SignalSizes, size_out: SignalSizes, user_data_size: int = SITE_OPEN_DOUBLES
) -> int:
    """D as ShadowExpSite computes it: ``max(user, 1 + sum(sizeTrial), sum(sizeOut))``."""
    return max(user_data_size, 1 + size_trial.total, size_out.total)
