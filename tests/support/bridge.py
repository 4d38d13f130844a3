"""Run a real bridge (its own event loop in a thread) and real OpenSeesPy clients (subprocesses)."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path
from typing import Any

from fresco_bridge.config import parse_config
from fresco_bridge.daemon import BridgeThread
from fresco_bridge.loops import LoopKind
from fresco_bridge.opensees_runtime import opensees_env as opensees_env  # the one home

OPENSEES_SCRIPT = Path(__file__).resolve().parent / "opensees_client.py"
"""The OpenSeesPy client scenarios, run as a script in its own process."""


def RunningBridge(config_toml: str, run_root: Path,
                  event_loop: LoopKind = "asyncio", base: Path | None = None) -> BridgeThread:
    """``with RunningBridge(toml, tmp_path) as b: b.ports['site']`` — a real bridge in a thread
    (``base``: the folder relative data paths resolve against, as a config file's)."""
    return BridgeThread(parse_config(config_toml, "<test config>", base=base), config_toml,
                        run_dir=run_root, event_loop=event_loop)


def run_opensees(scenario: str, timeout: float = 120.0, **params: Any) -> dict[str, Any]:
    """Run ``tests/support/opensees_client.py`` in a real OpenSeesPy process; its JSON result."""
    try:
        proc = subprocess.run(
            [sys.executable, str(OPENSEES_SCRIPT), scenario, json.dumps(params)],
            env=opensees_env(), capture_output=True, text=True, timeout=timeout,
        )
    except subprocess.TimeoutExpired as exc:
        raise AssertionError(
            f"OpenSeesPy scenario {scenario} hung for {timeout:g} s (a missing reply?)\n"
            f"stdout tail: {str(exc.stdout)[-1500:]}\nstderr tail: {str(exc.stderr)[-1500:]}"
        ) from None
    out = [ln for ln in proc.stdout.splitlines() if ln.startswith("RESULT ")]
    if proc.returncode != 0 or not out:
        raise AssertionError(
            f"OpenSeesPy scenario {scenario} failed (rc {proc.returncode})\n"
            f"stdout tail: {proc.stdout[-2000:]}\nstderr tail: {proc.stderr[-2000:]}"
        )
    result: dict[str, Any] = json.loads(out[-1][len("RESULT "):])
    return result
