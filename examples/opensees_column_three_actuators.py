"""A column tested with three actuators, driven from an unmodified OpenSeesPy model: the column's
top (u, v, θ) is one genericClient element the bridge serves through OpenFresco's
``ThreeActuators2d`` setup with exact geometry (``-nlGeom``), on three simulated servo-hydraulic
actuators loading one yielding specimen (examples/column_three_actuators.toml).

    .venv/bin/fresco-bridge serve --config examples/column_three_actuators.toml   # terminal 1
    .venv/bin/python examples/opensees_column_three_actuators.py                  # terminal 2

First a constant axial load (--axial, kN) in ten static steps, then the record
examples/data/RSN960_NORTHR_LOS270.AT2 (Northridge 1994) scaled to --pga along u. The bridge
turns each trial (u, v, θ) into the three actuators' exact strokes and their measured strokes
and forces back into the column's (u, v, θ) forces; a limit on any actuator holds all three.
Units: mm, kN, kN·mm, rad, s. Site column, port 8096.
"""

from __future__ import annotations

import sys
from collections.abc import Sequence
from typing import Any

from opensees_two_story import Stop, example_parser, prepare  # beside this file (on sys.path)

CONFIG = "examples/column_three_actuators.toml"
MASS = (0.02, 0.02, 5000.0)  # u, v: kN·s²/mm (20 t); θ: kN·mm·s² (the top's inertia)
ALPHA_M = 2.0  # 1/s: mass-proportional damping, about 3 % at the column's first mode


def run_column(ops: Any, accel_mm_s2: Sequence[float], dt: float, steps: int, axial: float,
               host: str, port: int) -> dict[str, float]:
    """Axial load, then ``steps`` steps of the record; the column top's peaks."""
    ops.wipe()
    ops.model("basic", "-ndm", 2, "-ndf", 3)
    ops.node(1, 0.0, 0.0)
    ops.mass(1, *MASS)
    ops.element("genericClient", 1, "-node", 1, "-dof", 1, 2, 3, "-server", port, host)
    ops.system("FullGeneral")
    ops.numberer("Plain")
    ops.constraints("Plain")
    ops.test("NormDispIncr", 1e-6, 50)
    ops.algorithm("Newton")
    # the axial load, static, in ten steps (every iteration moves the actuators)
    ops.timeSeries("Linear", 1)
    ops.pattern("Plain", 1, 1)
    ops.load(1, 0.0, -axial, 0.0)
    ops.integrator("LoadControl", 0.1)
    ops.analysis("Static")
    if ops.analyze(10) != 0:
        ops.wipe()
        raise Stop("the axial load could not be applied", 1)
    ops.loadConst("-time", 0.0)
    shortening = -ops.nodeDisp(1, 2)
    # the record along u (the same solver, now in time)
    ops.timeSeries("Path", 2, "-dt", dt, "-values", *accel_mm_s2)
    ops.pattern("UniformExcitation", 2, 1, "-accel", 2)
    ops.rayleigh(ALPHA_M, 0.0, 0.0, 0.0)
    ops.integrator("Newmark", 0.5, 0.25)
    ops.analysis("Transient")
    drift = shear = rotation = 0.0
    for step in range(steps):
        if ops.analyze(1, dt) != 0:
            ops.wipe()
            raise Stop(f"the analysis failed at step {step + 1} (a limit trip answers NaN: "
                       "see the bridge's log)", 1)
        u, _, theta = ops.nodeDisp(1)
        drift = max(drift, abs(u))
        rotation = max(rotation, abs(theta))
        shear = max(shear, abs(ops.eleResponse(1, "forces")[0]))
    ops.wipe()  # sends DIE: the bridge closes the session and waits for the next one
    return {"drift": drift, "shear": shear, "rotation": rotation, "shortening": shortening}


def main(argv: Sequence[str] | None = None) -> int:
    """Parse ``argv``, run the column against the bridge; the exit status."""
    parser = example_parser(__doc__)
    parser.add_argument("--axial", type=float, default=150.0,
                        help="axial load, kN (default %(default)s)")
    parser.add_argument("--port", type=int, default=8096,
                        help=f"the site's port (default: %(default)s, as in {CONFIG})")
    args = parser.parse_args(argv)
    try:
        motion, steps, ops = prepare(args, [args.port], CONFIG)
        peaks = run_column(ops, motion.accel_mm_s2.tolist(), motion.dt, steps, args.axial,
                           args.host, args.port)
    except Stop as exc:
        print(f"{parser.prog}: {exc}", file=sys.stderr)
        return exc.status
    print(f"axial load {args.axial:g} kN: shortening {peaks['shortening']:.3f} mm")
    print(f"{args.record.name} scaled to PGA {args.pga:g} m/s², {steps} steps of {motion.dt:g} s: "
          f"peak drift {peaks['drift']:.2f} mm, peak shear {peaks['shear']:.1f} kN, "
          f"peak rotation {peaks['rotation']:.2e} rad")
    print("next: .venv/bin/fresco-bridge runs list   # the run the bridge recorded "
          "(three actuators' ctrl and daq per step)")
    return 0


if __name__ == "__main__":
    sys.exit(main())
