"""The MTS-CSI-like line protocol of the simulated rig (version 1), for both ends.

ASCII lines ending in LF (CR LF accepted), at most :data:`MAX_LINE` bytes; tokens separated by
spaces; verbs case-insensitive. One request line gets exactly one reply line: ``OK`` followed by
``key=value`` pairs, or ``ERR <CODE> <message>``. Floats use Python's shortest round-trip repr,
so they parse back exactly. The verbs and their replies are in ``sim_actuator/README.md``.
"""

from __future__ import annotations

__all__ = [
    "MAX_LINE",
    "PROTOCOL",
    "PROTOCOL_VERSION",
    "MalformedReply",
    "Refused",
    "err",
    "ok",
    "parse_reply",
    "split_request",
]

PROTOCOL = "mts-stub"
PROTOCOL_VERSION = 1
MAX_LINE = 1024
"""Longest request line (bytes, without the terminator)."""


class Refused(Exception):
    """An ``ERR <code> <message>`` reply."""

    def __init__(self, code: str, message: str) -> None:
        super().__init__(f"ERR {code} {message}")
        self.code = code
        self.message = message


class MalformedReply(ValueError):
    """A reply that is neither ``OK key=value…`` nor ``ERR <code> <message>``."""


def ok(**fields: object) -> str:
    """``OK k=v …`` in the given order; floats as their shortest round-trip repr."""
    parts = ["OK"]
    for key, value in fields.items():
        parts.append(f"{key}={value!r}" if isinstance(value, float) else f"{key}={value}")
    return " ".join(parts)


def err(code: str, message: str) -> str:
    """``ERR <CODE> <message>``."""
    return f"ERR {code} {message}"


def split_request(text: str) -> tuple[str, list[str]]:
    """(verb in upper case, arguments); an empty line has the verb ``""``."""
    tokens = text.split()
    if not tokens:
        return "", []
    return tokens[0].upper(), tokens[1:]


def parse_reply(line: str) -> dict[str, str]:
    """The fields of an ``OK`` reply; :class:`Refused` for ``ERR``, :class:`MalformedReply`
    for anything else."""
    head, _, rest = line.strip().partition(" ")
    if head == "ERR":
        code, _, message = rest.partition(" ")
        raise Refused(code, message)
    if head != "OK":
        raise MalformedReply(f"not an OK or ERR reply: {line!r}")
    try:
        return dict(pair.split("=", 1) for pair in rest.split())
    except ValueError:
        raise MalformedReply(f"an OK reply with a field that is not key=value: {line!r}"
                             ) from None
