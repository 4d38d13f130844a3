"""Run a command on a real pseudo-terminal (what a person at a shell sees), with a deadline."""

from __future__ import annotations

import os
import pty
import select
import subprocess
import time
from collections.abc import Sequence

from tests.support.paths import REPO


def run_on_terminal(argv: Sequence[str], *, timeout: float = 120.0,
                    env: dict[str, str] | None = None) -> tuple[int, bytes]:
    """Run ``argv`` with stdout and stderr on one pty; its exit code and every byte it wrote."""
    leader, follower = pty.openpty()
    proc = subprocess.Popen(list(argv), stdin=subprocess.DEVNULL, stdout=follower,
                            stderr=follower, cwd=REPO, env={**os.environ, **(env or {}),
                                                            "COLUMNS": "120", "TERM": "xterm"})
    os.close(follower)
    out = bytearray()
    deadline = time.monotonic() + timeout
    try:
        while time.monotonic() < deadline:
            ready, _, _ = select.select([leader], [], [], 0.2)
            if ready:
                try:
                    data = os.read(leader, 65536)
                except OSError:  # EIO: every writer closed the pty
                    break
                if not data:
                    break
                out += data
            elif proc.poll() is not None:
                break
        else:
            raise AssertionError(f"{argv} still running after {timeout} s; output:\n{out!r}")
        return proc.wait(timeout=10), bytes(out)
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.wait(10)
        os.close(leader)
