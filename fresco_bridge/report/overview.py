"""The report's first screen: what a test engineer reads before anything else.

What was tested (the sites, their controllers or updaters, the committed steps and test time),
the headline figures (each site's tracking error and holds; the served twin against the
calibrated law when the run has those scores, the demo's ``summary.json``), each site's
diagnosis verdict in words with its confidence explained (``RUN/diagnosis-<site>/``), and what
to do next. Everything is read from the run directory; nothing is computed again. Each figure
is a ``<span data-key=… data-value=…>`` holding the exact number beside the rounded text, and
the same figures go into the report's embedded JSON (``overview``), so a test or a pipeline
compares them with the run's own files.
"""

from __future__ import annotations

import html
import json
from pathlib import Path
from typing import Any, Final

from ..numbers import fmt, pct
from ..progress import command_name
from ..runs import Run, SiteSummary
from .correction import correction_sentence
from .diagnosis import DIAGNOSIS_PREFIX, headline

__all__ = ["SCORES_FILE", "overview_section"]

SCORES_FILE: Final = "summary.json"
"""A run's scores written beside its record (the demo's: the twin against the calibrated law)."""
_NOT_AN_EFFECT: Final = frozenset({"none", "unexplained", "baseline_misfit"})


def _e(v: object) -> str:
    return html.escape(str(v), quote=True)


def _fig(key: str, value: float | int | None, text: str) -> str:
    """A headline figure: the exact value in ``data-value``, the rounded one shown."""
    exact = "" if value is None else repr(value)
    return f'<span class="fig" data-key="{_e(key)}" data-value="{_e(exact)}">{_e(text)}</span>'


def _read_json(path: Path) -> dict[str, Any] | None:
    try:
        data = json.loads(path.read_text(encoding="utf-8"))
    except (OSError, ValueError):
        return None
    return data if isinstance(data, dict) else None


def _controller_words(cfg: dict[str, Any]) -> str:
    ctl = cfg.get("controller", {})
    if not isinstance(ctl, dict):
        return "its controller"
    kind = str(ctl.get("kind", "sim"))
    if kind == "rig":
        return f"the simulated rig '{ctl.get('preset', '?')}'"
    if kind == "sim":
        return f"an in-process {ctl.get('model', 'simulated')} specimen"
    return f"a {kind} controller"


def _tested(run: Run, summaries: list[SiteSummary], twins: dict[str, str]) -> str:
    configs = run.site_configs()
    parts = []
    for s in summaries:
        cfg = configs.get(s.site, {})
        what = (f"updatable, the twin of {twins[s.site]} learned online with "
                f"{cfg.get('updater', '?')}" if s.site in twins else _controller_words(cfg))
        end = max((d.time_end for d in s.sessions_detail), default=0.0)
        parts.append(f"<b>{_e(s.site)}</b> ({_e(what)}): {s.steps} committed step(s) in "
                     f"{s.sessions} session(s), {_e(fmt(end, 's', 3))} of test time")
    return "; ".join(parts) or "no site committed a step"


def _tracking(s: SiteSummary) -> tuple[str, dict[str, Any]]:
    worst = max(s.sessions_detail, key=lambda d: d.max_tracking_error)
    figures = {"max_tracking_error_mm": worst.max_tracking_error, "nrms": worst.nrms}
    nrms = "–" if worst.nrms is None else fmt(worst.nrms, digits=3)
    text = (f"{s.site}: up to {_fig(f'tracking.{s.site}.max_tracking_error_mm', worst.max_tracking_error, fmt(worst.max_tracking_error, 'mm', 3))} "  # noqa: E501
            f"(NRMS {_fig(f'tracking.{s.site}.nrms', worst.nrms, nrms)})")
    return text, figures


def _twin_scores(scores: dict[str, Any]) -> tuple[str, dict[str, Any]]:
    tw = scores["twin"]
    served, fixed = tw["updated"]["rmseth_kN"], tw["calibrated_bilinear"]["rmseth_kN"]
    cut = tw["rmseth_reduction_pct"]
    text = (f"the twin served by {_e(tw['updater'])}: RMS error "
            f"{_fig('twin.updated.rmseth_kN', served, fmt(served, 'kN', 2))} against the "
            "tested damper's true law, the Bilinear calibrated on the characterisation "
            f"{_fig('twin.calibrated_bilinear.rmseth_kN', fixed, fmt(fixed, 'kN', 2))}: "
            f"updating cuts the error by {_fig('twin.rmseth_reduction_pct', cut, pct(cut, 0))}")
    return text, {"updated_rmseth_kN": served, "calibrated_rmseth_kN": fixed,
                  "rmseth_reduction_pct": cut}


def _confidence_words(verdict: dict[str, Any]) -> str:
    """The confidence in words: the diagnosis' own (``confidence_words``) when it wrote them,
    else what its verdict says of the runner-up and of the parameters the record leaves
    unmeasured."""
    words = verdict.get("confidence_words")
    if words:
        return str(words)
    reasons = []
    if verdict.get("not_separated_from"):  # the diagnosis names it only below its low mark
        reasons.append(f"low: the record does not separate it from "
                       f"{verdict['not_separated_from']}")
    flags = verdict.get("flags") or {}
    if flags:
        reasons.append(f"the record does not measure {', '.join(flags)} well")
    return "; ".join(reasons) or "clear of its runner-up"


def _diagnosis(site: str, folder: Path) -> tuple[str, dict[str, Any], list[str]] | None:
    result = _read_json(folder / "diagnosis.json")
    if result is None:
        return None
    try:
        h, verdict = headline(result), result["verdict"]
    except (KeyError, TypeError, StopIteration):
        return None
    conf = float(h["confidence"])
    confidence = (f"confidence {_fig(f'diagnosis.{site}.confidence', conf, f'{conf:.2f}')} "
                  f"({_e(_confidence_words(verdict))})")
    figures = {"effect": h["effect"], "confidence": conf, "shrink_pct": h["shrink_pct"],
               "gap_before_pct": h["gap_before_pct"], "gap_after_pct": h["gap_after_pct"]}
    todo = []
    if h["effect"] in _NOT_AN_EFFECT:
        text = f"{site}: {_e(h['effect'])}: {_e(h['explanation'])} ({confidence})"
        if h["effect"] != "none":
            todo.append(f"Site {_e(site)}: the diagnosis finds no single effect that explains "
                        "the gap to its simulation; read its section before trusting the sim.")
        return text, figures, todo
    before, after = h["gap_before_pct"], h["gap_after_pct"]
    text = (f"{site}: the simulation ({_e(h['baseline'])}) misses <b>{_e(h['effect'])}</b>: "
            "adding it shrinks the withheld gap from "
            f"{_fig(f'diagnosis.{site}.gap_before_pct', before, pct(before, 1))} to "
            f"{_fig(f'diagnosis.{site}.gap_after_pct', after, pct(after, 1))}; {confidence}")
    todo.append(f"Site {_e(site)}: add {_e(h['effect'])} to the specimen's numerical model "
                "(its magnitude is in the diagnosis section)" + (
                    f", but first separate it from {_e(verdict['not_separated_from'])}: a "
                    "longer record or a test at larger amplitudes tells them apart"
                    if verdict.get("not_separated_from") else "") + ".")
    return text, figures, todo


def overview_section(run: Run, summaries: list[SiteSummary],
                     corrections: dict[str, dict[str, Any]] | None = None,
                     ) -> tuple[str, dict[str, Any]]:
    """The ``overview`` section and its figures (for the report's embedded JSON);
    ``corrections``: the corrected sites' figures (``report.correction.correction_data``)."""
    twins = run.sources()
    cmd, where = command_name(), run.directory
    scores = _read_json(run.directory / SCORES_FILE) or {}
    tested = _tested(run, summaries, twins)
    if "record" in scores and "pga_m_s2" in scores:
        tested = (f"under the ground motion {_e(scores['record'])} (PGA "
                  f"{_e(fmt(scores['pga_m_s2'], 'm/s²', 3))}): {tested}")
    rows: list[tuple[str, str]] = [("tested", tested)]
    data: dict[str, Any] = {"tracking": {}, "holds": {}, "diagnosis": {}}
    notes = "".join(f'<p class="note">{_e(n)}</p>' for n in run.notes)
    todo: list[str] = []
    measured = [s for s in summaries if s.site not in twins and s.sessions_detail]
    tracking = []
    for s in measured:
        text, figures = _tracking(s)
        tracking.append(text)
        data["tracking"][s.site] = figures
    if tracking:
        rows.append(("tracking error (measured − command)", "; ".join(tracking)))
    holds = []
    for s in summaries:
        data["holds"][s.site] = s.holds
        holds.append(f"{_e(s.site)} {_fig(f'holds.{s.site}', s.holds, str(s.holds))}"
                     + (f" ({s.limit_events} limit event(s))" if s.limit_events else ""))
        if s.holds:
            todo.append(f"Site {_e(s.site)} held {s.holds} time(s): read why in "
                        '<a href="#events">Events</a> before the next test.')
    rows.append(("holds", ", ".join(holds) or "none"))
    if corrections:
        data["correction"] = {site: {k: v for k, v in d.items()
                                     if k not in ("steps", "corrections", "residual_mm")}
                              for site, d in corrections.items()}
        rows.append(("displacement correction", "; ".join(
            f'<a href="#correction-{_e(site)}">{_e(correction_sentence(site, d))}</a>'
            for site, d in corrections.items())))
        todo.extend(f"Site {_e(site)}: {d['not_converged']} trial(s) ended outside the "
                    "correction's tolerance: read which in its correction section."
                    for site, d in corrections.items() if d["not_converged"])
    if isinstance(scores.get("twin"), dict):
        text, data["twin"] = _twin_scores(scores)
        rows.append(("twin vs calibrated law", text))
    diagnosed = set()
    for folder in sorted(run.directory.glob(f"{DIAGNOSIS_PREFIX}*")):
        site = folder.name[len(DIAGNOSIS_PREFIX):]
        found = _diagnosis(site, folder)
        if found is None:
            continue
        text, data["diagnosis"][site], advice = found
        diagnosed.add(site)
        rows.append(("diagnosis", text))
        todo.extend(advice)
    for s in measured:
        if s.site not in diagnosed:
            todo.append(f"Site {_e(s.site)} is not diagnosed: <code>{_e(cmd)} report "
                        f"{_e(where)} --diagnose {_e(s.site)}</code> finds where the test "
                        "departs from its simulation.")
    todo.append(f"The numbers of every session: <code>{_e(cmd)} runs show {_e(where)}</code>; "
                f"the committed steps as CSV: <code>{_e(cmd)} runs export {_e(where)}</code>.")
    table = "".join(f'<tr><th>{_e(k)}</th><td data-key="overview.{_e(k.split()[0])}">{v}</td>'
                    "</tr>" for k, v in rows)
    items = "".join(f"<li>{t}</li>" for t in todo)
    section = (f'<section id="overview"><h2>At a glance</h2>{notes}<table class="overview">'
               f"{table}</table><h3>What to do next</h3><ul>{items}</ul></section>")
    return section, data
