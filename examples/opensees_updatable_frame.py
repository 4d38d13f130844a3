"""An OpenSeesPy frame whose story-2 damper is the online-updated twin of the tested story-1
damper (genericClient elements; the bridge serves both, the twin from an updatable site).

1. In one terminal:  fresco-bridge serve --config examples/updatable_twin.toml
2. In another:       python examples/opensees_updatable_frame.py
   (Linux: OpenSeesPy's wheel needs its bundled BLAS on the loader path, e.g.
    LD_LIBRARY_PATH=$(python -c "import importlib.util,os;print(os.path.join(list(
    importlib.util.find_spec('openseespylinux').submodule_search_locations)[0],'lib'))"))
Units: mm, kN, s. Story 1: the tested damper (site damper); story 2: its twin (site twin1).
`fresco-bridge ctl status` shows the twin's learner (live, steps trained).
"""

import math

import openseespy.opensees as ops

M = 0.0202228  # 20222.8 kg per story, in kN·s²/mm
DT = 0.01
N = 1000

ops.wipe()
ops.model("basic", "-ndm", 1, "-ndf", 1)
for tag in (1, 2, 3):
    ops.node(tag, 0.0)
ops.fix(1, 1)
ops.mass(2, M)
ops.mass(3, M)
ops.element("genericClient", 1, "-node", 1, 2, "-dof", 1, "-dof", 1, "-server", 8092, "127.0.0.1")
ops.element("genericClient", 2, "-node", 2, 3, "-dof", 1, "-dof", 1, "-server", 8093, "127.0.0.1")
accel = [math.sin(2 * math.pi * 2.0 * DT * i) * math.exp(-0.2 * DT * i) for i in range(N)]
ops.timeSeries("Path", 1, "-dt", DT, "-values", *accel, "-factor", 3000.0)  # mm/s²
ops.pattern("UniformExcitation", 1, 1, "-accel", 1)
ops.system("FullGeneral")
ops.numberer("Plain")
ops.constraints("Plain")
ops.test("NormDispIncr", 1e-10, 25)
ops.algorithm("Newton")
ops.integrator("Newmark", 0.5, 0.25)
ops.analysis("Transient")
peak = 0.0
for step in range(N):
    if ops.analyze(1, DT) != 0:
        raise SystemExit(f"analysis failed at step {step}")
    peak = max(peak, abs(ops.nodeDisp(2, 1)))
print(f"peak story-1 drift {peak:.3f} mm over {N} steps")
ops.wipe()  # sends DIE: the bridge closes the session and waits for the next one
