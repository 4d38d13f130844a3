"""One operator request line as JSON, bounded in depth as the reader bounds it in size.

The control socket caps a line at 4 KiB and MQTT a command at 1 KiB, but Python's decoder
recurses once per nesting level: 4,000 ``[`` under the cap raised ``RecursionError`` out of the
client's task (a traceback in the log, no reply). ``decode`` counts the nesting before decoding
and turns every way a line can be wrong into one ``RequestJsonError`` of one line (what, where),
so both operator paths answer and log it the same way.
"""

from __future__ import annotations

import json
import re

__all__ = ["MAX_DEPTH", "RequestJsonError", "decode"]

MAX_DEPTH = 16
"""Nesting levels a request may use (a request is one flat object: depth 1)."""

_TOKENS = re.compile(r'"(?:[^"\\]|\\.)*"|[\[\]{}]', re.DOTALL)
"""A whole string (its brackets are text) or a bracket."""


class RequestJsonError(ValueError):
    """A request line that is not a small JSON document; the message is one line."""


def decode(data: bytes, max_depth: int = MAX_DEPTH) -> object:
    """The JSON value of ``data``, or ``RequestJsonError`` saying what is wrong and where."""
    try:
        text = data.decode("utf-8")
    except UnicodeDecodeError as exc:
        raise RequestJsonError(f"not UTF-8 at byte {exc.start}") from None
    depth = 0
    for match in _TOKENS.finditer(text):
        token = match.group()
        if token in "[{":
            depth += 1
            if depth > max_depth:
                raise RequestJsonError(f"nested deeper than {max_depth} levels at character "
                                       f"{match.start()}")
        elif token in "]}":
            depth -= 1
    try:
        return json.loads(text)
    except json.JSONDecodeError as exc:
        raise RequestJsonError(f"not JSON ({exc.msg} at character {exc.pos})") from None
    except (ValueError, RecursionError) as exc:  # a number past int's digit limit, …
        raise RequestJsonError(f"not a usable JSON value ({str(exc).splitlines()[0][:120]})"
                               ) from None
