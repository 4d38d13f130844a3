"""Newton iterations per step with each tangent answer, on a yielding specimen.

Why: under an implicit scheme every Newton iteration is a physical move of the actuators; a
constant initial stiffness past yield costs iterations that a measured tangent saves (target:
``broyden`` ≤ 0.7× ``initial``). A real OpenSeesPy process runs Newmark + Newton on a mass
carried by a ``genericClient`` element served by the bridge (in-process ``sim`` controller, a
Steel01-equivalent bilinear specimen driven far past yield: the printed peak is 15 to 100
times the yield displacement); each variant is the same analysis with the site's ``tangent``
changed. The mass ratio ``r = 4m / (dt² k0)`` says how
much the inertia term dominates the effective stiffness Newton iterates on (large r: the
tangent hardly matters); both a stiffness-dominated and an inertia-dominated case run.

    python -m benchmarks.bench_tangent [--steps 400] [--quick]

Reported per variant: mean and max iterations per step, total moves, the ratio to
``initial``, and the largest difference of the displacement history from the exact-tangent run
(every variant must converge to the same answer). Feeds BENCHMARKS.md, "Measured tangent".
"""

from __future__ import annotations

import argparse
import json
import subprocess
import sys
import tempfile
import textwrap
from pathlib import Path
from typing import Any

from fresco_bridge.opensees_runtime import opensees_env
from tests.support.bridge import RunningBridge

METHODS = ("controller", "initial", "broyden", "bfgs", "transpose")
K0, FY, ALPHA = 10.0, 5.0, 0.05  # kN/mm, kN, -
TARGET = 0.7


def run_peer(scenario: str, params: dict[str, Any], timeout: float = 600.0) -> dict[str, Any]:
    proc = subprocess.run([sys.executable, "-m", "benchmarks._tangent_peer", scenario,
                           json.dumps(params)], env=opensees_env(), capture_output=True,
                          text=True, timeout=timeout, check=False)
    out = [ln for ln in proc.stdout.splitlines() if ln.startswith("RESULT ")]
    if proc.returncode != 0 or not out:
        raise RuntimeError(f"{scenario} failed: {proc.stderr[-1500:]}")
    result: dict[str, Any] = json.loads(out[-1][len("RESULT "):])
    return result


def one(method: str, mass: float, steps: int, dt: float, run_root: Path) -> dict[str, Any]:
    config = textwrap.dedent(f"""
        [record]
        enabled = false
        [[sites]]
        name = "specimen"
        port = 0
        tangent = "{method}"
        [sites.controller]
        kind = "sim"
        model = "bilinear"
        params = {{ k0 = {K0}, fy = {FY}, alpha = {ALPHA} }}
        """)
    with RunningBridge(config, run_root) as bridge:
        try:
            return run_peer("sdof_newton", {
            "port": bridge.ports["specimen"], "mass": mass, "dt": dt, "nsteps": steps,
            "period": 1.0, "load": 1.6 * FY, "tol": 1e-8})
        except RuntimeError as exc:
            return {"failed": str(exc).splitlines()[1:3]}


def main(argv: list[str] | None = None) -> None:
    ap = argparse.ArgumentParser(prog="benchmarks.bench_tangent")
    ap.add_argument("--steps", type=int, default=400)
    ap.add_argument("--quick", action="store_true", help="100 steps")
    args = ap.parse_args(argv)
    if args.quick:
        args.steps = min(args.steps, 100)
    dt = 0.01
    print(f"bilinear k0 {K0} kN/mm, fy {FY} kN, alpha {ALPHA}; sine load 1.6 fy, period 1 s; "
          f"Newmark (0.5, 0.25), Newton, NormDispIncr 1e-8; dt {dt} s, {args.steps} steps")
    with tempfile.TemporaryDirectory() as tmp:
        for ratio in (0.5, 50.0):
            mass = ratio * dt * dt * K0 / 4
            runs = {m: one(m, mass, args.steps, dt, Path(tmp)) for m in METHODS}
            exact = runs["controller"]["u"]
            base = sum(runs["initial"]["iters"])
            peak = max(abs(x) for x in exact)
            print(f"\nmass ratio 4m/(dt² k0) = {ratio:g} (m = {mass:.3g} kN·s²/mm); peak "
                  f"displacement {peak:.2f} mm = {peak * K0 / FY:.1f} × yield")
            print(f"{'tangent':<11} {'iter/step':>9} {'max':>4} {'moves':>6} {'/initial':>9} "
                  f"{'max |Δu| vs exact (mm)':>24}")
            for m in METHODS:
                it, u = runs[m]["iters"], runs[m]["u"]
                diff = max(abs(a - b) for a, b in zip(u, exact, strict=True))
                print(f"{m:<11} {sum(it) / len(it):>9.2f} {max(it):>4} {sum(it):>6} "
                      f"{sum(it) / base:>9.2f} {diff:>24.2e}")
            verdict = sum(runs["broyden"]["iters"]) / base
            print(f"broyden / initial = {verdict:.2f} (target ≤ {TARGET}): "
                  f"{'met' if verdict <= TARGET else 'NOT met'}")


if __name__ == "__main__":
    main()
