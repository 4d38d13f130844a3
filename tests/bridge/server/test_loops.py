"""``[bridge] event_loop``: the loop ``serve`` runs on, and a clear error when it is missing."""

from __future__ import annotations

import asyncio
import importlib.util

import pytest

from fresco_bridge import loops
from fresco_bridge.config import ConfigError, parse_config


def test_asyncio_is_the_standard_loop() -> None:
    assert loops.loop_factory("asyncio") is None


def test_auto_and_uvloop_run_on_uvloop_when_it_is_installed() -> None:
    if importlib.util.find_spec("uvloop") is None:
        pytest.skip("uvloop is not installed")
    for kind in ("auto", "uvloop"):
        async def loop_module() -> str:
            return type(asyncio.get_running_loop()).__module__

        assert loops.run(loop_module(), kind).startswith("uvloop")  # type: ignore[arg-type]


def test_a_missing_uvloop_is_a_config_error_or_falls_back(
        monkeypatch: pytest.MonkeyPatch) -> None:
    real = importlib.util.find_spec
    monkeypatch.setattr(importlib.util, "find_spec",
                        lambda name, *a: None if name == "uvloop" else real(name, *a))
    assert loops.loop_factory("auto") is None
    with pytest.raises(ConfigError, match='event_loop = "uvloop" but uvloop is not installed'):
        loops.loop_factory("uvloop")


def test_the_config_key_is_validated() -> None:
    base = '[[sites]]\nname = "s"\nport = 0\ndofs = 1\n[sites.controller]\nkind = "sim"\n'
    assert parse_config(base).bridge.event_loop == "auto"
    with pytest.raises(ConfigError, match="event_loop"):
        parse_config('[bridge]\nevent_loop = "trio"\n' + base)
