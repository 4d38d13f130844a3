"""What a diagnosis shows a person: a ten-second summary, the JSON file, a directory of plots.

Plots (PNG, matplotlib Agg through ``fresco_bridge.report.figures``): the hysteresis of the
measurement against the sim with and without the winning effect, the force residual against the
loop phase, measured against commanded displacement, and the residual spectrum.
"""

from __future__ import annotations

import json
import math
from pathlib import Path
from typing import Any

import numpy as np

from .verdict import LOW_CONFIDENCE

__all__ = ["summary", "to_json", "write_json", "write_report"]


def _f(x: Any, digits: int = 4, unit: str = "") -> str:
    if x is None or (isinstance(x, float) and not math.isfinite(x)):
        return "—"
    return f"{x:.{digits}g}{(' ' + unit) if unit else ''}"


def _pct(x: Any) -> str:
    return "—" if x is None or not math.isfinite(x) else f"{x:.2f} %"


def summary(result: dict[str, Any]) -> str:
    """The terminal summary: record, baseline, gap, where, verdict, the candidate table."""
    rec, base, verdict = result["record"], result["baseline"], result["verdict"]
    loc, noise = result["localization"], result["noise_floor"]
    cal, wh = rec["calibration"]["samples"], rec["withheld"]["samples"]
    gap = base["gap_withheld"]
    lines = [
        f"record    {rec['source']}: {rec['samples']} samples over {rec['duration_s']:.4g} s; "
        f"calibration {cal[0]}-{cal[1]}, withheld {wh[0]}-{wh[1]}",
        f"baseline  {base['kind']}: " + ", ".join(
            f"{k} {_f(v)}" for k, v in base["params"].items()),
        *([] if base.get("selection") is None else
          [f"          chosen by {base['requested']} (BIC, calibration part): "
           f"{base['selection']['reason']}"]),
        f"gap       withheld: force {_pct(gap['force_pct'])}, displacement "
        f"{_pct(gap['disp_pct'])}, total {_pct(gap['total_pct'])} (floor "
        f"{noise['floor_pct']:g} %, white noise alone {_pct(noise['noise_only_gap_pct'])})",
    ]
    layers = loc["layers"]
    interface = layers["interface"]
    where = (f"where     force gap: interface {interface['share_pct']:.0f} %, specimen "
             f"{layers['specimen']['share_pct']:.0f} %, sensor {layers['sensor']['share_pct']:.0f}"
             f" %; worst phase {loc['worst_phase']} "
             f"(NRMS {_pct(loc['phase'][loc['worst_phase']]['nrms_pct'])})")
    lines.append(where)
    if interface["measured"]:
        fei_ms, xcorr_ms = (None if interface[k] is None else 1e3 * interface[k]
                            for k in ("fei_delay_s", "xcorr_delay_s"))
        lines.append(
            f"interface NRMS {_pct(interface['nrms_pct'])}, FEI amplitude "
            f"{_f(interface['fei_amplitude'])}, FEI delay {_f(fei_ms)} ms, xcorr delay "
            f"{_f(xcorr_ms)} ms, energy error {_pct(loc['force']['energy_error_pct'])}")
    lines.append(f"VERDICT   {verdict['effect']} (confidence {verdict['confidence']:.2f}): "
                 f"{verdict['explanation']}")
    if verdict.get("not_separated_from"):
        lines.append(f"UNSURE    confidence below {LOW_CONFIDENCE:g}: not separated from "
                     f"{verdict['not_separated_from']}")
    if verdict.get("better_family"):
        lines.append(f"          try --baseline {verdict['better_family']}")
    winner = next((e for e in [*result["effects"], *result["pairs"]]
                   if e["name"] == verdict["effect"]), None)
    if winner is not None:
        for name, p in winner["params"].items():
            flag = p.get("flag")
            lines.append(f"          {name} = {_f(p['value'])} ± {_f(p['std'], 2)} {p['unit']}"
                         f"  ({p['meaning']})" + ("" if not flag else f"  [UNSURE: {flag}]"))
    lines.append("candidates (withheld gap after, shrink, score = shrink − 2 %/parameter):")
    families = [{**e, "name": f"law family {e['name']}"} for e in result.get("families", [])]
    for e in [*result["effects"], *result["pairs"][:3], *families]:
        mark = "" if e.get("compared_with") is None else f"  (vs the {e['compared_with']})"
        lines.append(f"  {e['name']:<40} {_pct(e['gap_after']['total_pct']):>9}  "
                     f"{_pct(e['shrink_pct']):>9}  {_f(e['score'], 3):>6}{mark}")
    lines.extend(f"note      {n}" for n in rec["notes"])
    lines.append(f"time      {result['seconds']:.1f} s")
    return "\n".join(lines)


def to_json(result: dict[str, Any]) -> str:
    """The JSON document (the ``_series`` arrays used by the plots are left out)."""

    def clean(obj: Any) -> Any:
        if isinstance(obj, dict):
            return {k: clean(v) for k, v in obj.items() if not k.startswith("_")}
        if isinstance(obj, list | tuple):
            return [clean(v) for v in obj]
        if isinstance(obj, float | np.floating):
            value = float(obj)
            return value if math.isfinite(value) else None
        if isinstance(obj, np.integer):
            return int(obj)
        return obj

    return json.dumps(clean(result), indent=2)


def write_json(result: dict[str, Any], path: Path) -> None:
    path.write_text(to_json(result) + "\n", encoding="utf-8")


def write_report(result: dict[str, Any], directory: Path) -> list[Path]:
    """Write summary.txt, diagnosis.json and the plots into ``directory``; the files."""
    from matplotlib.figure import Figure

    from ..report.figures import _png, _stride
    from ..report.figures import synchronization as sync_figure
    from ..runs import SessionSignals
    from .localise import phase_angle

    directory.mkdir(parents=True, exist_ok=True)
    s = result["_series"]
    t, c, m, f = s["time"], s["cmd"], s["meas_disp"], s["force"]
    sim, best, stop = s["sim"], s["best"], s["stop"]
    name = result["verdict"]["effect"]
    k = _stride(t.size)
    files: dict[str, bytes] = {}

    fig = Figure(figsize=(7.2, 5.4))
    ax = fig.add_subplot()
    x = m if m is not None else c
    ax.plot(x[::k], f[::k], lw=0.9, color="0.2", label="measured")
    ax.plot(c[::k], sim[::k], lw=0.9, ls="--", color="tab:blue", label="sim (baseline)")
    if best is not None and name not in ("none", "unexplained", "baseline_misfit"):
        bd = s["best_disp"] if s["best_disp"] is not None else c
        ax.plot(bd[::k], best[::k], lw=0.9, ls=":", color="tab:red", label=f"sim + {name}")
    ax.set_xlabel("displacement (mm)")
    ax.set_ylabel("force (kN)")
    ax.set_title("hysteresis: measured vs sim, without and with the effect")
    ax.grid(alpha=0.3)
    ax.legend(fontsize="small")
    fig.tight_layout()
    files["hysteresis_overlay.png"] = _png(fig)

    fig = Figure(figsize=(7.2, 4.8))
    ax = fig.add_subplot()
    phase = phase_angle(c)
    ax.scatter(phase[::k], (f - sim)[::k], s=3, alpha=0.5, label="measured − sim (baseline)")
    if best is not None and name not in ("none", "unexplained", "baseline_misfit"):
        ax.scatter(phase[::k], (f - best)[::k], s=3, alpha=0.5, color="tab:red",
                   label=f"measured − sim + {name}")
    ax.set_xlabel("loop phase of the command (deg; 0 = positive peak, ±180 = negative peak)")
    ax.set_ylabel("force residual (kN)")
    ax.set_title("force residual against loop phase")
    ax.grid(alpha=0.3)
    ax.legend(fontsize="small", markerscale=4)
    fig.tight_layout()
    files["residual_vs_phase.png"] = _png(fig)

    meas = (m if m is not None else np.full_like(c, math.nan))[:, None]
    signals = SessionSignals("record", 1, t, np.arange(t.size), c[:, None], meas, f[:, None])
    files["measured_vs_command.png"] = sync_figure("record", [signals])

    fig = Figure(figsize=(7.2, 4.8))
    ax = fig.add_subplot()
    dt = float(np.median(np.diff(t)))
    freqs = np.fft.rfftfreq(t.size, dt)[1:]
    for label, r, color in (("force: measured − sim", f - sim, "tab:blue"),
                            (f"force: measured − sim + {name}",
                             None if best is None else f - best, "tab:red")):
        if r is None or (name in ("none", "unexplained", "baseline_misfit") and color == "tab:red"):
            continue
        spectrum = np.abs(np.fft.rfft((r - r.mean()) * np.hanning(r.size)))[1:]
        ax.semilogy(freqs, spectrum, lw=0.8, color=color, label=label)
    ax.axvline(1.0 / (2.0 * dt), color="0.5", lw=0.6)
    ax.set_xlabel("frequency (Hz)")
    ax.set_ylabel("|FFT| of the residual (kN, Hann window)")
    ax.set_title(f"residual spectrum (withheld part starts at t = {t[stop]:.4g} s)")
    ax.grid(alpha=0.3, which="both")
    ax.legend(fontsize="small")
    fig.tight_layout()
    files["residual_spectrum.png"] = _png(fig)

    written = []
    for filename, data in files.items():
        path = directory / filename
        path.write_bytes(data)
        written.append(path)
    (directory / "summary.txt").write_text(summary(result) + "\n", encoding="utf-8")
    write_json(result, directory / "diagnosis.json")
    return [*written, directory / "summary.txt", directory / "diagnosis.json"]
