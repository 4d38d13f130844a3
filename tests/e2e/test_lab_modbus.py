"""Bridge → Modbus adapter → `sim-actuator serve` (a separate process) over real Modbus TCP."""

from __future__ import annotations

import struct
import subprocess
import sys
from pathlib import Path

import pytest

from fresco_bridge.integrator.link import GenericClientLink
from fresco_bridge.record.export import committed_steps
from protocol import Action
from tests.support.bridge import RunningBridge


def _f32(x: float) -> float:
    return float(struct.unpack("<f", struct.pack("<f", x))[0])


@pytest.mark.parametrize("protocol", ["modbus", "mts"])
def test_bridge_drives_sim_actuator_process(tmp_path: Path, protocol: str) -> None:
    proc = subprocess.Popen(
        [sys.executable, "-m", "sim_actuator.cli", "serve", "--protocol", protocol,
         "--port", "0", "--preset", "ideal-elastic"],
        stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
    )
    try:
        assert proc.stdout is not None
        ready = proc.stdout.readline()
        err = "" if ready else (proc.stderr.read() if proc.stderr else "")
        assert ready.startswith("sim-actuator ready"), ready + err
        port = int(ready.split("port=")[1].split()[0])
        toml = f"""
[bridge]
controller_timeout = 5.0
[[sites]]
name = "act"
port = 0
[sites.controller]
kind = "{protocol}"
port = {port}
stiffness = 68.0
"""
        with RunningBridge(toml, tmp_path) as b:
            with GenericClientLink("127.0.0.1", b.ports["act"], 1, data_size=1) as link:
                assert link.matrix(Action.GET_TANGENT_STIFF)[0][0] == 68.0
                for i in range(1, 21):
                    d = 0.05 * i * (-1) ** i
                    link.set_trial((d,), time=0.01 * i)
                    f = link.force()[0]
                    expected = 68.0 * d if protocol == "mts" else _f32(68.0 * _f32(d))
                    assert f == pytest.approx(expected, rel=1e-6, abs=1e-6)
                    link.commit()
                link.force()
            run_dir = b.run_dir
        steps = committed_steps(run_dir)
        assert len(steps) == 20
        assert steps[-1].meas_force[0] == pytest.approx(68.0 * 1.0, rel=1e-6)
    finally:
        proc.terminate()
        proc.wait(10)
