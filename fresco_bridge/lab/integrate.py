"""The compose ``integrator`` service: the demo frame driving a running bridge's damper site."""

from __future__ import annotations

import json
import sys
import time
from typing import TextIO

from ..numbers import rounded
from ..progress import status
from .compose import LabError


def run_integrator(host: str, port: int, *, duration: float, pga: float, seed: int,
                   connect_timeout: float = 30.0, out: TextIO | None = None
                   ) -> dict[str, float | int]:
    """The demo's two-story frame (explicit Newmark) driving the damper site of a running bridge.

    Retries the connection until ``connect_timeout`` (the bridge may still be starting); every
    step then has the link's own receive deadline.
    """
    import numpy as np

    from ..integrator import (
        DEMO_DT,
        IntegrationError,
        demo_frame_integrator,
        demo_site_coupling,
        kanai_tajimi,
        run_coupled,
    )
    from ..integrator.link import GenericClientLink, LinkError
    from ..progress import ProgressBar

    motion = kanai_tajimi(pga, duration=duration, dt=DEMO_DT, seed=seed)
    status(f"integrator: connecting to the bridge's damper site at {host}:{port} (the demo's "
           f"two-story frame, {duration:g} s of record, PGA {pga:g} m/s²)")
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
        with ProgressBar("integrator", integ.n_steps, rate_unit="steps") as bar:
            response = run_coupled(integ, coupling, progress=bar)
    except IntegrationError as exc:
        if isinstance(exc.__cause__, LinkError):  # refused, closed, silent: the link says how
            raise LabError(f"integrator: {exc.__cause__}") from None
        raise
    finally:
        link.close()
    wall = time.perf_counter() - t0
    drift, forces = response.drift, coupling.force("damper")
    summary: dict[str, float | int] = {
        "steps": integ.n_steps,
        "ms_per_step": rounded(1000.0 * wall / max(integ.n_steps, 1)),
        "peak_story1_drift_mm": rounded(float(np.max(np.abs(drift[:, 0])))),
        "peak_damper_force_kN": rounded(float(np.max(np.abs(forces)))) if forces.size else 0.0,
    }
    out = sys.stdout if out is None else out
    out.write("integrator: " + json.dumps(summary) + "\n")
    out.flush()
    return summary
