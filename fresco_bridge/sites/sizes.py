"""Which signal sizes a site can serve, and its constant matrices in wire order (pure)."""

from __future__ import annotations

from protocol import SignalSizes


def size_problems(dofs: int, ctrl: SignalSizes, daq: SignalSizes) -> list[str]:
    """OpenFresco's rule: every non-zero size equals the element's DOFs, time sizes are 1;
    force control is not supported. Returns what does not fit (empty: it all fits)."""
    problems = []
    if ctrl.disp != dofs:
        problems.append(f"ctrl disp size {ctrl.disp} != {dofs} DOF(s) served by the site")
    for label, v in (("ctrl vel", ctrl.vel), ("ctrl accel", ctrl.accel),
                     ("daq disp", daq.disp), ("daq vel", daq.vel),
                     ("daq accel", daq.accel), ("daq force", daq.force)):
        if v not in (0, dofs):
            problems.append(f"{label} size {v} is neither 0 nor {dofs}")
    if ctrl.force:
        problems.append(f"ctrl force size {ctrl.force}: force control is not supported")
    for label, v in (("ctrl time", ctrl.time), ("daq time", daq.time)):
        if v not in (0, 1):
            problems.append(f"{label} size {v} is neither 0 nor 1")
    return problems


def column_major(rows: list[list[float]] | None, n: int) -> tuple[float, ...]:
    """An n×n matrix given as rows (config) in the column-major order of the wire; zero if
    none."""
    if rows is None:
        return (0.0,) * (n * n)
    return tuple(float(rows[r][c]) for c in range(n) for r in range(n))
