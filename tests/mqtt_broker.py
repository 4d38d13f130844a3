"""The machine's Mosquitto on 127.0.0.1:1883 for tests: reachable, or started if installed."""

from __future__ import annotations

import shutil
import socket
import subprocess
import time

HOST, PORT = "127.0.0.1", 1883


def _reachable() -> bool:
    try:
        socket.create_connection((HOST, PORT), timeout=1).close()
        return True
    except OSError:
        return False


def broker_up(deadline_s: float = 5.0) -> bool:
    """True when a broker answers on 127.0.0.1:1883, starting Debian's Mosquitto if needed."""
    if _reachable():
        return True
    if shutil.which("mosquitto") is None:
        return False
    subprocess.run(["mosquitto", "-d", "-c", "/etc/mosquitto/mosquitto.conf"], check=False)
    end = time.monotonic() + deadline_s
    while time.monotonic() < end:
        if _reachable():
            return True
        time.sleep(0.05)
    return False
