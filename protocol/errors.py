"""Typed errors of the sans-IO codec.

The split follows h11: a *local* error means our own code asked for something the
protocol state does not allow (a bug on our side, the connection may still be fine);
a *remote* error means the peer sent bytes that cannot be a valid message (the
connection must be dropped). Messages always say what, where and why.
"""

from __future__ import annotations

__all__ = ["LocalProtocolError", "ProtocolError", "RemoteProtocolError"]


class ProtocolError(Exception):
    """Base class of every error raised by :mod:`protocol`."""


class LocalProtocolError(ProtocolError):
    """We tried to send something illegal in the current state (or with wrong sizes)."""


class RemoteProtocolError(ProtocolError):
    """The peer sent something illegal; the session is now in its ERROR state."""
