"""The report's diagnosis section: what ``diagnose RUN --site S --report RUN/diagnosis-S`` wrote.

A run directory holds a site's diagnosis in ``diagnosis-<site>/`` (``diagnosis.json`` and the
plots of ``fresco_bridge.diagnosis.report``), written by ``diagnosis.rundir`` (the demo,
``report --diagnose SITE``) or by a user's ``diagnose --report``. The report reads it rather
than diagnosing again (a diagnosis costs seconds to minutes), and imports nothing of the
diagnosis, which draws with this package's figures.
"""

from __future__ import annotations

import html
import json
import math
from collections.abc import Callable
from pathlib import Path
from typing import Any, Final

__all__ = ["DIAGNOSIS_PREFIX", "diagnosis_sections", "headline"]

DIAGNOSIS_PREFIX: Final = "diagnosis-"
"""``RUN/diagnosis-<site>/``: where a site's diagnosis lives in its run directory."""
OVERLAY: Final = "hysteresis_overlay.png"
_LAW_SHAPE: Final = frozenset({"k0", "fy", "alpha", "n", "bg_sum", "beta_share", "R0", "cR1",
                               "cR2"})
"""A winner's parameters that shape the law rather than size the effect (its magnitude)."""
_NOT_AN_EFFECT: Final = frozenset({"none", "unexplained", "baseline_misfit"})


def headline(result: dict[str, Any]) -> dict[str, Any]:
    """What a person reads first of a diagnosis (its JSON): verdict, magnitude, the gap."""
    verdict = result["verdict"]
    winner = next((e for e in [*result["effects"], *result["pairs"]]
                   if e["name"] == verdict["effect"]), None)
    magnitude = {} if winner is None else {
        name: {k: p[k] for k in ("value", "std", "unit", "meaning")}
        for name, p in winner["params"].items() if name not in _LAW_SHAPE}
    return {
        "record": result["record"]["source"],
        "baseline": result["baseline"]["kind"],
        "effect": verdict["effect"],
        "confidence": verdict["confidence"],
        "gap_before_pct": verdict["gap_before_pct"],
        "gap_after_pct": verdict["gap_after_pct"],
        "shrink_pct": verdict["shrink_pct"],
        "explanation": verdict["explanation"],
        "magnitude": magnitude,
    }


def _e(v: object) -> str:
    return html.escape(str(v), quote=True)


def _num(x: Any, digits: int = 3, unit: str = "") -> str:
    """``x`` to ``digits`` significant digits; ``–`` when undefined."""
    if x is None or (isinstance(x, float) and not math.isfinite(x)):
        return "–"
    return f"{x:.{digits}g}{'' if unit in ('', '1') else ' ' + unit}"


def _section(site: str, folder: Path, img: Callable[[bytes, str, str], str]) -> str:
    try:
        result = json.loads((folder / "diagnosis.json").read_text(encoding="utf-8"))
        h = headline(result)
    except (OSError, ValueError, KeyError, TypeError) as exc:
        return (f'<section id="diagnosis-{_e(site)}"><h2>Diagnosis: {_e(site)}</h2>'
                f'<p class="note">{_e(folder)}/diagnosis.json is unreadable ({_e(exc)}).'
                "</p></section>")
    magnitude = "; ".join(
        f"{name} = {_num(p['value'])} ± {_num(p['std'], 2, p['unit'])} ({p['meaning']})"
        for name, p in h["magnitude"].items()) or "–"
    shrink = _num(h["shrink_pct"], 3, "%")
    rows = [
        ("record", h["record"]),
        ("sim (baseline law, fitted on the calibration part)", h["baseline"]),
        ("verdict", f"{h['effect']} (confidence {_num(h['confidence'], 2)})"),
        ("magnitude", magnitude),
        ("withheld gap without → with it (force and displacement NRMS)",
         f"{_num(h['gap_before_pct'], 3, '%')} → {_num(h['gap_after_pct'], 3, '%')}"),
        ("shrink", shrink if h["effect"] not in _NOT_AN_EFFECT else f"– ({h['effect']})"),
        ("explanation", h["explanation"]),
    ]
    table = "".join(f'<tr><th>{_e(k)}</th><td data-key="{_e(k.split()[0])}">{_e(v)}</td></tr>'
                    for k, v in rows)
    candidates = "".join(
        f'<tr><td>{_e(c["name"])}</td><td class="n">{_num(c["gap_after"]["total_pct"], 3)}</td>'
        f'<td class="n">{_num(c["shrink_pct"], 3)}</td><td class="n">{_num(c["score"], 3)}'
        "</td></tr>" for c in [*result["effects"], *result["pairs"][:3]])
    parts = [
        f'<section id="diagnosis-{_e(site)}"><h2>Diagnosis: {_e(site)}</h2>',
        "<p>Where the test departs from its simulation: a law fitted on the first part of the "
        "record predicts the withheld rest; each candidate effect is added and refitted, and "
        "the one that shrinks the withheld gap most (less 2 % per parameter) wins "
        f"(<code>fresco-bridge diagnose</code>; files in <code>{_e(folder.name)}/</code>).</p>",
        f'<table class="diagnosis">{table}</table>',
    ]
    overlay = folder / OVERLAY
    if overlay.is_file():
        parts.append(img(overlay.read_bytes(), f"{site} diagnosis overlay",
                         "Measured hysteresis against the sim without the effect and with it "
                         "(fitted on the calibration part, predicting the whole record)."))
    parts.append("<table><tr><th>candidate</th><th>withheld gap after (%)</th>"
                 f"<th>shrink (%)</th><th>score</th></tr>{candidates}</table></section>")
    return "".join(parts)


def diagnosis_sections(run_dir: Path, img: Callable[[bytes, str, str], str]) -> list[str]:
    """One section per ``diagnosis-<site>/`` of the run directory (``img`` inlines a PNG)."""
    return [_section(folder.name[len(DIAGNOSIS_PREFIX):], folder, img)
            for folder in sorted(run_dir.glob(f"{DIAGNOSIS_PREFIX}*"))
            if (folder / "diagnosis.json").is_file()]
