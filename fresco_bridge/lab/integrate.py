"""The compose ``integrator`` service: the demo frame driving a running bridge's damper site."""

from __future__ import annotations

import json
import sys
import time
from typing import TextIO

from .compose import LabError


def run_integrator(host: str, port: int, *, duration: float, pga: float, seed: int,
                   connect_timeout: float = 30.0, out: TextIO | None = None) -> dict[str, float]:
    """The demo's two-story frame (explicit Newmark) driving the damper site of a running bridge.

    Retries the connection until ``connect_timeout`` (the bridge may still be starting); every
    step then has the link's own receive deadline.
    """
    import numpy as np

    from ..integrator import (
        DEMO_DT,
        demo_frame_integrator,
        demo_site_coupling,
        kanai_tajimi,
        run_coupled,
    )
    from ..integrator.link import GenericClientLink

    motion = kanai_tajimi(pga, duration=duration, dt=DEMO_DT, seed=seed)
    link = GenericClientLink(host, port, 2, timeout=10.0)
    deadline = time.monotonic() + connect_timeout
    while True:
        try:
            link.connect()
            break
        except OSError as exc:
            if time.monotonic() > deadline:
                raise LabError(f"integrator: bridge {host}:{port} not reachable within "
                               f"{connect_timeout:g} s: {exc}") from None
            time.sleep(0.2)
    coupling = demo_site_coupling(link)
    integ = demo_frame_integrator(coupling, motion)
    t0 = time.perf_counter()
    try:
        response = run_coupled(integ, coupling)
    finally:
        link.close()
    wall = time.perf_counter() - t0
    drift, forces = response.drift, coupling.force("damper")
    summary = {
        "steps": float(integ.n_steps),
        "ms_per_step": 1000.0 * wall / max(integ.n_steps, 1),
        "peak_story1_drift_mm": float(np.max(np.abs(drift[:, 0]))),
        "peak_damper_force_kN": float(np.max(np.abs(forces))) if forces.size else 0.0,
    }
    out = sys.stdout if out is None else out
    out.write("integrator: " + json.dumps(summary) + "\n")
    out.flush()
    return summary
