"""Loopback ports for tests: free ones, waiting for one to open or close (with a deadline), and
peers that reset at once, also while the bridge's loop is held."""

from __future__ import annotations

import contextlib
import socket
import struct
import threading
import time
from collections.abc import Iterator
from typing import TYPE_CHECKING

if TYPE_CHECKING:
    from fresco_bridge.daemon import BridgeThread

HOST = "127.0.0.1"


def free_ports(n: int) -> list[int]:
    """``n`` distinct ports the kernel just handed out (closed again: a small race is left)."""
    socks = []
    try:
        for _ in range(n):
            s = socket.socket()
            s.bind((HOST, 0))
            socks.append(s)
        return [s.getsockname()[1] for s in socks]
    finally:
        for s in socks:
            s.close()


def port_open(port: int, host: str = HOST) -> bool:
    """Something accepts TCP connections on ``host:port``."""
    with socket.socket() as s:
        s.settimeout(0.5)
        return s.connect_ex((host, port)) == 0


def wait_port(port: int, *, is_open: bool, deadline_s: float = 10.0, host: str = HOST) -> None:
    """Until ``port`` is open (or closed); TimeoutError after ``deadline_s``."""
    end = time.monotonic() + deadline_s
    while port_open(port, host) is not is_open:
        if time.monotonic() > end:
            raise TimeoutError(f"port {port} still {'closed' if is_open else 'open'}")
        time.sleep(0.02)


def connect_and_reset(port: int) -> None:
    """Connect, then reset (``SO_LINGER`` 0): a peer gone as soon as it came."""
    with socket.socket() as s:
        s.setsockopt(socket.SOL_SOCKET, socket.SO_LINGER, struct.pack("ii", 1, 0))
        s.settimeout(5.0)
        s.connect((HOST, port))
    # closed with linger 0: a RST


BATCH = 30
"""Connections reset while the loop is held (within the listener's backlog)."""


@contextlib.contextmanager
def loop_held(bridge: BridgeThread) -> Iterator[None]:
    """The bridge's loop blocked (as by a burst of work): connections wait in the backlog."""
    held, release = threading.Event(), threading.Event()

    def hold() -> None:
        held.set()
        release.wait(10)

    holder = threading.Thread(target=bridge.call, args=(hold,), daemon=True)
    holder.start()
    assert held.wait(10), "the bridge's loop was not held"
    try:
        yield
    finally:
        release.set()
        holder.join(10)
