"""Drive a coroutine synchronously until it first suspends.

The hot path of a site (decode a request, ask the controller, encode the reply) completes
without ever suspending when the controller is in-process. Running it as a task per message
would add a scheduler round trip to every request (a visible share of an in-process step:
BENCHMARKS.md, "Step cost and scaling"); instead the connection steps the handler coroutine
directly and only hands it to a task when it really waits on something (a network controller).
Python 3.12's eager task factory does the same; we are on 3.11.
"""

from __future__ import annotations

import asyncio
from collections.abc import Coroutine, Generator
from typing import Any, Generic, TypeVar

T = TypeVar("T")


class Suspended(Generic[T]):
    """A coroutine that suspended on ``first``; ``task()`` finishes it under the event loop."""

    __slots__ = ("_coro", "_first")

    def __init__(self, coro: Coroutine[Any, Any, T], first: Any) -> None:
        self._coro = coro
        self._first = first

    def task(self, name: str | None = None) -> asyncio.Task[T]:
        return asyncio.get_running_loop().create_task(self._finish(), name=name)

    async def _finish(self) -> T:
        return await _Continuation(self._coro, self._first)


class _Continuation(Generic[T]):
    """Re-yield what the inner coroutine yielded, so the enclosing task waits on it."""

    __slots__ = ("_coro", "_first")

    def __init__(self, coro: Coroutine[Any, Any, T], first: Any) -> None:
        self._coro = coro
        self._first = first

    def __await__(self) -> Generator[Any, None, T]:
        coro, to_yield = self._coro, self._first
        while True:
            try:
                yield to_yield
            except GeneratorExit:
                coro.close()
                raise
            except BaseException as exc:  # cancellation and friends go to the inner coroutine
                try:
                    to_yield = coro.throw(exc)
                except StopIteration as stop:
                    return stop.value  # type: ignore[no-any-return]
            else:
                try:
                    to_yield = coro.send(None)
                except StopIteration as stop:
                    return stop.value  # type: ignore[no-any-return]


def start_eager(coro: Coroutine[Any, Any, T]) -> T | Suspended[T]:
    """Run ``coro`` until it returns (its value) or suspends (a ``Suspended`` to finish).

    Exceptions raised before the first suspension propagate to the caller. Code run this way
    must not need ``asyncio.current_task()`` before it first awaits (``asyncio.timeout``
    does; ``asyncio.wait_for`` does not).
    """
    try:
        first = coro.send(None)
    except StopIteration as stop:
        return stop.value  # type: ignore[no-any-return]
    return Suspended(coro, first)
