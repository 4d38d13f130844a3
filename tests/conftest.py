"""Fixtures shared by every test folder.

The helpers behind them are plain modules in ``tests/support/`` (import them as
``from tests.support.bridge import RunningBridge``): ``paths`` (the repository, ``../shared``),
``bridge`` (a real bridge in a thread, real OpenSeesPy clients), ``broker`` (Mosquitto),
``net`` (ports), ``lab`` (``fresco-bridge lab up``), ``controller`` (``sim-actuator serve``
processes), ``recorded_run`` (real run directories), ``spied_bridge`` (a bridge on an elastic
specimen with limits and a spy on its controller).

The step path runs compiled (mypyc, as installed); ``FRESCO_BRIDGE_PURE=1`` runs the pure
sources of the same modules instead (``fresco_bridge/__init__.py`` installs the finder before
anything else of ours is imported; subprocesses inherit it). ``make test`` runs the protocol,
record and server tests in both modes; the header of the report says which.
"""

from __future__ import annotations

from collections.abc import Callable, Iterator
from contextlib import ExitStack
from pathlib import Path

import pytest
from hypothesis import settings

from fresco_bridge import _compiled
from fresco_bridge.daemon import BridgeThread
from tests.support.bridge import RunningBridge
from tests.support.broker import SYSTEM_PORT, OwnBroker, broker_up
from tests.support.net import free_ports
from tests.support.paths import SHARED

# No timed assertions in tests: hypothesis' per-example deadline (200 ms) failed a pure
# encoder test when a loaded machine stalled one example for 936 ms. Every wait that matters
# has its own deadline in the test itself.
settings.register_profile("fresco-bridge", deadline=None)
settings.load_profile("fresco-bridge")


def pytest_report_header() -> str:
    compiled = _compiled.compiled_modules()
    mode = ("pure sources (FRESCO_BRIDGE_PURE=1)" if _compiled.pure_requested()
            else f"compiled ({sum(compiled.values())} of {len(compiled)} modules)")
    return f"fresco-bridge step path: {mode}"


@pytest.fixture(scope="session")
def shared_dir() -> Path:
    """``../shared`` (CI has it beside the clone); tests needing it skip when it is absent."""
    if not SHARED.is_dir():
        pytest.skip(f"../shared not found at {SHARED}")
    return SHARED


@pytest.fixture
def run_bridge(tmp_path: Path) -> Iterator[Callable[[str], BridgeThread]]:
    """``bridge = run_bridge(toml)``: a real bridge in its own thread, run directories under
    ``tmp_path``, stopped when the test ends (``bridge.ports['site']`` for its ports)."""
    with ExitStack() as stack:

        def start(config_toml: str) -> BridgeThread:
            return stack.enter_context(RunningBridge(config_toml, tmp_path))

        yield start


@pytest.fixture(scope="session")
def system_broker() -> int:
    """The machine's Mosquitto on 127.0.0.1:1883 (started when installed), else skip."""
    if not broker_up():
        pytest.skip("no Mosquitto on 127.0.0.1:1883 and it could not be started")
    return SYSTEM_PORT


@pytest.fixture
def own_broker(tmp_path: Path) -> Iterator[OwnBroker]:
    """A private Mosquitto on a free port that the test may kill and restart."""
    broker = OwnBroker(tmp_path)
    broker.start()
    try:
        yield broker
    finally:
        broker.close()


@pytest.fixture
def free_port() -> int:
    """A port the kernel just handed out (closed again: a small race is left)."""
    return free_ports(1)[0]
