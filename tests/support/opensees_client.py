"""Scenarios run inside a real OpenSeesPy process (started by bridge_harness.run_opensees).

Usage: python opensees_client.py SCENARIO JSON_PARAMS — prints one ``RESULT {json}`` line.
Each scenario builds the model either with ``genericClient`` elements pointed at the bridge
(``ports`` given) or with the equivalent pure-OpenSees reference elements (``ports`` null).
"""

from __future__ import annotations

import json
import math
import os
import sys
from typing import Any

import openseespy.opensees as ops


def _gc_args(port: int, p: dict[str, Any]) -> list[Any]:
    args: list[Any] = ["-server", port, "127.0.0.1"]
    if p.get("udp"):
        args.append("-udp")
    if p.get("data_size") is not None:
        args += ["-dataSize", p["data_size"]]
    if p.get("no_rayleigh"):
        args.append("-noRayleigh")
    return args


def static_1dof(p: dict[str, Any]) -> dict[str, Any]:
    """Grounded 1-DOF spring under a static load ramp (spec fixture gc_1dof_static_tcp)."""
    ops.wipe()
    ops.model("basic", "-ndm", 1, "-ndf", 1)
    ops.node(1, 0.0)
    if p.get("port") is not None:
        ops.element("genericClient", 1, "-node", 1, "-dof", 1, *_gc_args(p["port"], p))
    else:
        ops.node(0, 0.0)
        ops.fix(0, 1)
        ops.uniaxialMaterial(*p["material"])
        ops.element("zeroLength", 1, 0, 1, "-mat", p["material"][1], "-dir", 1)
    ops.timeSeries("Linear", 1)
    ops.pattern("Plain", 1, 1)
    ops.load(1, float(p["load"]))
    ops.system("BandGeneral")
    ops.numberer("Plain")
    ops.constraints("Plain")
    ops.test("NormDispIncr", 1e-12, 50)
    ops.algorithm(*p.get("algorithm", ["Newton"]))
    ops.integrator("LoadControl", 1.0 / p["nsteps"])
    ops.analysis("Static")
    u, f = [], []
    for i in range(p["nsteps"]):
        if i == p.get("killed_after"):  # the integrator dies: no wipe, so no DIE is sent
            print("RESULT " + json.dumps({"u": u, "force": f}), flush=True)
            os._exit(0)
        if ops.analyze(1) != 0:
            raise RuntimeError("static analysis failed")
        u.append(ops.nodeDisp(1, 1))
        f.append(ops.eleResponse(1, "force")[-1])  # force on node 1 (zeroLength: [f0, f1])
    ops.wipe()
    return {"u": u, "force": f}


def _build_frame(p: dict[str, Any]) -> None:
    ops.wipe()
    ops.model("basic", "-ndm", 1, "-ndf", 1)
    for tag in (1, 2, 3):
        ops.node(tag, 0.0)
    ops.fix(1, 1)
    ops.mass(2, p["masses"][0])
    ops.mass(3, p["masses"][1])
    ports = p.get("ports")
    if ports is not None:
        tags = (2, 1) if p.get("story2_first") else (1, 2)  # OpenSees visits elements by tag
        for ele, (ni, nj), port in ((tags[0], (1, 2), ports[0]), (tags[1], (2, 3), ports[1])):
            ops.element("genericClient", ele, "-node", ni, nj, "-dof", 1, "-dof", 1,
                        *_gc_args(port, p))
    else:
        ops.uniaxialMaterial(*p["story1"])
        ops.uniaxialMaterial(*p["story2"])
        ray = [] if p.get("no_rayleigh") or not p.get("rayleigh") else ["-doRayleigh", 1]
        ops.element("zeroLength", 1, 1, 2, "-mat", p["story1"][1], "-dir", 1, *ray)
        ops.element("zeroLength", 2, 2, 3, "-mat", p["story2"][1], "-dir", 1, *ray)
    ops.timeSeries("Path", 1, "-dt", p["dt"], "-values", *p["accel"], "-factor", p["factor"])
    ops.pattern("UniformExcitation", 1, 1, "-accel", 1)
    if p.get("rayleigh"):
        ops.rayleigh(*p["rayleigh"])
    ops.system("FullGeneral")
    ops.numberer("Plain")
    ops.constraints("Plain")
    ops.test("NormDispIncr", 1e-12, 50)
    ops.algorithm(*p.get("algorithm", ["Newton"]))
    ops.integrator(*p.get("integrator", ["Newmark", 0.5, 0.25]))
    ops.analysis("Transient")


def frame2(p: dict[str, Any]) -> dict[str, Any]:
    """Two-story shear frame under base excitation; optionally wiped and rebuilt and run again."""
    runs = []
    for _ in range(2 if p.get("rebuild") else 1):
        _build_frame(p)
        eig = ops.eigen("-fullGenLapack", 2) if p.get("eigen_first") else None
        u2, u3 = [], []
        for _ in range(p["nsteps"]):
            if ops.analyze(1, p["dt"]) != 0:
                raise RuntimeError("transient analysis failed")
            u2.append(ops.nodeDisp(2, 1))
            u3.append(ops.nodeDisp(3, 1))
        runs.append({"u2": u2, "u3": u3, "eigen": eig})
        ops.wipe()
    return {"runs": runs}


def column3(p: dict[str, Any]) -> dict[str, Any]:
    """The top of a 2-D column (u, v, theta) as one genericClient element with three basic DOFs
    (three actuators behind the bridge), shaken horizontally and vertically with a growing
    amplitude and rocked by a moment; stops at the first step OpenSees cannot converge (a
    holding site answers NaN)."""
    ops.wipe()
    ops.model("basic", "-ndm", 2, "-ndf", 3)
    ops.node(1, 0.0, 0.0)
    ops.mass(1, *p["masses"])
    ops.element("genericClient", 1, "-node", 1, "-dof", 1, 2, 3, *_gc_args(p["port"], p))
    dt, n = p["dt"], p["nsteps"]
    for direction, (amp, freq, growth) in enumerate(p["excitation"], 1):
        values = [amp * (1 + growth * i * dt) * math.sin(6.283185307 * freq * i * dt)
                  for i in range(n + 1)]
        ops.timeSeries("Path", direction, "-dt", dt, "-values", *values)
        if direction < 3:
            ops.pattern("UniformExcitation", direction, direction, "-accel", direction)
        else:
            ops.pattern("Plain", direction, direction)
            ops.load(1, 0.0, 0.0, 1.0)
    ops.system("FullGeneral")
    ops.numberer("Plain")
    ops.constraints("Plain")
    ops.test("NormDispIncr", 1e-10, 10)
    ops.algorithm("Linear")
    ops.integrator("Newmark", 0.5, 0.25)
    ops.analysis("Transient")
    u: list[list[float]] = []
    failed_at = None
    for i in range(n):
        if ops.analyze(1, dt) != 0:
            failed_at = i + 1
            break
        disp = ops.nodeDisp(1)
        if any(d != d for d in disp):  # NaN forces give NaN displacements: the bridge holds
            failed_at = i + 1
            break
        u.append(disp)
    ops.wipe()
    return {"u": u, "failed_at": failed_at}


if __name__ == "__main__":
    scenario, params = sys.argv[1], json.loads(sys.argv[2])
    result = {"static_1dof": static_1dof, "frame2": frame2, "column3": column3}[scenario](params)
    print("RESULT " + json.dumps(result), flush=True)
