"""One case of the study driven by real OpenSees (``study paper --integrator opensees``).

The same case as ``study.simulate``, but the frame is integrated by OpenSeesPy
(``study.opensees_frame``, its own process) and both dampers are ``genericClient`` elements
served by one bridge started in this process for the case: the tested damper by an
experimental site whose ``sim`` controller holds the specimen's true law, the twin by an
updatable site with the case's updater learning from it in the bridge's worker process. So
the study exercises the product path a lab uses: the protocol, the sites, the learner beside
the event loop, either causality.

Load-cell noise (``--noise``) is the ``sim`` controller's ``load_cell_noise``: the same
``Sensor`` with the run's seed and standard deviation, one draw per trial, as the in-process
study's ``MeasuredElement``. The two paths' noise samples are not aligned (the in-process
element also reads at-rest step 0, and an OpenSees Newton step may try more than once), so a
noisy case agrees with the in-process one statistically, not sample for sample.
"""

from __future__ import annotations

import importlib.util
import json
import subprocess
import sys
import tempfile
from collections.abc import Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from fresco_bridge.integrator import DEMO_DT, DEMO_ZETA, GroundMotion, paper_two_story_frame
from fresco_bridge.lawfit import law_forces
from fresco_bridge.opensees_runtime import INSTALL_HINT
from fresco_bridge.study.simulate import (
    CaseHistory,
    FloatArray,
    specimen_model,
    specimen_params,
)
from fresco_bridge.updating.base import Updater

__all__ = ["OpenSeesError", "TwinSite", "simulate_case_opensees"]

OPENSEES_TIMEOUT = 3600.0
"""Seconds one case's OpenSees process may take before it counts as hung."""


class OpenSeesError(RuntimeError):
    """OpenSeesPy is missing, failed or hung."""


@dataclass(frozen=True)
class TwinSite:
    """The case's twin as an updatable site: its updater and what it is configured with."""

    updater: str
    options: Mapping[str, Any] = field(default_factory=dict)
    offline: tuple[FloatArray, FloatArray] | None = None
    """The offline database (d, F), written to a CSV for the site."""
    model: Any = None
    """A pre-trained ANN, saved to a model file for the site."""


def _require_opensees() -> None:
    """Fail before the bridge starts when OpenSeesPy is missing (the frame process imports it
    through ``opensees_runtime``, which finds the wheel's bundled BLAS itself)."""
    if importlib.util.find_spec("openseespy") is None:
        raise OpenSeesError(f"--integrator opensees needs OpenSeesPy ({INSTALL_HINT})")


def _toml(value: Any) -> str:
    """A TOML value (inline table for a mapping; JSON's scalars and strings are TOML's)."""
    if isinstance(value, Mapping):
        return "{ " + ", ".join(f"{k} = {_toml(v)}" for k, v in value.items()) + " }"
    return json.dumps(value)


def _lab_toml(specimen: str, twin: TwinSite, causality: str, folder: Path, *,
              noise_std: float = 0.0, noise_seed: int = 0) -> str:
    """Two sites: ``tested`` (sim, the true law read through the load cell) and ``twin``
    (updatable, learning from it)."""
    kind, params = specimen_params(specimen)
    lines = [
        '[bridge]\nrun_name = "study"\n',
        '[[sites]]\nname = "tested"\nport = 0\ndofs = 2\nsetup = "OneActuator"\n',
        f'[sites.controller]\nkind = "sim"\nmodel = "{kind}"\nparams = {_toml(params)}\n'
        f'load_cell_noise = {float(noise_std)!r}\nnoise_seed = {int(noise_seed)}\n',
        '[[sites]]\nname = "twin"\nport = 0\ndofs = 2\nsetup = "OneActuator"\n'
        f'kind = "updatable"\nlearns_from = "tested"\nupdater = "{twin.updater}"\n'
        f'causality = "{causality}"\n',
    ]
    if twin.offline is not None:
        path = folder / "offline.csv"
        d, f = twin.offline
        path.write_text("time,disp,force\n" + "".join(
            f"{DEMO_DT * (i + 1)!r},{float(x)!r},{float(y)!r}\n"
            for i, (x, y) in enumerate(zip(d, f, strict=True))), encoding="utf-8")
        lines.append(f"offline = {json.dumps(str(path))}\n")
    if twin.model is not None:
        from fresco_bridge.updating.modelfile import save_model

        path = folder / "pretrained.ann"
        save_model(twin.model, path)
        lines.append(f"model = {json.dumps(str(path))}\n")
    if twin.options:
        lines.append(f"updater_options = {_toml(twin.options)}\n")
    return "".join(lines)


def _frame_params(layout: str, specimen: str, motion: GroundMotion, steps: int,
                  ports: tuple[int, int]) -> dict[str, Any]:
    """The study's frame (``simulate_case``'s masses, stiffness and Rayleigh damping)."""
    frame = paper_two_story_frame()
    twin_story = 0 if layout == "paper" else 1
    extra = np.zeros(frame.n_stories)
    k0 = specimen_model(specimen).initial_tangent
    extra[0] += k0
    extra[twin_story] += k0
    alpha_m, beta_k, _ = frame.rayleigh(DEMO_ZETA, (1, 2), extra_story_stiffness=extra)
    return {
        "masses": frame.masses.tolist(), "dt": DEMO_DT, "steps": steps,
        "frame_stiffness": frame.story_stiffness.tolist(),
        "frame_eta": (beta_k * (frame.story_stiffness + extra)).tolist(),
        "alpha_m": alpha_m, "accel": motion.accel_mm_s2.tolist(),
        "dampers": [[0, ports[0]], [twin_story, ports[1]]],
    }


def _run_opensees(params: dict[str, Any]) -> tuple[FloatArray, float]:
    """The floor displacements (steps, 2) of the frame run by OpenSeesPy in its own process,
    and the wall time of its step loop (s)."""
    try:
        proc = subprocess.run([sys.executable, "-m", "fresco_bridge.study.opensees_frame"],
                              input=json.dumps(params), capture_output=True,
                              text=True, timeout=OPENSEES_TIMEOUT)  # fmt: skip
    except subprocess.TimeoutExpired:
        raise OpenSeesError(f"OpenSees did not finish within {OPENSEES_TIMEOUT:g} s") from None
    out = [ln for ln in proc.stdout.splitlines() if ln.startswith("RESULT ")]
    if proc.returncode != 0 or not out:
        raise OpenSeesError(f"OpenSees failed (exit {proc.returncode}): "
                            f"{proc.stderr.strip()[-1500:]}")  # fmt: skip
    result = json.loads(out[-1][len("RESULT "):])
    return np.asarray(result["floors"], dtype=np.float64), float(result["loop_seconds"])


def simulate_case_opensees(
    layout: str,
    specimen: str,
    twin: TwinSite,
    motion: GroundMotion,
    *,
    steps: int | None = None,
    causality: str = "same-step",
    ahead_updater: Updater | None = None,
    noise_std: float = 0.0,
    noise_seed: int = 0,
) -> CaseHistory:
    """One case, OpenSees-driven, to the end of the record (or ``steps`` steps after step 0).

    The twin's one-step-ahead force is its served answer under ``previous-step``; under
    ``same-step`` it is replayed with ``ahead_updater`` (a fresh copy of the case's updater)
    over the recorded histories, learned through step i - 1. Update times are the worker's,
    not reported per step here (``update_seconds`` is empty); ``extra["loop_seconds"]`` is the
    wall time of OpenSees' step loop (start-up of the bridge, worker and OpenSees excluded)."""
    from fresco_bridge.config import parse_config
    from fresco_bridge.daemon import BridgeThread
    from fresco_bridge.updating.histories import read_history
    from fresco_bridge.updating.replay import replay

    if layout not in ("paper", "generalisation"):
        raise ValueError(f"unknown layout {layout!r}; known: paper, generalisation")
    _require_opensees()
    n = motion.npts - 1 if steps is None else min(steps, motion.npts - 1)
    with tempfile.TemporaryDirectory(prefix="fresco-study-") as tmp:
        folder = Path(tmp)
        text = _lab_toml(specimen, twin, causality, folder, noise_std=noise_std,
                         noise_seed=noise_seed)
        with BridgeThread(parse_config(text, "<study>"), text, run_dir=folder) as bridge:
            ports = (bridge.ports["tested"], bridge.ports["twin"])
            floors, loop_seconds = _run_opensees(_frame_params(layout, specimen, motion, n, ports))
            run_dir = bridge.run_dir
        tested = read_history(run_dir, site="tested")
        served = read_history(run_dir, site="twin")
    assert tested.force is not None and served.force is not None

    def with_rest(x: FloatArray) -> FloatArray:
        return np.concatenate(([0.0], x))  # step 0: at rest, as the built-in integrator's

    twin_drift = with_rest(served.disp)
    twin_force = with_rest(served.force)
    ahead = twin_force
    if causality == "same-step" and ahead_updater is not None:
        ahead = with_rest(replay(ahead_updater, tested.disp, tested.force, served.disp,
                                 lag=True).force_pred)
    return CaseHistory(
        tested_drift=with_rest(tested.disp),
        tested_force=with_rest(tested.force),
        twin_drift=twin_drift,
        twin_force=twin_force,
        twin_true_force=law_forces(specimen_model(specimen), twin_drift),
        twin_ahead_force=ahead,
        update_seconds=np.zeros(0),
        floor_displacement=np.vstack((np.zeros((1, 2)), floors)),
        extra={"integrator": "opensees", "loop_seconds": loop_seconds},
    )
