"""Mosquitto for tests: the machine's broker on 127.0.0.1:1883 (reachable, or started if
installed), a private broker a test may kill, and an independent ``mosquitto_sub`` subscriber.

Fixtures: ``system_broker`` and ``own_broker`` in ``tests/conftest.py``; modules that need the
Mosquitto tools set ``pytestmark = needs_mosquitto``.
"""

from __future__ import annotations

import asyncio
import os
import shutil
import subprocess
import time
from pathlib import Path

import pytest

from tests.support.net import HOST, free_ports, port_open, wait_port

SYSTEM_PORT = 1883

needs_mosquitto = pytest.mark.skipif(
    not all(shutil.which(tool) for tool in ("mosquitto", "mosquitto_sub", "mosquitto_pub",
                                            "stdbuf")),
    reason="needs mosquitto, mosquitto_sub, mosquitto_pub and stdbuf on PATH",
)
"""The skip rule of every test module that runs Mosquitto or its command-line clients."""


def broker_up(deadline_s: float = 5.0) -> bool:
    """True when a broker answers on 127.0.0.1:1883, starting Debian's Mosquitto if needed."""
    if port_open(SYSTEM_PORT):
        return True
    if shutil.which("mosquitto") is None:
        return False
    subprocess.run(["mosquitto", "-d", "-c", "/etc/mosquitto/mosquitto.conf"], check=False)
    end = time.monotonic() + deadline_s
    while time.monotonic() < end:
        if port_open(SYSTEM_PORT):
            return True
        time.sleep(0.05)
    return False


class OwnBroker:
    """A private Mosquitto on a free port that the test may kill and restart."""

    def __init__(self, workdir: Path) -> None:
        self.port = free_ports(1)[0]
        self.conf = workdir / "mosquitto.conf"
        lines = [f"listener {self.port} {HOST}", "allow_anonymous true", "persistence false",
                 f"log_dest file {workdir / 'mosquitto.log'}"]
        if os.geteuid() == 0:
            lines.append("user root")
        self.conf.write_text("\n".join(lines) + "\n")
        self.proc: subprocess.Popen[bytes] | None = None

    def start(self) -> None:
        self.proc = subprocess.Popen(["mosquitto", "-c", str(self.conf)])
        wait_port(self.port, is_open=True)

    def kill(self) -> None:
        assert self.proc is not None
        self.proc.kill()
        self.proc.wait(timeout=10)
        self.proc = None

    def close(self) -> None:
        if self.proc is not None:
            self.kill()


class Subscriber:
    """``mosquitto_sub -v`` in a subprocess; lines are collected as they arrive."""

    def __init__(self, proc: asyncio.subprocess.Process) -> None:
        self.proc = proc
        self.messages: list[tuple[str, bytes]] = []
        self._subscribed = asyncio.Event()
        self._reader = asyncio.create_task(self._read())

    @classmethod
    async def start(cls, port: int, topic: str, count: int) -> Subscriber:
        proc = await asyncio.create_subprocess_exec(
            "stdbuf", "-oL", "mosquitto_sub", "-d", "-h", HOST, "-p", str(port), "-t", topic,
            "-q", "1", "-v", "-C", str(count),
            stdout=asyncio.subprocess.PIPE, stderr=asyncio.subprocess.DEVNULL)
        sub = cls(proc)
        async with asyncio.timeout(10):
            await sub._subscribed.wait()
        return sub

    async def _read(self) -> None:
        assert self.proc.stdout is not None
        async for raw in self.proc.stdout:
            line = raw.rstrip(b"\n")
            if line.startswith(b"Subscribed (mid"):
                self._subscribed.set()
            elif not line.startswith(b"Client ") and b" " in line:
                topic, payload = line.split(b" ", 1)
                self.messages.append((topic.decode(), payload))

    async def finish(self, deadline_s: float = 20.0) -> list[tuple[str, bytes]]:
        """Wait until mosquitto_sub has its ``-C`` messages and exits."""
        async with asyncio.timeout(deadline_s):
            await self.proc.wait()
            await self._reader
        return self.messages

    def kill(self) -> None:
        if self.proc.returncode is None:
            self.proc.kill()


def clear_retained(port: int, *topics: str) -> None:
    """Delete retained messages on ``topics`` (an empty retained publish each)."""
    for topic in topics:
        subprocess.run(["mosquitto_pub", "-h", HOST, "-p", str(port), "-t", topic, "-r", "-n"],
                       check=True, timeout=10)
