"""Drive fresco-bridge from an unmodified OpenSeesPy model: a two-story shear frame (10 kN/mm
per story, about 5 % damping) with one genericClient element per story served by the bridge,
under a real ground motion.

    .venv/bin/fresco-bridge serve --config examples/lab.toml      # terminal 1
    .venv/bin/python examples/opensees_two_story.py               # terminal 2

The record is examples/data/RSN960_NORTHR_LOS270.AT2 (Northridge 1994, 20 s at 0.01 s) scaled
to a PGA of 3 m/s^2 (the source paper's 300 cm/s^2); --record, --pga and --steps change that.
OpenSeesPy comes with `make demo` (the `opensees` extra). fresco_bridge.opensees_runtime checks
that the bridge is listening before any element connects (a genericClient refused by its
server crashes OpenSees) and loads OpenSeesPy's bundled BLAS (no LD_LIBRARY_PATH).
Units: mm, kN, s. Story 1: site damper (port 8090), story 2: site story2 (port 8091).
"""

from __future__ import annotations

import argparse
import sys
from collections.abc import Sequence
from pathlib import Path
from typing import Any

from fresco_bridge.integrator import GroundMotion, GroundMotionFormatError, read_peer_at2
from fresco_bridge.opensees_runtime import (
    BridgeNotListening,
    OpenSeesUnavailable,
    import_opensees,
    require_listening,
)

M = 0.0202228  # 20222.8 kg per story, in kN·s²/mm
FRAME_K = 10.0  # kN/mm per story
ALPHA_M = 2.0  # 1/s: mass-proportional damping, about 5 % at the first mode (T1 ≈ 0.3 s)
RECORD = Path(__file__).resolve().parent / "data" / "RSN960_NORTHR_LOS270.AT2"


class Stop(Exception):
    """The example cannot run: the message for stderr and the exit status."""

    def __init__(self, message: str, status: int) -> None:
        super().__init__(message)
        self.status = status


def run_frame(ops: Any, accel_mm_s2: Sequence[float], dt: float, steps: int, host: str,
              ports: Sequence[int]) -> float:
    """Build the frame, integrate ``steps`` steps; the peak story-1 drift (mm), or :class:`Stop`."""
    ops.wipe()
    ops.model("basic", "-ndm", 1, "-ndf", 1)
    for tag in (1, 2, 3):
        ops.node(tag, 0.0)
    ops.fix(1, 1)
    ops.mass(2, M)
    ops.mass(3, M)
    # each story's frame: 10 kN/mm (the demo's), beside the story's served element
    ops.uniaxialMaterial("Elastic", 1, FRAME_K)
    for story in (1, 2):
        ops.element("zeroLength", 10 + story, story, story + 1, "-mat", 1, "-dir", 1)
    ops.rayleigh(ALPHA_M, 0.0, 0.0, 0.0)
    # the served elements: plain genericClients, one port (one bridge site) each
    ops.element("genericClient", 1, "-node", 1, 2, "-dof", 1, "-dof", 1,
                "-server", ports[0], host)
    ops.element("genericClient", 2, "-node", 2, 3, "-dof", 1, "-dof", 1,
                "-server", ports[1], host)
    ops.timeSeries("Path", 1, "-dt", dt, "-values", *accel_mm_s2)
    ops.pattern("UniformExcitation", 1, 1, "-accel", 1)
    ops.system("FullGeneral")
    ops.numberer("Plain")
    ops.constraints("Plain")
    ops.test("NormDispIncr", 1e-10, 25)
    ops.algorithm("Newton")
    ops.integrator("Newmark", 0.5, 0.25)
    ops.analysis("Transient")
    peak = 0.0
    for step in range(steps):
        if ops.analyze(1, dt) != 0:
            ops.wipe()
            raise Stop(f"the analysis failed at step {step + 1}", 1)
        peak = max(peak, abs(ops.nodeDisp(2, 1)))
    ops.wipe()  # sends DIE: the bridge closes the sessions and waits for the next ones
    return peak


def example_parser(doc: str) -> argparse.ArgumentParser:
    """The options every OpenSeesPy example shares: the record, its PGA and length, the host."""
    parser = argparse.ArgumentParser(prog=Path(sys.argv[0]).name, description=doc.split("\n\n")[0],
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--record", type=Path, default=RECORD,
                        help="a PEER .AT2 record (default: %(default)s)")
    parser.add_argument("--pga", type=float, default=3.0, help="m/s^2 (default %(default)s)")
    parser.add_argument("--steps", type=int, default=None, help="default: the whole record")
    parser.add_argument("--host", default="127.0.0.1", help="the bridge's address")
    return parser


def prepare(args: argparse.Namespace, ports: Sequence[int],
            config: str) -> tuple[GroundMotion, int, Any]:
    """(the scaled record, its steps, OpenSeesPy) once the bridge of ``config`` listens on
    ``ports``; :class:`Stop` (2: a bad record, 1: no bridge or no OpenSeesPy) otherwise."""
    try:
        motion = read_peer_at2(args.record).scaled_to_pga(args.pga)
    except (OSError, GroundMotionFormatError) as exc:
        raise Stop(f"cannot read the record: {exc}", 2) from None
    steps = motion.npts if args.steps is None else min(args.steps, motion.npts)
    try:  # the bridge first: before OpenSees is loaded, whose exit prints its own line
        require_listening(ports, args.host,
                          hint=f"start it first: .venv/bin/fresco-bridge serve --config {config}")
        return motion, steps, import_opensees()
    except (OpenSeesUnavailable, BridgeNotListening) as exc:
        raise Stop(str(exc), 1) from None


def main(argv: Sequence[str] | None = None, *, doc: str = __doc__,
         ports: tuple[int, int] = (8090, 8091), config: str = "examples/lab.toml",
         next_step: str = ".venv/bin/fresco-bridge runs list   # the run the bridge recorded"
         ) -> int:
    """Parse ``argv``, run the frame against the bridge of ``config``; the exit status."""
    parser = example_parser(doc)
    parser.add_argument("--ports", type=int, nargs=2, default=ports, metavar=("STORY1", "STORY2"),
                        help="the two sites' ports (default: %(default)s, as in " + config + ")")
    args = parser.parse_args(argv)
    try:
        motion, steps, ops = prepare(args, args.ports, config)
        peak = run_frame(ops, motion.accel_mm_s2.tolist(), motion.dt, steps, args.host,
                         args.ports)
    except Stop as exc:
        print(f"{parser.prog}: {exc}", file=sys.stderr)
        return exc.status
    print(f"{args.record.name} scaled to PGA {args.pga:g} m/s², {steps} steps of {motion.dt:g} s: "
          f"peak story-1 drift {peak:.2f} mm")
    print(f"next: {next_step}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
