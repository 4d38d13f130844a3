"""``fresco-bridge demo`` (the default): the source paper's story end to end, in one process.

Four acts, all on embedded defaults (no broker, no hardware, no file from outside the package):

1. *Characterisation*: a short cyclic test (±1 to ±16 mm, two cycles each) of a nominally
   identical damper on the simulated rig, through the bridge like any test; its run directory
   is the twin's offline database (what the paper calls the conventional test).
2. *Hybrid test*: the two-story frame integrated by our explicit Newmark. The tested damper
   (story 1) is the ``damper`` site: a degrading, pinching BWBN on the simulated rig
   ``damper-lab`` (servo delay and lag, a little backlash, sensor noise). Its twin (story 2,
   the paper's "remaining components with similar properties") is the ``twin`` site, an
   updatable site learning from ``damper`` with ``online_improved`` beside the event loop;
   the integrator reaches both over the genericClient protocol.
3. *Scores*: the twin's served force against the damper's true law along the twin's drift,
   and the same for the Bilinear calibrated to the characterisation (the study's
   ``conventional_calibrated``), replayed through the same source history.
4. *Diagnosis* of the recorded ``damper`` site (``fresco-bridge diagnose``'s code) and the
   report, whose diagnosis section reads what act 4 wrote into ``RUN/diagnosis-damper``.

The bridge is closed before acts 3 and 4, so nothing they compute touches an event loop.
"""

from __future__ import annotations

import json
import sys
import time
from pathlib import Path
from typing import Any, Final

import numpy as np
import numpy.typing as npt

from .config import parse_config
from .demo import bridge_act, telemetry_text
from .exit_codes import Interrupted
from .integrator import (
    DEMO_DT,
    GroundMotion,
    demo_frame_integrator,
    kanai_tajimi,
    paper_two_story_frame,
    read_ground_motion,
    run_coupled,
)
from .integrator.coupling import Placement, StoryCoupling
from .integrator.link import GenericClientLink, SiteElement
from .numbers import fmt, pct
from .progress import ProgressBar, command_name
from .record import export_csv

__all__ = [
    "CHARACTERISATION_AMPLITUDES_MM",
    "RIG_PRESET",
    "characterisation_path",
    "format_story",
    "run_story",
    "story_config_text",
    "twin_scores",
]

RIG_PRESET: Final = "damper-lab"
"""The ``sim_actuator`` preset of the tested damper (``sim-actuator presets``)."""
DAMPER_K0: Final = 8.0
"""The damper's initial stiffness (kN/mm): the rig's and the twin's stiffness estimate."""
SOURCE, TWIN = "damper", "twin"
TWIN_STORY: Final = 1
"""0-based story of the twin: story 2 (the study's generalisation layout)."""
UPDATER: Final = "online_improved"
TWIN_FIGURE: Final = "twin_vs_bilinear.png"
CHARACTERISATION_AMPLITUDES_MM: Final = (1.0, 2.0, 4.0, 6.0, 9.0, 12.0, 16.0)
CHARACTERISATION_STEPS_PER_CYCLE: Final = 40
DEMO_LEARNER_DEADLINE: Final = 20.0
"""The twin's learner deadline (s) in the demo. The default 2 s suits a lab's dedicated host;
on a busy laptop the updater's refit (every 300 steps) missed it and the demo ended in HOLD."""
DEMO_CONTROLLER_TIMEOUT: Final = 30.0
"""``bridge.controller_timeout`` (s) in the demo: longer than the learner deadline, as required."""

FloatArray = npt.NDArray[np.float64]


def characterisation_path() -> FloatArray:
    """The characterisation's displacement history (mm): two sine cycles per amplitude."""
    n = CHARACTERISATION_STEPS_PER_CYCLE
    cycle = np.sin(2.0 * np.pi * np.arange(2 * n) / n)
    return np.concatenate([*(a * cycle for a in CHARACTERISATION_AMPLITUDES_MM), [0.0]])


def _site(name: str, transport: str) -> str:
    return (f'[[sites]]\nname = "{name}"\nport = 0\ntransport = "{transport}"\ndofs = 2\n'
            'setup = "OneActuator"\n')


def _rig(transport: str) -> str:
    return (_site(SOURCE, transport) + '[sites.controller]\nkind = "rig"\n'
            f'preset = "{RIG_PRESET}"\nstiffness = {DAMPER_K0!r}\n'
            f"ramp_time = {DEMO_DT!r}   # each move in one time step, as in a fast test\n")


def story_config_text(offline: Path | None, transport: str = "tcp", run_name: str = "demo", *,
                      telemetry: str = "") -> str:
    """The lab config of act 2 (``offline``: the characterisation run) or, without
    ``offline``, of act 1 (the rig alone)."""
    head = ("# fresco-bridge demo: the two-story frame; tested damper (story 1) on the "
            "simulated rig, its twin (story 2) learned online (mm, kN, s)\n"
            f'[bridge]\nrun_name = "{run_name}"\n'
            f"controller_timeout = {DEMO_CONTROLLER_TIMEOUT!r}   # s; generous: the demo runs "
            "on whatever machine, and a busy one must not HOLD it\n\n")
    text = head + _rig(transport)
    if offline is not None:
        text += ("\n" + _site(TWIN, transport)
                 + f'kind = "updatable"\nlearns_from = "{SOURCE}"\nupdater = "{UPDATER}"\n'
                 f"offline = {json.dumps(str(offline))}\ncausality = \"previous-step\"\n"
                 f"learner_deadline = {DEMO_LEARNER_DEADLINE!r}   # s; the updater refits "
                 "every 300 steps, slower on a busy machine\n")
    return text + telemetry


def _characterise(runs: Path, transport: str, progress: bool) -> Path:
    """Act 1: the cyclic test through the bridge; returns its run directory."""
    path = characterisation_path()
    text = story_config_text(None, transport, "demo-characterisation")
    with bridge_act(parse_config(text, "<demo characterisation>"), text, runs,
                    "act 1 (the characterisation)") as bridge:
        link = GenericClientLink("127.0.0.1", bridge.ports[SOURCE], 2, transport=transport,
                                 timeout=10.0)
        element = SiteElement(link, DAMPER_K0)
        bar = ProgressBar("act 1, characterisation", path.size, enabled=progress,
                          rate_unit="steps")
        with link:
            for i, d in enumerate(path, start=1):
                element.begin_step(i, i * DEMO_DT)
                element.set_trial(float(d))
                element.commit()
                bar(i, path.size)
        return bridge.run_dir


def run_story(
    *,
    record: Path | None = None,
    pga: float = 3.0,
    duration: float = 20.0,
    seed: int = 1,
    runs: Path = Path("runs"),
    transport: str = "tcp",
    mqtt: str | None = None,
    mqtt_prefix: str = "fresco",
    metrics_port: int | None = None,
    progress: bool = True,
) -> dict[str, Any]:
    """Run the four acts; returns the summary (also written to the run directory)."""
    if record is not None:
        motion: GroundMotion = read_ground_motion(record).scaled_to_pga(pga)
    else:
        motion = kanai_tajimi(pga, duration=duration, dt=DEMO_DT, seed=seed)
    telemetry = telemetry_text(mqtt, mqtt_prefix, metrics_port)
    started = time.perf_counter()
    print(f"fresco-bridge demo: the two-story frame under {motion.name} (PGA {pga:g} m/s²); "
          f"tested damper in story 1 = a degrading, pinching BWBN on the simulated rig "
          f"'{RIG_PRESET}' (servo delay and lag, backlash, sensor noise), site '{SOURCE}'; its "
          f"twin in story 2 = the updatable site '{TWIN}' ({UPDATER}), both served over "
          f"{transport.upper()}", file=sys.stderr)
    runs.mkdir(parents=True, exist_ok=True)
    char_dir = _characterise(runs, transport, progress)
    text = story_config_text(char_dir.resolve(), transport, telemetry=telemetry)
    with bridge_act(parse_config(text, "<demo config>"), text, runs,
                    "act 2 (the hybrid test)") as bridge:
        links = {site: GenericClientLink("127.0.0.1", bridge.ports[site], 2,
                                         transport=transport, timeout=10.0)
                 for site in (SOURCE, TWIN)}
        coupling = StoryCoupling({
            SOURCE: Placement(0, SiteElement(links[SOURCE], DAMPER_K0)),
            TWIN: Placement(TWIN_STORY, SiteElement(links[TWIN], DAMPER_K0)),
        })  # fmt: skip
        integ = demo_frame_integrator(coupling, motion)
        bar = ProgressBar("act 2, hybrid test", integ.n_steps, enabled=progress,
                          rate_unit="steps")
        t0 = time.perf_counter()
        with links[SOURCE], links[TWIN]:
            response = run_coupled(integ, coupling, progress=bar)
        wall = time.perf_counter() - t0
        run_dir = bridge.run_dir
    try:
        n_rows = export_csv(run_dir, run_dir / "steps.csv")
        with ProgressBar("act 3, scores", 1, enabled=progress) as scoring:
            scores = twin_scores(run_dir, char_dir, run_dir / TWIN_FIGURE)
            scoring(1)
        diagnosis = _diagnose(run_dir, progress)
        summary = _summary(response, motion, wall, integ.n_steps, run_dir, char_dir, n_rows,
                           scores, diagnosis)
        from .report.html import write_report

        summary_file = run_dir / "summary.json"  # the report's overview quotes its scores
        summary_file.write_text(json.dumps(summary, indent=2), encoding="utf-8")
        write_report(run_dir)
    except KeyboardInterrupt:
        raise Interrupted(
            f"fresco-bridge demo stopped by Ctrl-C after the hybrid test: its run {run_dir} is "
            "recorded and closed; the scores, diagnosis or report were not finished (next: "
            f"{command_name()} report {run_dir} --diagnose {SOURCE})") from None
    summary["total_wall_s"] = round(time.perf_counter() - started, 1)
    summary_file.write_text(json.dumps(summary, indent=2), encoding="utf-8")
    print(format_story(summary), file=sys.stderr)
    return summary


def twin_scores(run_dir: Path, char_dir: Path, figure: Path | None = None) -> dict[str, Any]:
    """The twin's served force and the calibrated Bilinear's, each against the damper's true
    law driven along the twin's drift (known in simulation only): MAETH and RMSETH in kN;
    with ``figure``, the three hysteresis loops and both error histories drawn there."""
    from sim_actuator.config import preset
    from sim_actuator.models import make_model

    from . import indicators as ind
    from .lawfit import law_forces
    from .updating.histories import read_history
    from .updating.registry import calibrated_bilinear, make_updater
    from .updating.replay import replay

    source = read_history(run_dir, site=SOURCE)
    twin = read_history(run_dir, site=TWIN)
    offline = read_history(char_dir, site=SOURCE)
    assert source.force is not None and twin.force is not None and offline.force is not None
    specimen = preset(RIG_PRESET).specimen
    truth = law_forces(make_model(specimen.kind, **specimen.params), twin.disp)
    calibrated = calibrated_bilinear("none", (offline.disp, offline.force))
    bilinear = replay(make_updater("none", params=calibrated), source.disp, source.force,
                      twin.disp, lag=True).force_pred

    def score(pred: FloatArray) -> dict[str, float]:
        return {"maeth_kN": ind.maeth(truth, pred), "rmseth_kN": ind.rmseth(truth, pred)}

    served, fixed = score(twin.force), score(bilinear)
    if figure is not None:
        _plot_twin(figure, twin.disp, truth, twin.force, bilinear)
    return {
        "twin_steps": int(twin.disp.size),
        "twin_peak_drift_mm": float(np.max(np.abs(twin.disp))),
        "updater": UPDATER, "updated": served,
        "calibrated_bilinear": {**fixed, "params": calibrated,
                                "calibrated_on": str(char_dir)},
        "rmseth_reduction_pct": 100.0 * (1.0 - served["rmseth_kN"] / fixed["rmseth_kN"]),
        "maeth_reduction_pct": 100.0 * (1.0 - served["maeth_kN"] / fixed["maeth_kN"]),
    }


def _plot_twin(path: Path, disp: FloatArray, truth: FloatArray, served: FloatArray,
               bilinear: FloatArray) -> None:
    from matplotlib.figure import Figure

    fig = Figure(figsize=(11.5, 4.4))
    left, right = fig.subplots(1, 2, gridspec_kw={"width_ratios": (1.0, 1.4)})
    left.plot(disp, truth, color="0.15", lw=1.6, label="true law (the damper's BWBN)")
    left.plot(disp, bilinear, color="tab:blue", lw=0.9, ls="--", label="calibrated Bilinear")
    left.plot(disp, served, color="tab:red", lw=0.8, label=f"served twin ({UPDATER})")
    left.set(xlabel="twin drift, story 2 (mm)", ylabel="force (kN)",
             title="Twin hysteresis: served vs true vs calibrated")
    left.legend(fontsize="small", loc="upper left")
    t = np.arange(disp.size) * DEMO_DT
    right.plot(t, bilinear - truth, color="tab:blue", lw=0.7, label="calibrated Bilinear")
    right.plot(t, served - truth, color="tab:red", lw=0.8, label=f"served twin ({UPDATER})")
    right.axhline(0.0, color="0.5", lw=0.6)
    right.set(xlabel="time (s)", ylabel="force − true force (kN)",
              title="Twin force error in time")
    right.legend(fontsize="small", loc="upper right")
    for ax in (left, right):
        ax.grid(alpha=0.3)
    fig.tight_layout()
    fig.savefig(path, dpi=110)


def _diagnose(run_dir: Path, progress: bool) -> dict[str, Any]:
    """Act 4: ``fresco-bridge diagnose RUN --site damper --report RUN/diagnosis-damper``; a
    record the diagnosis refuses (too short: ``--duration``) gives ``{"skipped": reason}``."""
    from .diagnosis.load import DiagnosisInputError
    from .diagnosis.rundir import diagnose_into_run

    try:
        return diagnose_into_run(run_dir, SOURCE,
                                 ProgressBar("act 4, diagnosis", 1, enabled=progress))
    except DiagnosisInputError as exc:
        return {"skipped": str(exc)}


def _summary(resp: Any, motion: GroundMotion, wall: float, n_steps: int, run_dir: Path,
             char_dir: Path, n_rows: int, scores: dict[str, Any],
             diagnosis: dict[str, Any]) -> dict[str, Any]:
    from .runs import load_run, summarise

    drift = resp.drift
    force = resp.experimental_force[:, 0]
    sites = summarise(load_run(run_dir))
    site = next(s for s in sites if s.site == SOURCE)
    detail = site.sessions_detail[-1]
    return {
        "run_dir": str(run_dir),
        "characterisation_dir": str(char_dir),
        "record": motion.name,
        "pga_m_s2": round(motion.pga_m_s2, 9),
        "steps": n_steps,
        "dt_s": DEMO_DT,
        "wall_s": round(wall, 3),
        "ms_per_step": round(1000 * wall / max(n_steps, 1), 4),
        "rig_preset": RIG_PRESET,
        "periods_s_with_dampers": [round(float(x), 4) for x in paper_two_story_frame().modes(
            np.array([DAMPER_K0, DAMPER_K0])).period],
        "peak_story_drift_mm": [round(float(np.max(np.abs(drift[:, i]))), 4)
                                for i in range(drift.shape[1])],
        "peak_roof_disp_mm": round(float(np.max(np.abs(resp.displacement[:, -1]))), 4),
        "peak_damper_force_kN": [round(float(force.max()), 4), round(float(force.min()), 4)],
        "max_tracking_error_mm": detail.max_tracking_error,
        "tracking_nrms": detail.nrms,
        "twin": scores,
        "diagnosis": diagnosis,
        "committed_steps_in_record": n_rows,
        "committed_steps_per_site": site.steps,
        "holds": sum(s.holds for s in sites),
        "files": ["config.toml", "run.json", "record.jsonl", "steps.csv", "summary.json",
                  "report.html", TWIN_FIGURE, f"diagnosis-{SOURCE}/summary.txt"],
    }


def format_story(s: dict[str, Any]) -> str:
    """The closing note: what happened, in a few lines, and what to try next."""
    tw, dg = s["twin"], s["diagnosis"]
    bil = tw["calibrated_bilinear"]
    params = bil["params"]
    if "skipped" in dg:
        diagnosis = f"diagnosis      skipped: {dg['skipped']}"
    else:
        diagnosis = _diagnosis_line(dg)
    run, char, cmd = s["run_dir"], s["characterisation_dir"], command_name()
    drift = " / ".join(fmt(d, digits=3) for d in s["peak_story_drift_mm"])
    peak_f = s["peak_damper_force_kN"]
    return "\n".join([
        "",
        f"run directory  {run}  ({s['steps']} time steps in {fmt(s['wall_s'], 's', 3)} through "
        f"the bridge; {s['committed_steps_per_site']} committed per site with the initial "
        f"state at t = 0; demo {fmt(s['total_wall_s'], 's', 3)} in all)",
        f"peaks          story drift {drift} mm, roof {fmt(s['peak_roof_disp_mm'], 'mm', 3)}; "
        f"tested damper {fmt(peak_f[0], digits=3)} / {fmt(peak_f[1], 'kN', 3)}; "
        f"rig tracking error up to {fmt(s['max_tracking_error_mm'], 'mm', 2)}",
        f"twin           {tw['updater']} served force vs the damper's true law (story 2, "
        f"peak drift {fmt(tw['twin_peak_drift_mm'], 'mm', 3)}): RMS error "
        f"{fmt(tw['updated']['rmseth_kN'], 'kN', 2)}, max "
        f"{fmt(tw['updated']['maeth_kN'], 'kN', 2)}",
        f"               calibrated Bilinear (k0 {fmt(params['k0'], 'kN/mm', 3)}, fy "
        f"{fmt(params['fy'], 'kN', 3)}, alpha {fmt(params['alpha'], digits=2)}): RMS "
        f"{fmt(bil['rmseth_kN'], 'kN', 2)}, max {fmt(bil['maeth_kN'], 'kN', 2)} -> updating "
        f"cuts the RMS error by {pct(tw['rmseth_reduction_pct'], 0)}",
        diagnosis,
        f"report         {run}/report.html (opens with the run at a glance and what to do next)"
        f" and {run}/{TWIN_FIGURE}",
        f"next           {cmd} report {run} --diagnose {SOURCE}   (again, from the record)",
        f"               {cmd} diagnose {run} --site {SOURCE}",
        f"               {cmd} updater replay --source {run} --site {SOURCE} --twin {run} "
        f"--twin-site {TWIN} --lag --updater online_ukf --offline {char} -o ukf.csv",
        f"               {cmd} study paper --cases conventional_calibrated,{UPDATER} "
        "--steps 600",
        f"               {cmd} demo --simple   (the ideal run: bilinear damper, no twin)",
    ])


def _diagnosis_line(dg: dict[str, Any]) -> str:
    if dg["effect"] in ("none", "unexplained", "baseline_misfit"):
        return f"diagnosis      {dg['effect']}: {dg['explanation']}"
    magnitude = ", ".join(f"{k} {fmt(v['value'], '' if v['unit'] == '1' else v['unit'], 3)}"
                          for k, v in dg["magnitude"].items()) or "–"
    return (f"diagnosis      {dg['named']} ({magnitude}; confidence {dg['confidence_text']}) "
            f"against a {dg['baseline']} sim: adding it shrinks the withheld gap from "
            f"{pct(dg['gap_before_pct'], 1)} to {pct(dg['gap_after_pct'], 1)} "
            f"({pct(dg['shrink_pct'], 1)})")
