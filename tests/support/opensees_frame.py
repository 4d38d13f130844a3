"""The conformance frame: a two-story shear frame in real OpenSeesPy, story 1 a bilinear damper
and story 2 elastic, either served by the bridge (genericClient elements) or as the equivalent
pure-OpenSees elements (zeroLength + Steel01/Elastic), for comparisons to 1e-9."""

from __future__ import annotations

import math

M = 0.0202228  # story mass, kN·s²/mm (20222.8 kg)
BILINEAR = {"k0": 20.0, "fy": 15.0, "alpha": 0.05}
K2 = 15.0


def accel(n: int = 300) -> list[float]:
    """A decaying two-tone base acceleration (mm/s² after the factor) that yields story 1."""
    return [
        math.exp(-0.01 * i) * (math.sin(2 * math.pi * 2.0 * 0.01 * i)
                               + 0.5 * math.sin(2 * math.pi * 5.3 * 0.01 * i))
        for i in range(n)
    ]


def site(name: str, port: int, *, dofs: int, setup: str, model: str, params: dict[str, float],
          transport: str = "tcp") -> str:
    p = ", ".join(f"{k} = {v!r}" for k, v in params.items())
    return (
        f'[[sites]]\nname = "{name}"\nport = {port}\ntransport = "{transport}"\ndofs = {dofs}\n'
        f'setup = "{setup}"\n[sites.controller]\nmodel = "{model}"\nparams = {{ {p} }}\n'
    )


def frame_config(transport: str = "tcp") -> str:
    return (
        '[bridge]\nrun_name = "conformance"\n'
        + site("story1", 0, dofs=2, setup="OneActuator", model="bilinear", params=BILINEAR,
                transport=transport)
        + site("story2", 0, dofs=2, setup="OneActuator", model="elastic", params={"k": K2},
                transport=transport)
    )


def rel_diff(a: list[float], b: list[float]) -> float:
    assert len(a) == len(b)
    scale = max(abs(x) for x in b)
    assert scale > 0
    return max(abs(x - y) for x, y in zip(a, b, strict=True)) / scale


def frame_params(**extra: object) -> dict[str, object]:
    p: dict[str, object] = {
        "masses": [M, M], "dt": 0.01, "nsteps": 300, "accel": accel(), "factor": 3000.0,
        "story1": ["Steel01", 1, BILINEAR["fy"], BILINEAR["k0"], BILINEAR["alpha"]],
        "story2": ["Elastic", 2, K2],
    }
    p.update(extra)
    return p
