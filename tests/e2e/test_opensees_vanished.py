"""A real OpenSeesPy ``genericClient -udp`` killed mid-analysis (no DIE) must not lock its site:
after ``bridge.session_idle_timeout`` the site is free and the next OpenSees process is served.
A site that stayed locked would leave the second one waiting for the handshake reply forever
(its own deadline here: the harness timeout).
"""

from __future__ import annotations

from pathlib import Path

import pytest

from fresco_bridge.record import read_record
from tests.support.bridge import RunningBridge, run_opensees
from tests.support.opensees_frame import site
from tests.support.spied_bridge import wait_for

pytestmark = pytest.mark.opensees


def test_a_killed_udp_opensees_frees_its_site_for_the_next_one(tmp_path: Path) -> None:
    cfg = '[bridge]\nrun_name = "vanished"\nsession_idle_timeout = 1.0\n' + site(
        "spring", 0, dofs=1, setup="NoTransformation", model="elastic", params={"k": 100.0},
        transport="udp")
    with RunningBridge(cfg, tmp_path) as bridge:
        port = bridge.ports["spring"]
        killed = run_opensees("static_1dof", port=port, load=30.0, nsteps=3, udp=True,
                              killed_after=2)
        assert killed["u"] == pytest.approx([0.1, 0.2], rel=1e-12)
        wait_for(lambda: bridge.call(lambda: bridge.bridge.sites["spring"].peer) == "",
                 "the vanished client's session to end", timeout=15)
        res = run_opensees("static_1dof", port=port, load=30.0, nsteps=3, udp=True,
                           timeout=60.0)
        assert res["u"] == pytest.approx([0.1, 0.2, 0.3], rel=1e-12)
        closes = [r["reason"] for r in read_record(bridge.run_dir)
                  if r.get("event") == "session-close"]
    assert "no message from the client" in closes[0] and "client sent DIE" in closes[1]


def test_a_udp_opensees_started_while_a_killed_one_holds_the_site_is_served(
    tmp_path: Path
) -> None:
    """OpenSees sends its handshake once: queued while the killed client's session is open,
    answered when the idle deadline ends it, so the new analysis runs without a restart."""
    cfg = '[bridge]\nrun_name = "queued"\nsession_idle_timeout = 2.0\n' + site(
        "spring", 0, dofs=1, setup="NoTransformation", model="elastic", params={"k": 100.0},
        transport="udp")
    with RunningBridge(cfg, tmp_path) as bridge:
        port = bridge.ports["spring"]
        run_opensees("static_1dof", port=port, load=30.0, nsteps=3, udp=True, killed_after=2)
        res = run_opensees("static_1dof", port=port, load=30.0, nsteps=3, udp=True,
                           timeout=60.0)  # at once: the killed one still holds the site
        assert res["u"] == pytest.approx([0.1, 0.2, 0.3], rel=1e-12)
        wait_for(lambda: len(_closes(bridge.run_dir)) == 2, "both sessions to be closed")
        closes = _closes(bridge.run_dir)
    assert "no message from the client" in closes[0] and "client sent DIE" in closes[1]


def _closes(run_dir: Path) -> list[str]:
    return [r["reason"] for r in read_record(run_dir) if r.get("event") == "session-close"]
