"""OpenSees uniaxial materials in a real OpenSeesPy process, as references for the models.

``setStrain`` of OpenSeesPy's ``testUniaxialMaterial`` calls ``setTrialStrain`` and then
``commitState``, so every strain is a committed step; a model mirrors it with ``set_trial(d)`` +
``commit()``.
"""

from __future__ import annotations

import json
import random
import subprocess
import sys

from tests.support.bridge import opensees_env

_DRIVER = """
import json, sys
import openseespy.opensees as ops
jobs = json.loads(sys.stdin.read())
results = []
for tag, (material, strains) in enumerate(jobs, start=1):
    ops.wipe()
    ops.uniaxialMaterial(material[0], tag, *material[1:])
    ops.testUniaxialMaterial(tag)
    rows = []
    for strain in strains:
        ops.setStrain(strain)
        rows.append([ops.getStrain(), ops.getStress(), ops.getTangent()])
    results.append(rows)
print("RESULT-JSON " + json.dumps(results))
"""


def run_materials(jobs: list[tuple[list[object], list[float]]]) -> list[list[list[float]]]:
    """Drive each (material command args, strains) job; returns [strain, stress, tangent] rows."""
    env = opensees_env()
    proc = subprocess.run(
        [sys.executable, "-c", _DRIVER],
        input=json.dumps(jobs),
        capture_output=True,
        text=True,
        env=env,
        timeout=120,
        check=False,
    )
    lines = [ln for ln in proc.stdout.splitlines() if ln.startswith("RESULT-JSON ")]
    assert proc.returncode == 0 and lines, f"OpenSees driver failed:\n{proc.stderr[-2000:]}"
    result: list[list[list[float]]] = json.loads(lines[-1].removeprefix("RESULT-JSON "))
    return result


def cyclic_history(rng: random.Random, dy: float, count: int) -> list[float]:
    """Random cyclic strains: tiny reversals, medium steps, elastic-through-yield jumps, repeats."""
    history = [3.0 * dy, -0.5 * dy, 4.5 * dy]  # virgin jump through yield, then two big reversals
    d = history[-1]
    while len(history) < count:
        pick = rng.random()
        if pick < 0.3:
            step = rng.uniform(-0.05, 0.05) * dy
        elif pick < 0.65:
            step = rng.uniform(-1.0, 1.0) * dy
        elif pick < 0.9:
            step = rng.choice((-1.0, 1.0)) * rng.uniform(2.0, 6.0) * dy
        else:
            step = 0.0
        d = min(8.0 * dy, max(-8.0 * dy, d + step))
        history.append(d)
    return history


def close(actual: float, expected: float) -> bool:
    return abs(actual - expected) <= max(1e-9 * abs(expected), 1e-12)
