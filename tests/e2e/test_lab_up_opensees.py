"""Real OpenSeesPy genericClient → bridge → ``sim-actuator serve`` (Modbus TCP, MTS-like stub),
all started by ``fresco-bridge lab up`` from docker/compose.yaml, against the same run with the
damper served in-process (``sim`` controller).

Tolerance (Modbus), derived rather than picked. The register map carries float32 (unit roundoff
u = 2⁻²⁴): the command d reaches the rig as fl32(d) and the force returns as fl32(f). The
bilinear damper is Lipschitz in its input history with constant k0 (a play operator is
non-expansive), so one step's force error is at most δF = u·(max|F| + k0·max|d|). The FE model
propagates force errors linearly: with `algorithm Linear -initial` every step is one solve with
the initial stiffness, and the displacement error is at most ‖h‖₁·δF, where h is the discrete
impulse response (Newmark average acceleration, same M, C, dt) to a unit force on floor 1. The
damper's tangent is k0 (elastic) or α·k0 (yielding); the bound takes the larger ‖h‖₁ of the two
linear systems over the run length. This is a linearised bound (worst case: every rounding
aligned), so the observed error sits well below it; a register map with less resolution than
float32 (e.g. int16 at 1 µm) would exceed it by orders of magnitude.

MTS-like stub: replies carry shortest round-trip decimals, so the result must be identical.
"""

from __future__ import annotations

import tomllib
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from fresco_bridge.config import parse_config
from fresco_bridge.daemon import BridgeThread
from fresco_bridge.integrator import DEMO_FLOOR_MASS, kanai_tajimi
from fresco_bridge.record.export import committed_steps
from tests.support.bridge import run_opensees
from tests.support.lab import DOCKER, lab_up, pid_alive, reference_config

pytestmark = pytest.mark.opensees

G_MM_S2 = 9806.65
DT = 0.01
NSTEPS = 1200
ALPHA_M = 1.2  # mass-proportional damping, 1/s (5 % near 12 rad/s)
U32 = 2.0**-24


def _params(ports: list[int]) -> dict[str, Any]:
    motion = kanai_tajimi(1.5, duration=NSTEPS * DT + 0.5, dt=DT, seed=4)
    return {
        "ports": ports, "masses": [DEMO_FLOOR_MASS, DEMO_FLOOR_MASS], "dt": DT,
        "accel": [float(a) for a in motion.accel], "factor": G_MM_S2, "nsteps": NSTEPS,
        "algorithm": ["Linear", "-initial"], "rayleigh": [ALPHA_M, 0.0, 0.0, 0.0],
    }


def _reference(tmp_path: Path, lab: Any) -> dict[str, Any]:
    text = reference_config(lab, tmp_path / "ref-runs")
    with BridgeThread(parse_config(text, "<reference>"), text,
                      run_dir=tmp_path / "ref-runs") as ref:
        return run_opensees("frame2", **_params([ref.ports["damper"], ref.ports["story2"]]))


def _impulse_l1(k1: float, k2: float, m: float, n: int) -> float:
    """‖h‖₁ of floor displacements (max over floors) after a unit force on floor 1, Newmark
    average acceleration with mass-proportional damping, ``n`` steps of ``DT``."""
    mass = np.diag([m, m])
    stiff = np.array([[k1 + k2, -k2], [-k2, k2]])
    damp = ALPHA_M * mass
    beta, gamma = 0.25, 0.5
    keff = stiff + gamma / (beta * DT) * damp + mass / (beta * DT**2)
    u, v = np.zeros(2), np.zeros(2)
    a = np.linalg.solve(mass, np.array([1.0, 0.0]))  # the impulse: unit force for one step
    total = 0.0
    for step in range(n):
        p = np.zeros(2)
        rhs = (p + mass @ (u / (beta * DT**2) + v / (beta * DT) + (0.5 / beta - 1) * a)
               + damp @ (gamma / (beta * DT) * u + (gamma / beta - 1) * v
                         + DT * (gamma / (2 * beta) - 1) * a))
        if step == 0:
            rhs = rhs + np.array([1.0, 0.0])
        un = np.linalg.solve(keff, rhs)
        an = (un - u) / (beta * DT**2) - v / (beta * DT) - (0.5 / beta - 1) * a
        v = v + DT * ((1 - gamma) * a + gamma * an)
        u, a = un, an
        total += float(np.max(np.abs(u)))
    return total


def _check_record(runs: Path) -> None:
    (run_dir,) = [p for p in runs.iterdir() if p.is_dir()]
    damper = [s for s in committed_steps(run_dir) if s.site == "damper"]
    assert len(damper) == NSTEPS


def test_modbus_lab_matches_the_in_process_run_within_float32(tmp_path: Path) -> None:
    with lab_up(tmp_path / "runs") as lab:
        lab.wait_ready()
        assert set(lab.pids) >= {"sim-actuator", "bridge"}
        got = run_opensees("frame2", timeout=300, **_params(
            [lab.port("LAB_BRIDGE_PORT"), lab.port("LAB_STORY2_PORT")]))
        ref = _reference(tmp_path, lab)
        assert lab.stop() == 0, lab.output()
    assert not any(pid_alive(p) for p in lab.pids.values()), lab.pids
    _check_record(tmp_path / "runs")

    u_got = np.array([got["runs"][0]["u2"], got["runs"][0]["u3"]])
    u_ref = np.array([ref["runs"][0]["u2"], ref["runs"][0]["u3"]])
    rig = tomllib.loads((DOCKER / "rig.toml").read_text())["specimen"]["params"]
    k0, alpha = rig["k0"], rig["alpha"]
    drift = u_ref[0]
    f_max = k0 * np.max(np.abs(drift))  # bilinear: |F| <= k0 |d|
    delta_f = U32 * (f_max + k0 * np.max(np.abs(drift)))
    gain = max(_impulse_l1(k, 10.0, DEMO_FLOOR_MASS, NSTEPS) for k in (k0, alpha * k0))
    bound = gain * delta_f
    err = float(np.max(np.abs(u_got - u_ref)))
    peak = float(np.max(np.abs(u_ref)))
    assert peak > 3 * rig["fy"] / k0, "the run must drive the damper well past yield"
    assert err <= bound, f"max |Δu| {err:.3e} mm > float32 bound {bound:.3e} mm"
    assert err > 0.0, "float32 registers cannot reproduce a double run bit for bit"
    print(f"modbus lab: max |Δu| {err:.3e} mm (relative {err / peak:.2e}), derived bound "
          f"{bound:.3e} mm (relative {bound / peak:.2e}), peak {peak:.2f} mm")


def test_mts_lab_is_identical_to_the_in_process_run(tmp_path: Path) -> None:
    with lab_up(tmp_path / "runs", "--controller", "mts") as lab:
        lab.wait_ready()
        got = run_opensees("frame2", timeout=300, **_params(
            [lab.port("LAB_BRIDGE_PORT"), lab.port("LAB_STORY2_PORT")]))
        ref = _reference(tmp_path, lab)
        assert lab.stop() == 0, lab.output()
    assert "protocol=mts" in lab.output()
    _check_record(tmp_path / "runs")
    assert got["runs"][0]["u2"] == ref["runs"][0]["u2"]
    assert got["runs"][0]["u3"] == ref["runs"][0]["u3"]
