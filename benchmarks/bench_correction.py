"""The outer-loop displacement correction on the simulated rig: does the interface gap close?

1. **The demo's frame** (two stories, the demo's Kanai-Tajimi record, explicit Newmark) with
   the tested damper (the demo's bilinear, k0 8 kN/mm, fy 12 kN) on an in-process ``rig``
   controller, in three variants: an ideal actuator (the reference), a compliant reaction frame
   (``--frame`` kN/mm) and separately a pin gap (``--gap`` mm each side); each without and with
   the correction (``measured = "external"``: the specimen's displacement). Per variant:
   interface NRMS (specimen displacement vs the integrator's target), the peak story-1 drift
   error against the ideal actuator's run (max over the history of |drift − ideal drift|, and
   the error of the peak), and corrections per step (median, p95, max).
   Targets: NRMS with ≤ 10 % of without; peak drift error ≤ 20 % of without; median ≤ 3.
2. **Step time over Modbus.** The compliant frame's first ``--modbus-steps`` targets through the
   Modbus adapter and ``sim-actuator``'s Modbus server on loopback (one process, one loop), with
   and without the correction, alternating blocks, ≥ 3 rounds: time per step with correction
   vs (1 + mean corrections) × the uncorrected step.

    taskset -c 1 python -m benchmarks.bench_correction [--quick] [--loop]

The frame runs go through the experimental site (default): a real bridge in a thread serving a
``rig`` site with ``[sites.correction]``, the frame's integrator its genericClient over loopback;
the targets, the specimen displacements and the corrections are read back from the run
record's correction lines (the uncorrected runs: a tolerance no step exceeds, so each trial's
one measurement is recorded and nothing is corrected). ``--loop``: the loop alone, through
``LimitedPath`` (limits and state table, no site). The Modbus timing drives the loop through
``LimitedPath`` either way. Feeds BENCHMARKS.md, "Displacement correction".
"""

from __future__ import annotations

import argparse
import asyncio
import statistics
import tempfile
import time
from collections.abc import Coroutine
from pathlib import Path
from typing import Any, TypeVar

import numpy as np

from fresco_bridge.config import parse_config
from fresco_bridge.controls.base import Controller
from fresco_bridge.controls.modbus import ModbusController, ModbusControllerConfig
from fresco_bridge.controls.rig import RigController, RigControllerConfig
from fresco_bridge.daemon import BridgeThread
from fresco_bridge.eager import Suspended, start_eager
from fresco_bridge.indicators import nrms_error
from fresco_bridge.integrator.coupling import Placement, StoryCoupling, run_coupled
from fresco_bridge.integrator.demo import DEMO_DAMPER, demo_frame_integrator, demo_ground_motion
from fresco_bridge.integrator.link import GenericClientLink, SiteElement
from fresco_bridge.lab import dump_toml
from fresco_bridge.record import read_record
from fresco_bridge.record.export import correction_lines
from fresco_bridge.safety import CorrectionConfig, Limiter
from fresco_bridge.sites.correction_loop import CorrectionLoop, LimitedPath, StepCorrection
from sim_actuator.config import build_rig, parse_rig_config
from sim_actuator.servers.controller import RigController as ServedRig
from sim_actuator.servers.modbus import ModbusRigServer

T = TypeVar("T")
CORRECTION = CorrectionConfig(tolerance=0.01, max_correction=3.0, max_iterations=10,
                              measured="external", policy="accept-with-event")
"""accept-with-event: a step that does not converge is counted (``not converged``), not a stop.
``--gain`` and ``--max-iterations`` replace the gain and the bound."""


def eager(coro: Coroutine[Any, Any, T]) -> T:
    """An in-process controller never suspends: the loop's coroutine completes at once."""
    done = start_eager(coro)
    if isinstance(done, Suspended):
        raise RuntimeError("an in-process controller suspended")
    return done


DAMPER = {k: float(v) for k, v in DEMO_DAMPER.items() if k != "model"}


def rig_description(effects: dict[str, Any]) -> dict[str, Any]:
    return {"name": "bench", "specimen": {"kind": str(DEMO_DAMPER["model"]), "params": DAMPER},
            "effects": effects, "default_ramp_time": 0.05, "settle_time": 0.01}


_FILES = tempfile.TemporaryDirectory(prefix="bench-correction-")
"""The rig files of this run (removed when the process ends)."""


def rig_file(effects: dict[str, Any]) -> Path:
    """The rig description as a file, as a lab writes it for ``[sites.controller] file``."""
    parse_rig_config(rig_description(effects))  # a bad description fails here, named
    path = Path(_FILES.name) / f"rig-{len(list(Path(_FILES.name).iterdir()))}.toml"
    path.write_text(dump_toml(rig_description(effects)), encoding="utf-8")
    return path


class RigElement:
    """A story element on the rig: set_trial moves it (corrected or not), answers the force."""

    def __init__(self, effects: dict[str, Any], corrected: bool,
                 correction: CorrectionConfig = CORRECTION) -> None:
        self.rig = RigController(RigControllerConfig(file=rig_file(effects),
                                                     external="specimen"))
        self.initial_tangent = DAMPER["k0"]
        self.loop = CorrectionLoop(LimitedPath(self.rig, Limiter([], 1)),
                                   correction.to_settings(1), self.rig, external=True) \
            if corrected else None
        self.targets: list[float] = []
        self.specimen: list[float] = []
        self.corrections: list[int] = []
        self.events = 0

    def set_trial(self, d: float) -> tuple[float, float]:
        if self.loop is None:
            self.rig.set_ctrl_now((d,))
            daq = self.rig.get_daq_now()
            corrections = 0
        else:
            step: StepCorrection = eager(self.loop.run((d,)))
            if step.daq is None or step.verdict.hold:
                raise RuntimeError(f"correction ended in HOLD: {step.verdict.describe()}")
            daq, corrections = step.daq, step.corrections
            self.events += step.verdict.event
        assert daq.external is not None
        self.targets.append(d)
        self.specimen.append(daq.external[0])
        self.corrections.append(corrections)
        return daq.force[0], self.initial_tangent

    def commit(self) -> None:
        """A physical rig has no trial state."""


def frame_run(effects: dict[str, Any], corrected: bool, steps: int | None,
              correction: CorrectionConfig = CORRECTION) -> dict[str, Any]:
    element = RigElement(effects, corrected, correction)
    coupling = StoryCoupling({"damper": Placement(0, element)})
    integrator = demo_frame_integrator(coupling, demo_ground_motion())
    response = run_coupled(integrator, coupling, steps=steps)
    drift = np.asarray(response.drift)[:, 0]
    return {"drift": drift, "targets": np.array(element.targets),
            "specimen": np.array(element.specimen), "corrections": element.corrections,
            "events": element.events}


UNCORRECTED_TOLERANCE = 1e9
"""mm: no step exceeds it, so the site measures each trial once and corrects nothing."""


def site_config(effects: dict[str, Any], correction: CorrectionConfig) -> str:
    c = correction
    return f"""
[bridge]
run_name = "bench-correction"
[record]
fsync = "off"
[[sites]]
name = "damper"
port = 0
[sites.controller]
kind = "rig"
file = "{rig_file(effects)}"
external = "specimen"
[sites.correction]
tolerance = {c.tolerance!r}
max_correction = {c.max_correction!r}
max_iterations = {c.max_iterations}
gain = {c.gain!r}
measured = "{c.measured}"
policy = "{c.policy}"
"""


def site_frame_run(effects: dict[str, Any], corrected: bool, steps: int | None,
                   correction: CorrectionConfig = CORRECTION) -> dict[str, Any]:
    """``frame_run`` through the experimental site of a real bridge (its gate, its record)."""
    if not corrected:
        correction = correction.model_copy(update={"tolerance": UNCORRECTED_TOLERANCE})
    with tempfile.TemporaryDirectory(prefix="bench-correction-runs-") as runs:
        config = site_config(effects, correction)
        with BridgeThread(parse_config(config, "<bench>"), config, run_dir=Path(runs)) as b, \
                GenericClientLink("127.0.0.1", b.ports["damper"], 1, timeout=60.0) as link:
            coupling = StoryCoupling({"damper": Placement(0, SiteElement(link, DAMPER["k0"]))})
            integrator = demo_frame_integrator(coupling, demo_ground_motion())
            response = run_coupled(integrator, coupling, steps=steps)
            run_dir = b.run_dir
        lines = correction_lines(read_record(run_dir))
    drift = np.asarray(response.drift)[:, 0]
    return {"drift": drift, "targets": np.array([c.target[0] for c in lines]),
            "specimen": np.array([c.measured[-1][0] for c in lines]),
            "corrections": [c.corrections for c in lines],
            "events": sum(c.outcome != "converged" for c in lines)}


def summarise(run: dict[str, Any], ideal: np.ndarray) -> dict[str, float]:
    drift = run["drift"]
    c = run["corrections"]
    return {
        "nrms %": 100 * nrms_error(run["targets"], run["specimen"]),
        "max |drift - ideal| mm": float(np.max(np.abs(drift - ideal))),
        "peak error mm": abs(float(np.max(np.abs(drift))) - float(np.max(np.abs(ideal)))),
        "median corr": float(np.median(c)), "p95 corr": float(np.percentile(c, 95)),
        "max corr": float(max(c)), "not converged": float(run["events"]),
    }


async def modbus_step_times(effects: dict[str, Any], targets: list[float], rounds: int
                            ) -> tuple[list[float], list[float], float]:
    cfg = parse_rig_config(rig_description(effects))
    served = ServedRig(build_rig(cfg))
    server = ModbusRigServer(served, host="127.0.0.1", port=0)
    _, port = await server.start()
    served.start_heartbeat(20.0)
    ctl = ModbusController(ModbusControllerConfig(kind="modbus", port=port, ramp_time=0.05,
                                                  request_timeout=2.0, external_register=24))
    await ctl.connect()
    plain: list[float] = []
    corrected: list[float] = []
    counts: list[int] = []
    try:
        loop = CorrectionLoop(LimitedPath(ctl, Limiter([], 1)), CORRECTION.to_settings(1), ctl,
                              external=True)
        for _ in range(rounds):
            for variant in ("plain", "corrected"):
                t0 = time.perf_counter()
                for t in targets:
                    if variant == "plain":
                        await plain_step(ctl, t)
                    else:
                        counts.append((await loop.run((t,))).corrections)
                per_step = (time.perf_counter() - t0) / len(targets)
                (plain if variant == "plain" else corrected).append(per_step)
    finally:
        await ctl.close()
        await server.stop()
        await served.close()
    return plain, corrected, statistics.fmean(counts)


async def plain_step(ctl: Controller, target: float) -> None:
    await ctl.set_ctrl((target,))
    await ctl.get_daq()


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--quick", action="store_true", help="500 frame steps, 2 rounds")
    parser.add_argument("--frame", type=float, default=40.0, help="frame stiffness, kN/mm")
    parser.add_argument("--gap", type=float, default=0.2, help="pin gap each side, mm")
    parser.add_argument("--modbus-steps", type=int, default=60)
    parser.add_argument("--rounds", type=int, default=3)
    parser.add_argument("--gain", type=float, default=CORRECTION.gain)
    parser.add_argument("--max-iterations", type=int, default=CORRECTION.max_iterations)
    parser.add_argument("--loop", action="store_true",
                        help="the frame runs through the loop alone (LimitedPath), not the site")
    args = parser.parse_args(argv)
    run = frame_run if args.loop else site_frame_run
    print("frame runs through " + ("the loop alone (LimitedPath)" if args.loop else
                                   "the experimental site of a bridge (genericClient, record)"))
    correction = CORRECTION.model_copy(update={"gain": args.gain,
                                               "max_iterations": args.max_iterations})
    print(f"correction: gain {correction.gain:g}, max_iterations {correction.max_iterations}, "
          f"tolerance {correction.tolerance} mm, max_correction {correction.max_correction} mm")
    steps = 500 if args.quick else None
    rounds = 2 if args.quick else max(3, args.rounds)
    ideal = run({}, False, steps)
    print(f"ideal actuator: peak story-1 drift {np.max(np.abs(ideal['drift'])):.3f} mm, "
          f"{len(ideal['drift'])} steps")
    variants = {f"compliant frame {args.frame:g} kN/mm": {"frame": {"stiffness": args.frame}},
                f"pin gap {args.gap:g} mm": {"backlash": {"gap": args.gap}}}
    for name, effects in variants.items():
        off = summarise(run(effects, False, steps), ideal["drift"])
        on = summarise(run(effects, True, steps, correction), ideal["drift"])
        print(f"\n{name}")
        for key in off:
            print(f"  {key:24s} without {off[key]:10.4g}   with {on[key]:10.4g}")
        print(f"  ratio NRMS {on['nrms %'] / off['nrms %']:.3%}, max drift error "
              f"{on['max |drift - ideal| mm'] / off['max |drift - ideal| mm']:.3%}, "
              f"peak error {on['peak error mm'] / max(off['peak error mm'], 1e-12):.3%}")
    frame = variants[next(iter(variants))]
    compliant = frame_run(frame, False, args.modbus_steps)
    targets = [float(t) for t in compliant["targets"][1:]]
    plain, corrected, mean_corr = asyncio.run(modbus_step_times(frame, targets, rounds))
    ratio = min(corrected) / min(plain)
    print(f"\nModbus loopback, {len(targets)} steps x {rounds} rounds: plain step min "
          f"{min(plain) * 1e3:.2f} ms (median {statistics.median(plain) * 1e3:.2f}), corrected "
          f"min {min(corrected) * 1e3:.2f} ms (median {statistics.median(corrected) * 1e3:.2f}); "
          f"ratio {ratio:.2f} vs 1 + mean corrections = {1 + mean_corr:.2f}")


if __name__ == "__main__":
    main()
