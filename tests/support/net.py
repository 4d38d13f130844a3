"""Loopback ports for tests: free ones, and waiting for one to open or close (with a deadline)."""

from __future__ import annotations

import socket
import time

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
