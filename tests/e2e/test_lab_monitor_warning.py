"""The online monitor's warning through a real bridge: a lagging rig (``sim-actuator`` with the
servo-hydraulic preset, over Modbus) trips ``warn_tracking_error``; the event is recorded with
the committed step it belongs to, once (edge-triggered), and matches the recorded monitor line.
"""

from __future__ import annotations

from pathlib import Path

from fresco_bridge.integrator.link import GenericClientLink
from fresco_bridge.record import read_record
from tests.support.bridge import RunningBridge
from tests.support.controller import bridge_toml, sim_actuator

THRESHOLD = 0.008  # mm: above the settled lag of slow steps (~0.004), below that of fast ones


def test_a_lagging_rig_trips_the_tracking_error_warning_at_its_step(
    tmp_path: Path, free_port: int
) -> None:
    port = free_port
    toml = bridge_toml("modbus", port, ramp_time=0.02) + (
        f"\n[telemetry]\nwarn_tracking_error = {THRESHOLD}\n")
    with sim_actuator("modbus", port, "--preset", "servo-hydraulic", "--time-scale", "1.0"), \
            RunningBridge(toml, tmp_path) as b:
        with GenericClientLink("127.0.0.1", b.ports["act"], 1, data_size=1,
                               timeout=10.0) as link:
            for i in range(1, 41):  # accelerating: the servo lag's error grows with speed
                link.set_trial((0.0025 * i * i,), time=0.01 * i)
                link.force()
                link.commit()
        run_dir = b.run_dir
    records = list(read_record(run_dir))
    warnings = [r for r in records if r.get("event") == "monitor-warning"]
    assert len(warnings) == 1, warnings  # edge-triggered: once per crossing
    w = warnings[0]
    assert "|tracking error|" in w["reason"] and f"> {THRESHOLD:g}" in w["reason"]
    monitors = {r["step"]: r for r in records if r["kind"] == "monitor"}
    assert abs(monitors[w["step"]]["err"]) > THRESHOLD  # the step the event names tripped it
    assert all(abs(monitors[s]["err"]) <= THRESHOLD for s in monitors if s < w["step"])
