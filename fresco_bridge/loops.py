"""The event loop the daemon runs on (``[bridge] event_loop``).

Every message of a session passes through the loop (poll, read, callback, write): with the
standard library's pure-Python selector loop that is a large share of the bridge's CPU per step.
uvloop (libuv, in C) runs the same asyncio code with less of it; ``auto`` uses it when it is
installed and falls back to asyncio otherwise.
"""

from __future__ import annotations

import asyncio
import importlib.util
import logging
from collections.abc import Callable, Coroutine
from typing import Any, Literal, TypeVar

from .config import ConfigError

log = logging.getLogger("fresco_bridge")
T = TypeVar("T")
LoopKind = Literal["auto", "uvloop", "asyncio"]


class EventLoopError(ConfigError):
    """The configured event loop is not available."""


def loop_factory(kind: LoopKind) -> Callable[[], asyncio.AbstractEventLoop] | None:
    """The factory of the event loop ``kind`` names (None: asyncio's default)."""
    if kind == "asyncio":
        return None
    if importlib.util.find_spec("uvloop") is None:
        if kind == "uvloop":
            raise EventLoopError("[bridge] event_loop = \"uvloop\" but uvloop is not installed "
                                 "(pip install uvloop, or event_loop = \"asyncio\")")
        return None
    import uvloop

    return uvloop.new_event_loop


def run(main: Coroutine[Any, Any, T], kind: LoopKind) -> T:
    """``asyncio.run(main)`` on the event loop ``kind`` names."""
    factory = loop_factory(kind)
    with asyncio.Runner(loop_factory=factory) as runner:
        log.debug("event loop: %s", type(runner.get_loop()).__module__)
        return runner.run(main)
