"""Events produced by the sessions' ``next_event()`` and the two sentinels.

Events are small frozen dataclasses so the daemon can ``match`` on them. The same
classes are used by the element and the site protocol wherever the meaning is the same
(a trial, a commit, a DIE, an ignored code, the end of the stream).
"""

from __future__ import annotations

import enum
from dataclasses import dataclass
from typing import Final

from protocol.wire import Action, Signals, SignalSizes, SizeID

__all__ = [
    "NEED_DATA",
    "PAUSED",
    "CommitReceived",
    "ConnectionClosed",
    "DieReceived",
    "Ignored",
    "ReplyReceived",
    "ReplyRequested",
    "Sentinel",
    "SizeReceived",
    "TrialReceived",
]


class Sentinel(enum.Enum):
    """Non-event results of ``next_event()``."""

    NEED_DATA = "NEED_DATA"
    """Feed more bytes with ``receive_data`` before the next event can be decoded."""
    PAUSED = "PAUSED"
    """A reply is owed: call a ``send_*`` method before reading further events."""

    def __repr__(self) -> str:
        return self.value


NEED_DATA: Final = Sentinel.NEED_DATA
PAUSED: Final = Sentinel.PAUSED


@dataclass(frozen=True, slots=True)
class SizeReceived:
    """The element-protocol size ID arrived and was accepted."""

    size_id: SizeID


@dataclass(frozen=True, slots=True)
class TrialReceived:
    """Code 3 (setTrialResponse): the only message that carries fresh trial data."""

    trial: Signals


@dataclass(frozen=True, slots=True)
class CommitReceived:
    """Code 5 (commitState): the step is over; its payload is stale and ignored."""


@dataclass(frozen=True, slots=True)
class ReplyRequested:
    """Codes 6..15: the server owes exactly one reply before it may read further."""

    action: Action


@dataclass(frozen=True, slots=True)
class DieReceived:
    """Code 99. Element protocol: no reply. Site protocol: reply with ``send_die_reply``.

    ``peer_tag`` is the ShadowExpSite tag from slot 1 (site protocol only).
    """

    peer_tag: int | None = None


@dataclass(frozen=True, slots=True)
class Ignored:
    """A code that gets no reply: 1, 2, 4, 98, unknown or non-integer codes (spec §3.5)."""

    code: float


@dataclass(frozen=True, slots=True)
class ConnectionClosed:
    """EOF was fed. ``clean`` is False when it cut an item short (``pending_bytes`` > 0)."""

    clean: bool
    pending_bytes: int = 0


@dataclass(frozen=True, slots=True)
class ReplyReceived:
    """Client side: the server's reply to a request, all dataSize values from slot 0."""

    action: Action
    values: tuple[float, ...]

    def first(self, count: int) -> tuple[float, ...]:
        """Slots 0..count-1 (e.g. the genericClient force block)."""
        if count > len(self.values):
            raise ValueError(f"asked for {count} values of a {len(self.values)}-slot reply")
        return self.values[:count]

    def force(self, n: int) -> tuple[float, ...]:
        """genericClient layout: the n forces are slots 0..n-1."""
        return self.first(n)

    def matrix(self, n: int) -> tuple[tuple[float, ...], ...]:
        """The n x n matrix as rows, decoded from column-major slots (slot c*n + r = K[r][c])."""
        flat = self.first(n * n)
        return tuple(tuple(flat[c * n + r] for c in range(n)) for r in range(n))

    def daq(self, sizes: SignalSizes) -> Signals:
        """All daq blocks packed from slot 0 (reply to code 6, or an adapter's code 10)."""
        if sizes.total > len(self.values):
            raise ValueError(
                f"daq sizes need {sizes.total} slots but the reply has {len(self.values)}"
            )
        blocks: list[tuple[float, ...]] = []
        slot = 0
        for count in sizes.as_tuple():
            blocks.append(self.values[slot : slot + count])
            slot += count
        return Signals(*blocks)
