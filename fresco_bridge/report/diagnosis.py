"""The report's diagnosis section: what ``diagnose RUN --site S --report RUN/diagnosis-S`` wrote.

A run directory holds a site's diagnosis in ``diagnosis-<site>/`` (``diagnosis.json`` and the
plots of ``fresco_bridge.diagnosis.outputs``), written by ``diagnosis.rundir`` (the demo,
``report --diagnose SITE``) or by a user's ``diagnose --report``. The report reads it rather
than diagnosing again (a diagnosis costs seconds to minutes), and imports nothing of the
diagnosis, which draws with this package's figures.
"""

from __future__ import annotations

import html
import json
from collections.abc import Callable
from pathlib import Path
from typing import Any, Final

from ..numbers import fmt, pct

__all__ = ["BASIS_WORDS", "DIAGNOSIS_PREFIX", "confidence_text", "diagnosis_sections", "headline",
           "on_basis"]

DIAGNOSIS_PREFIX: Final = "diagnosis-"
"""``RUN/diagnosis-<site>/``: where a site's diagnosis lives in its run directory."""
OVERLAY: Final = "hysteresis_overlay.png"
_LAW_SHAPE: Final = frozenset({"k0", "fy", "alpha", "n", "bg_sum", "beta_share", "R0", "cR1",
                               "cR2"})
"""A winner's parameters that shape the law rather than size the effect (its magnitude)."""
_NOT_AN_EFFECT: Final = frozenset({"none", "unexplained", "baseline_misfit"})


BASIS_WORDS: Final = {"raw": "as measured", "systematic": "white noise removed"}
"""What a verdict's ``gap_basis`` means, in the words every table and figure heads it with."""


def on_basis(row: dict[str, Any], basis: str) -> tuple[float | None, float | None,
                                                       float | None]:
    """(withheld gap after, shrink %, score) of a candidate row on the verdict's ``gap_basis``:
    the one place the summary, the report and the figure take a candidate's figures from, so
    they quote what the verdict quotes (a verdict scored without the white noise shows its
    candidates without it too)."""
    sys_row = row.get("systematic") if basis == "systematic" else None
    if sys_row is not None:
        return sys_row["gap_after_pct"], sys_row["shrink_pct"], sys_row["score"]
    return row["gap_after"]["total_pct"], row["shrink_pct"], row["score"]


def confidence_text(verdict: dict[str, Any]) -> str:
    """``0.08 (low: the record does not separate it from friction)``: the number and its words
    (``verdict.confidence_words``, written by the diagnosis)."""
    words = verdict.get("confidence_words")
    return f"{verdict['confidence']:.2f}" + ("" if not words else f" ({words})")


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
        "named": " or ".join(str(st["effect"]) for st in verdict.get("stories") or [])
        or verdict["effect"],
        "confidence": verdict["confidence"],
        "confidence_text": confidence_text(verdict),
        "gap_basis": verdict.get("gap_basis", "raw"),
        "gap_before_pct": verdict["gap_before_pct"],
        "gap_after_pct": verdict["gap_after_pct"],
        "shrink_pct": verdict["shrink_pct"],
        "explanation": verdict["explanation"],
        "magnitude": magnitude,
    }


def _e(v: object) -> str:
    return html.escape(str(v), quote=True)


def _gap_row(h: dict[str, Any], floor_pct: float | None) -> str:
    """The withheld gap without → with the effect; one number when nothing was added, and below
    the noise floor said as such (a gap of round-off is no gap: issue 27's ``3.26e-12 %``)."""
    before, after = h["gap_before_pct"], h["gap_after_pct"]
    if floor_pct is not None and before is not None and before < floor_pct:
        return f"{pct(before)}: below the noise floor ({fmt(floor_pct)} %), nothing to explain"
    if h["effect"] in _NOT_AN_EFFECT:
        return f"{pct(before)} → {pct(after)} with the best candidate ({h['effect']})"
    return f"{pct(before)} → {pct(after)}"


def _section(site: str, folder: Path, img: Callable[[bytes, str, str], str]) -> str:
    try:
        result = json.loads((folder / "diagnosis.json").read_text(encoding="utf-8"))
        h = headline(result)
    except (OSError, ValueError, KeyError, TypeError) as exc:
        return (f'<section id="diagnosis-{_e(site)}"><h2>Diagnosis: {_e(site)}</h2>'
                f'<p class="note">{_e(folder)}/diagnosis.json is unreadable ({_e(exc)}).'
                "</p></section>")
    magnitude = "; ".join(
        f"{name} = {fmt(p['value'], digits=3)} ± "
        f"{fmt(p['std'], '' if p['unit'] == '1' else p['unit'], digits=2)} ({p['meaning']})"
        for name, p in h["magnitude"].items()) or "–"
    floor = result.get("noise_floor", {}).get("floor_pct")
    below_floor = floor is not None and (h["gap_before_pct"] or 0.0) < floor
    rows = [
        ("record", h["record"]),
        ("sim (baseline law, fitted on the calibration part)", h["baseline"]),
        ("verdict", f"{h['named']} (confidence {h['confidence_text']})"),
        ("magnitude", magnitude),
        ("withheld gap without → with it (force and displacement NRMS, "
         f"{BASIS_WORDS.get(h['gap_basis'], h['gap_basis'])})", _gap_row(h, floor)),
        ("shrink", pct(h["shrink_pct"], 1) if h["effect"] not in _NOT_AN_EFFECT
         else f"– ({h['effect']}: no effect added)"),
        ("explanation", h["explanation"]),
    ]
    gap = result.get("interface_gap")
    if gap is not None:  # a run with displacement correction (diagnosis/interface_gap.py)
        other = gap["against"]
        rows.append((f"interface gap, target vs measured ({gap['run']['channel']} channel, NRMS)",
                     pct(gap["run"]["nrms_pct"]) + ("" if other is None else
                     f" (uncorrected run {pct(other['nrms_pct'])}: "
                     f"{pct(gap['closed_pct'])} closed)")))
    table = "".join(f'<tr><th>{_e(k)}</th><td data-key="{_e(k.split()[0])}">{_e(v)}</td></tr>'
                    for k, v in rows)
    rows_on_basis = [(c["name"], *on_basis(c, h["gap_basis"]))
                     for c in [*result["effects"], *result["pairs"][:3]]]
    candidates = "".join(
        f'<tr><td>{_e(name)}</td><td class="n">{pct(after)}</td>'
        f'<td class="n">{"–" if below_floor else pct(shrink, 1)}</td>'
        f'<td class="n">{"–" if below_floor else fmt(score, digits=3)}</td></tr>'
        for name, after, shrink, score in rows_on_basis)
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
                         "Top: the measured hysteresis (grey) against the sim without the "
                         "effect (left) and with it (right), both fitted on the calibration part "
                         "and predicting the whole record. Bottom: the force residual in time, "
                         "measured − sim, for each model; the shaded part is the withheld one "
                         "the gaps are scored on."))
    parts.append("<table><tr><th>candidate effect</th><th>withheld gap after "
                 f"({_e(BASIS_WORDS.get(h['gap_basis'], h['gap_basis']))})</th>"
                 "<th>shrink</th><th>score (shrink − 2 % per parameter)</th></tr>"
                 f"{candidates}</table></section>")
    return "".join(parts)


def diagnosis_sections(run_dir: Path, img: Callable[[bytes, str, str], str]) -> list[str]:
    """One section per ``diagnosis-<site>/`` of the run directory (``img`` inlines a PNG)."""
    return [_section(folder.name[len(DIAGNOSIS_PREFIX):], folder, img)
            for folder in sorted(run_dir.glob(f"{DIAGNOSIS_PREFIX}*"))
            if (folder / "diagnosis.json").is_file()]
