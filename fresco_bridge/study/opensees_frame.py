"""The study's frame in OpenSeesPy, run as its own process by ``study.opensees``.

Usage: ``python -m fresco_bridge.study.opensees_frame`` with the frame as JSON on stdin; prints
one ``RESULT {json}`` line (the floor displacements after every step and the wall time of the
step loop).

The model is ``study.simulate``'s, element for element: a shear building (nodes 1-3, node 1
the ground), each story's frame stiffness a ``zeroLength`` with an ``Elastic`` material whose
``eta`` is that story's stiffness-proportional Rayleigh term (``beta_k`` times the frame's plus
the dampers' initial stiffness, as the study's damping matrix), the mass-proportional term by
``rayleigh``, both dampers ``genericClient`` elements served by the bridge, explicit Newmark
(gamma = 1/2) with the ``Linear`` algorithm: one trial per step, as the built-in integrator.
It imports OpenSeesPy through ``fresco_bridge.opensees_runtime`` (which loads the Linux wheel's
bundled BLAS first: no ``LD_LIBRARY_PATH`` needed).
"""

from __future__ import annotations

import json
import sys
import time
from typing import Any


def run_frame(p: dict[str, Any]) -> dict[str, Any]:
    """Build the frame of ``p`` and integrate it to the end; floor displacements per step."""
    from fresco_bridge.opensees_runtime import import_opensees

    ops = import_opensees()

    ops.wipe()
    ops.model("basic", "-ndm", 1, "-ndf", 1)
    for tag in (1, 2, 3):
        ops.node(tag, 0.0)
    ops.fix(1, 1)
    ops.mass(2, p["masses"][0])
    ops.mass(3, p["masses"][1])
    for story, (k, eta) in enumerate(zip(p["frame_stiffness"], p["frame_eta"], strict=True)):
        ops.uniaxialMaterial("Elastic", 10 + story, k, eta)
        ops.element("zeroLength", 10 + story, 1 + story, 2 + story, "-mat", 10 + story,
                    "-dir", 1)
    for tag, (story, port) in enumerate(p["dampers"], start=1):
        ops.element("genericClient", tag, "-node", 1 + story, 2 + story, "-dof", 1, "-dof", 1,
                    "-server", port, "127.0.0.1")
    ops.timeSeries("Path", 1, "-dt", p["dt"], "-values", *p["accel"], "-factor", 1.0)
    ops.pattern("UniformExcitation", 1, 1, "-accel", 1)
    ops.rayleigh(p["alpha_m"], 0.0, 0.0, 0.0)
    ops.system("FullGeneral")
    ops.numberer("Plain")
    ops.constraints("Plain")
    ops.algorithm("Linear")
    ops.integrator("NewmarkExplicit", 0.5)
    ops.analysis("Transient")
    floors: list[list[float]] = []
    start = time.perf_counter()
    for step in range(p["steps"]):
        if ops.analyze(1, p["dt"]) != 0:
            raise RuntimeError(f"OpenSees: transient analysis failed at step {step + 1}")
        floors.append([ops.nodeDisp(2, 1), ops.nodeDisp(3, 1)])
    seconds = time.perf_counter() - start
    ops.wipe()  # sends DIE: the bridge closes both sessions
    return {"floors": floors, "loop_seconds": seconds}


if __name__ == "__main__":
    result = run_frame(json.loads(sys.stdin.read()))
    print("RESULT " + json.dumps(result), flush=True)
