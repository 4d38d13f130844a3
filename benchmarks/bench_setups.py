"""Step cost of a three-actuator site against a one-actuator site, and a three-actuator column
through the bridge against the same column with the transformation done by hand in OpenSees.

Why: a multi-actuator setup must not make the bridge the bottleneck (target: a
``ThreeActuators2d`` site under nonlinear geometry costs ≤ 1.3× a one-actuator site per step,
same run, pinned), and its geometry must be the physical one (target: the OpenSees analysis
through the bridge equals the hand-transformed model to 1e-9 relative).

Step cost: the server's whole per-step Python work (``bench_step_path``: protocol → site →
setup → safety → controller → record → reply, fed in process), the one-actuator site
(``OneActuator``, a bilinear specimen) and the three-actuator site (``ThreeActuators2d``,
``nlGeom``, three bilinear actuators) alternating, the order reversed every round; run it under
``taskset -c 1``. Reported: µs of CPU per step, min and median over rounds, and the ratio of
medians.

Column: ``benchmarks/_tangent_peer.py column3`` — a platform with mass and inertia under a
horizontal sine load and gravity, Newmark + Newton; (a) a 3-DOF ``genericClient`` served by a
``ThreeActuators2d`` ``nlGeom`` site on the ``sim`` controller with elastic actuators, (b)
the same three actuators as ``corotTruss`` elements from the ground to the platform's joints
in OpenSees. Reported: the largest difference of the displacement histories relative to
their largest value.

    python -m benchmarks.bench_setups [--steps 3000] [--rounds 5] [--column-steps 400] [--quick]

Feeds BENCHMARKS.md, "Multi-actuator setups".
"""

from __future__ import annotations

import argparse
import asyncio
import math
import statistics
import tempfile
import textwrap
from pathlib import Path
from typing import Any

import numpy as np

from .bench_step_path import run as step_path
from .bench_tangent import run_peer

ONE = """
[[sites]]
name = "spec"
port = 0
dofs = 1
setup = "OneActuator"
[sites.controller]
kind = "sim"
model = "bilinear"
params = { k0 = 100.0, fy = 20.0, alpha = 0.02 }
"""
GEOMETRY = "La1 = 1000.0\nLa2 = 900.0\nLa3 = 800.0\nL1 = 500.0\nL2 = 400.0\n"
THREE = f"""
[[sites]]
name = "spec"
port = 0
dofs = 3
[sites.setup]
kind = "ThreeActuators2d"
{GEOMETRY}nlGeom = true
[sites.controller]
kind = "sim"
model = "bilinear"
params = {{ k0 = 100.0, fy = 20.0, alpha = 0.02 }}
"""
PLAIN3 = THREE.replace(f"[sites.setup]\nkind = \"ThreeActuators2d\"\n{GEOMETRY}nlGeom = true\n",
                       'setup = "NoTransformation"\n')
"""Three actuators without geometry: what three DOFs cost the protocol, record and specimen."""
TARGET_RATIO = 1.3
TARGET_AGREEMENT = 1e-9


def step_cost(steps: int, rounds: int, record: bool) -> None:
    cost: dict[str, list[float]] = {"one": [], "plain3": [], "three": []}
    assert "ThreeActuators2d" not in PLAIN3
    for r in range(rounds):
        order = [("one", ONE, 1), ("plain3", PLAIN3, 3), ("three", THREE, 3)]
        for name, site, dofs in order if r % 2 == 0 else order[::-1]:
            cost[name] += asyncio.run(step_path(dofs, steps, record, False, 1, None, site=site))
    one, plain, three = (statistics.median(cost[k]) for k in ("one", "plain3", "three"))
    print(f"step cost, {steps} steps × {rounds} rounds, record {'on' if record else 'off'}, "
          "µs CPU/step (min / median):")
    print(f"  OneActuator, 1 DOF            {min(cost['one']):6.1f} / {one:6.1f}")
    print(f"  NoTransformation, 3 DOF       {min(cost['plain3']):6.1f} / {plain:6.1f}  "
          f"({plain / one:.2f}× one)")
    print(f"  ThreeActuators2d nlGeom, 3    {min(cost['three']):6.1f} / {three:6.1f}  "
          f"({three / one:.2f}× one, {three / plain:.2f}× three without geometry)")
    print(f"  target ≤ {TARGET_RATIO}× one: {'met' if three / one <= TARGET_RATIO else 'NOT met'}")


def column(steps: int) -> None:
    from tests.support.bridge import RunningBridge

    k = 0.5
    links = [((-500.0, 0.0), (-1500.0, 0.0)), ((-500.0, 0.0), (-500.0, -900.0)),
             ((400.0, 0.0), (400.0, -800.0))]  # (platform point, ground point)
    params = {"mass": 0.05, "inertia": 0.05 * 450.0**2, "k": k, "dt": 0.01, "nsteps": steps,
              "period": 0.8, "load": 60.0, "links": links}
    config = textwrap.dedent(f"""
        [record]
        enabled = false
        [[sites]]
        name = "column"
        port = 0
        dofs = 3
        [sites.setup]
        kind = "ThreeActuators2d"
        nlGeom = true
        [sites.controller]
        kind = "sim"
        model = "elastic"
        params = {{ k = {k} }}
        """).replace("nlGeom = true\n", GEOMETRY + "nlGeom = true\n")
    with tempfile.TemporaryDirectory() as tmp, RunningBridge(config, Path(tmp)) as bridge:
        through = run_peer("column3", {**params, "port": bridge.ports["column"]})["u"]
    scale = [max(abs(u[i]) for u in through) for i in range(3)]
    print(f"column, {steps} steps: peak x {scale[0]:.1f} mm, y {scale[1]:.2f} mm, θ "
          f"{scale[2]:.4f} rad")

    def report(name: str, other: list[list[float]]) -> float:
        worst = [max(abs(a[i] - b[i]) for a, b in zip(through, other, strict=True)) / scale[i]
                 for i in range(3)]
        print(f"  vs {name}: largest difference relative to the peak x {worst[0]:.1e}, "
              f"y {worst[1]:.1e}, θ {worst[2]:.1e}")
        return max(worst)

    exact = report("the same Newmark + Newton, geometry by hand (numpy)",
                   by_hand(params, k, links))
    print(f"  target ≤ {TARGET_AGREEMENT:g}: {'met' if exact <= TARGET_AGREEMENT else 'NOT met'}")
    for stiff in (1e2, 1e3, 1e4):
        try:
            report(f"OpenSees corotTruss actuators on corotational links {stiff:g}× stiffer",
                   run_peer("column3", {**params, "port": None, "stiff": stiff})["u"])
        except RuntimeError as exc:
            print(f"  OpenSees links {stiff:g}× stiffer: {str(exc).splitlines()[1][:80]}")


def by_hand(p: dict[str, Any], k: float, links: list[tuple[tuple[float, float],
                                                          tuple[float, float]]]
            ) -> list[list[float]]:
    """The column integrated as OpenSees does (Newmark γ = 1/2, β = 1/4, Newton to a
    displacement increment of 1e-13), the actuators' forces from the exact geometry written
    out here, independently of the bridge's setups."""
    m = np.diag([p["mass"], p["mass"], p["inertia"]])
    dt, beta, gamma = p["dt"], 0.25, 0.5

    def internal(q: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        force, tangent = np.zeros(3), np.zeros((3, 3))
        c, s = math.cos(q[2]), math.sin(q[2])
        for (px, py), (gx, gy) in links:
            wx, wy = c * px - s * py, s * px + c * py
            r = np.array([q[0] + wx - gx, q[1] + wy - gy])
            length, rest = float(np.hypot(*r)), math.hypot(px - gx, py - gy)
            e = r / length
            row = np.array([e[0], e[1], e[1] * wx - e[0] * wy])
            force += k * (length - rest) * row
            tangent += k * np.outer(row, row)  # enough for Newton to converge
        return force, tangent

    u, v, a = np.zeros(3), np.zeros(3), np.zeros(3)
    out = []
    for n in range(1, p["nsteps"] + 1):
        t = n * dt
        load = p["load"] * math.sin(2 * math.pi * t / p["period"]) * np.array([1.0, -0.3, 300.0])
        x = u.copy()
        for _ in range(100):
            acc = (x - u) / (beta * dt * dt) - v / (beta * dt) - (0.5 / beta - 1) * a
            f, kt = internal(x)
            step = np.linalg.solve(kt + m / (beta * dt * dt), load - f - m @ acc)
            x += step
            if np.linalg.norm(step) <= 1e-13:
                break
        acc = (x - u) / (beta * dt * dt) - v / (beta * dt) - (0.5 / beta - 1) * a
        v = v + dt * ((1 - gamma) * a + gamma * acc)
        u, a = x, acc
        out.append(u.tolist())
    return out


def main(argv: list[str] | None = None) -> None:
    ap = argparse.ArgumentParser(prog="benchmarks.bench_setups")
    ap.add_argument("--steps", type=int, default=3000)
    ap.add_argument("--rounds", type=int, default=5)
    ap.add_argument("--column-steps", type=int, default=400)
    ap.add_argument("--no-column", action="store_true")
    ap.add_argument("--quick", action="store_true", help="300 steps, one round, 50 column steps")
    args = ap.parse_args(argv)
    if args.quick:
        args.steps, args.rounds, args.column_steps = 300, 1, 50
    step_cost(args.steps, args.rounds, record=True)
    step_cost(args.steps, args.rounds, record=False)
    if not args.no_column:
        column(args.column_steps)


if __name__ == "__main__":
    main()
