"""OpenSeesPy scenarios of the tangent and setup benchmarks, each run in its own process.

Usage: python -m benchmarks._tangent_peer SCENARIO JSON_PARAMS — prints one ``RESULT {json}``.
"""

from __future__ import annotations

import json
import math
import sys
from typing import Any

import openseespy.opensees as ops  # type: ignore[import-untyped]


def sdof_newton(p: dict[str, Any]) -> dict[str, Any]:
    """A mass on a ``genericClient`` spring (the bridge's site) under a sine load, Newmark +
    Newton: the Newton iterations of every step (each one a physical move of the actuator)."""
    ops.wipe()
    ops.model("basic", "-ndm", 1, "-ndf", 1)
    ops.node(1, 0.0)
    ops.mass(1, p["mass"])
    ops.element("genericClient", 1, "-node", 1, "-dof", 1, "-server", p["port"], "127.0.0.1")
    # active past the last step (at t = tEnd, rounding may switch a Trig series off)
    ops.timeSeries("Trig", 1, 0.0, p["dt"] * (p["nsteps"] + 1), p["period"], "-factor", p["load"])
    ops.pattern("Plain", 1, 1)
    ops.load(1, 1.0)
    ops.system("BandGeneral")
    ops.numberer("Plain")
    ops.constraints("Plain")
    ops.test("NormDispIncr", p["tol"], 100)
    ops.algorithm("Newton")
    ops.integrator("Newmark", 0.5, 0.25)
    ops.analysis("Transient")
    iters, u = [], []
    for _ in range(p["nsteps"]):
        if ops.analyze(1, p["dt"]) != 0:
            raise RuntimeError("transient analysis failed")
        iters.append(ops.testIter())
        u.append(ops.nodeDisp(1, 1))
    ops.wipe()
    return {"iters": iters, "u": u}


def column3(p: dict[str, Any]) -> dict[str, Any]:
    """A column's top platform (x, y, θ) with lumped mass and inertia under a horizontal sine
    load and gravity. ``port``: one 3-DOF ``genericClient`` (the bridge's ThreeActuators2d
    site with elastic actuators); else the same three actuators as corotational trusses in
    OpenSees between the ground and rigid links to the control point — the setup's
    transformation done by hand."""
    ops.wipe()
    ops.model("basic", "-ndm", 2, "-ndf", 3)
    ops.node(1, 0.0, 0.0)
    ops.mass(1, p["mass"], p["mass"], p["inertia"])
    if p.get("port") is not None:
        ops.element("genericClient", 1, "-node", 1, "-dof", 1, 2, 3,
                    "-server", p["port"], "127.0.0.1")
    else:
        ops.uniaxialMaterial("Elastic", 1, p["k"])  # truss: EA/L → k·La with A = 1
        ops.geomTransf("Corotational", 1)
        tag = 10
        for i, ((px, py), (gx, gy)) in enumerate(p["links"]):
            joint, ground = tag + 2 * i, tag + 2 * i + 1
            ops.node(joint, px, py)
            ops.node(ground, gx, gy)
            ops.fix(ground, 1, 1, 1)
            # the platform: an exactly rigid link would be a nonlinear constraint, which
            # OpenSees' rigidLink (a constant, small-rotation matrix) is not; a corotational
            # beam ``stiff`` times the actuators' stiffness is exact in its rigid-body motion
            # and deforms by force / stiffness
            big = p["stiff"] * p["k"] * math.hypot(px, py)
            ops.element("elasticBeamColumn", 200 + i, 1, joint, 1.0, big, big * 1e6, 1)
            length = math.hypot(px - gx, py - gy)
            ops.uniaxialMaterial("Elastic", 100 + i, p["k"] * length)
            ops.element("corotTruss", 100 + i, ground, joint, 1.0, 100 + i)
    # active past the last step (at t = tEnd, rounding may switch a Trig series off)
    ops.timeSeries("Trig", 1, 0.0, p["dt"] * (p["nsteps"] + 1), p["period"], "-factor", p["load"])
    ops.pattern("Plain", 1, 1)
    ops.load(1, 1.0, -0.3, 300.0)
    ops.system("FullGeneral")
    ops.numberer("Plain")
    ops.constraints("Plain")
    ops.test("NormDispIncr", 1e-12, 50)
    ops.algorithm("Newton")
    ops.integrator("Newmark", 0.5, 0.25)
    ops.analysis("Transient")
    u: list[list[float]] = []
    for _ in range(p["nsteps"]):
        if ops.analyze(1, p["dt"]) != 0:
            raise RuntimeError("transient analysis failed")
        u.append([ops.nodeDisp(1, d) for d in (1, 2, 3)])
    ops.wipe()
    return {"u": u}


if __name__ == "__main__":
    scenario, params = sys.argv[1], json.loads(sys.argv[2])
    result = {"sdof_newton": sdof_newton, "column3": column3}[scenario](params)
    print("RESULT " + json.dumps(result), flush=True)
