"""What a diagnosis shows a person: a ten-second summary, the JSON file, a directory of plots.

Plots (PNG, ``fresco_bridge.diagnosis.figures``): the hysteresis of the measurement against the
sim without and with the winning effect and their force residuals in time, the force residual
against the loop phase, measured against commanded displacement, and the residual spectrum.
"""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

from ..numbers import fmt, pct
from ..report.diagnosis import BASIS_WORDS, confidence_text, headline, on_basis
from .result import Diagnosis, json_ready

__all__ = ["summary", "to_json", "write_json", "write_report"]


def summary(diagnosis: Diagnosis) -> str:
    """The terminal summary: record, baseline, gap, where, verdict, the candidate table; read
    from the JSON document, so it prints what ``diagnosis.json`` holds."""
    result = diagnosis.to_json()
    rec, base, verdict = result["record"], result["baseline"], result["verdict"]
    loc, noise = result["localization"], result["noise_floor"]
    cal, wh = rec["calibration"]["samples"], rec["withheld"]["samples"]
    gap = base["gap_withheld"]
    lines = [
        f"record    {rec['source']}: {rec['samples']} samples over {rec['duration_s']:.4g} s; "
        f"calibration {cal[0]}-{cal[1]}, withheld {wh[0]}-{wh[1]}",
        f"baseline  {base['kind']}: " + ", ".join(
            f"{k} {fmt(v)}" for k, v in base["params"].items()),
        *([] if base.get("selection") is None else
          [f"          chosen by {base['requested']} (BIC, calibration part): "
           f"{base['selection']['reason']}"]),
        f"gap       withheld: force {pct(gap['force_pct'])}, displacement "
        f"{pct(gap['disp_pct'])}, total {pct(gap['total_pct'])} (floor "
        f"{noise['floor_pct']:g} %, white noise alone {pct(noise['noise_only_gap_pct'])})",
    ]
    layers = loc["layers"]
    interface = layers["interface"]
    where = (f"where     force gap: interface {pct(interface['share_pct'], 0)}, specimen "
             f"{pct(layers['specimen']['share_pct'], 0)}, sensor "
             f"{pct(layers['sensor']['share_pct'], 0)}; worst phase {loc['worst_phase']} "
             f"(NRMS {pct(loc['phase'][loc['worst_phase']]['nrms_pct'])})")
    lines.append(where)
    if interface["measured"]:
        fei_ms, xcorr_ms = (None if interface[k] is None else 1e3 * interface[k]
                            for k in ("fei_delay_s", "xcorr_delay_s"))
        lines.append(
            f"interface NRMS {pct(interface['nrms_pct'])}, FEI amplitude "
            f"{fmt(interface['fei_amplitude'])}, FEI delay {fmt(fei_ms)} ms, xcorr delay "
            f"{fmt(xcorr_ms)} ms, energy error {pct(loc['force']['energy_error_pct'])}")
    if result.get("interface_gap") is not None:
        from .interface_gap import interface_lines

        lines.extend(interface_lines(result["interface_gap"]))
    stories = verdict.get("stories") or []
    named = headline(result)["named"]
    lines.append(f"VERDICT   {named} (confidence {confidence_text(verdict)}): "
                 f"{verdict['explanation']}")
    if result.get("hidden"):
        lines.append("hidden    no command channel: the measured displacement drives the law, "
                     "so these were not judged:")
        lines.extend(f"          {line}" for line in result["hidden"])
    if len(stories) > 1:
        lines.append("TWO STORIES " + " / ".join(f"{st['effect']} {st['weight']:.2f}"
                                               for st in stories)
                     + f"; to separate them: {verdict.get('separated_by')}")
    if verdict.get("better_family"):
        lines.append(f"          try --baseline {verdict['better_family']}")
    winner = next((e for e in [*result["effects"], *result["pairs"]]
                   if e["name"] == verdict["effect"]), None)
    if winner is not None:
        for name, p in winner["params"].items():
            flag = p.get("flag")
            unit = "" if p["unit"] == "1" else p["unit"]  # "1": dimensionless
            lines.append(f"          {name} = {fmt(p['value'])} ± {fmt(p['std'], unit, 2)}"
                         f"  ({p['meaning']})"
                         + ("" if not flag else f"  [UNSURE: {flag}]"))
    basis = verdict.get("gap_basis", "raw")
    lines.append(f"candidates (withheld gap after, shrink, score = shrink − 2 %/parameter; "
                 f"{BASIS_WORDS.get(basis, basis)}, as the verdict):")
    families = [{**e, "name": f"law family {e['name']}"} for e in result.get("families", [])]
    for e in [*result["effects"], *result["pairs"][:3], *families]:
        mark = "" if e.get("compared_with") is None else f"  (vs the {e['compared_with']})"
        after, shrink, score = on_basis(e, basis)
        lines.append(f"  {e['name']:<40} {pct(after):>9}  {pct(shrink):>9}  "
                     f"{fmt(score, digits=3):>6}{mark}")
    lines.extend(f"note      {n}" for n in rec["notes"])
    lines.append(f"time      {result['seconds']:.1f} s")
    return "\n".join(lines)


def to_json(doc: Diagnosis | dict[str, Any]) -> str:
    """The JSON text of a diagnosis (or of a document holding diagnoses: ``--same-device``)."""
    return json.dumps(json_ready(doc), indent=2)


def write_json(result: Diagnosis, path: Path) -> None:
    path.write_text(to_json(result) + "\n", encoding="utf-8")


def write_report(result: Diagnosis, directory: Path) -> list[Path]:
    """Write summary.txt, diagnosis.json and the plots into ``directory``; the files."""
    from .figures import plots

    directory.mkdir(parents=True, exist_ok=True)
    files = plots(result)

    written = []
    for filename, data in files.items():
        path = directory / filename
        path.write_bytes(data)
        written.append(path)
    (directory / "summary.txt").write_text(summary(result) + "\n", encoding="utf-8")
    write_json(result, directory / "diagnosis.json")
    return [*written, directory / "summary.txt", directory / "diagnosis.json"]
