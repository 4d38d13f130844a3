"""The report's displacement correction: per site with ``[sites.correction]``, the corrections
its trials needed and the residual error left, from the record's correction lines (the same
lines ``export --corrections`` writes, summed up as ``runs show`` does: ``runs.correction_stats``).

The figure is ``figures.correction``; the numbers go into the report's embedded JSON
(``correction``: per site the per-trial ``steps``, ``corrections``, ``residual``, and the
summary figures) and a sentence into "At a glance".
"""

from __future__ import annotations

import html
from collections.abc import Callable
from typing import Any

import numpy as np

from ..numbers import fmt
from ..runs import CorrectionStats, Run, correction_stats

__all__ = ["correction_data", "correction_section", "correction_sentence"]


def _e(v: object) -> str:
    return html.escape(str(v), quote=True)


def _settings(run: Run, site: str) -> tuple[float | None, int | None]:
    """(tolerance of control point 1, max_iterations) from the config snapshot, when known."""
    table = run.site_configs().get(site, {}).get("correction")
    if not isinstance(table, dict):
        return None, None
    tol = table.get("tolerance")
    if isinstance(tol, list):
        tol = tol[0] if tol else None
    tolerance = float(tol) if isinstance(tol, int | float) else None
    return tolerance, int(table.get("max_iterations", 5))


def _stats(run: Run, site: str) -> CorrectionStats | None:
    lines = [c for c in run.corrections if c.site == site]
    return correction_stats(lines) if lines else None


def correction_data(run: Run) -> dict[str, dict[str, Any]]:
    """Per corrected site, the figures the report shows (its embedded JSON's ``correction``)."""
    out: dict[str, dict[str, Any]] = {}
    for site in run.sites:
        st = _stats(run, site)
        if st is None:
            continue
        tolerance, max_iterations = _settings(run, site)
        out[site] = {
            "trials": len(st.steps), "median_corrections": st.median,
            "max_corrections": max(st.corrections), "not_converged": st.not_converged,
            "max_residual_mm": max(st.residual), "tolerance_mm": tolerance,
            "max_iterations": max_iterations, "steps": st.steps,
            "corrections": st.corrections, "residual_mm": st.residual,
        }
    return out


def correction_sentence(site: str, d: dict[str, Any]) -> str:
    """The overview's sentence for one corrected site."""
    tol = "" if d["tolerance_mm"] is None else f" (tolerance {fmt(d['tolerance_mm'], 'mm')})"
    most = "" if d["max_iterations"] is None else f" of max_iterations {d['max_iterations']}"
    return (f"{site}: {d['trials']} trial(s) corrected, median {d['median_corrections']} and "
            f"max {d['max_corrections']} correction(s){most}; {d['not_converged']} not "
            f"converged; largest residual {fmt(d['max_residual_mm'], 'mm')}{tol}")


def correction_section(run: Run, site: str, data: dict[str, Any],
                       img: Callable[[bytes, str, str], str]) -> str:
    """The ``correction-<site>`` section: the sentence and the figure."""
    from . import figures

    st = _stats(run, site)
    assert st is not None  # data holds only corrected sites
    png = figures.correction(site, np.array(st.steps, dtype=float), np.array(st.corrections),
                             np.array(st.residual), np.array(st.converged),
                             data["tolerance_mm"], data["max_iterations"])
    return "".join([
        f'<section id="correction-{_e(site)}"><h2>Displacement correction: {_e(site)}</h2>',
        f"<p>{_e(correction_sentence(site, data))}. Every command and measurement: "
        "<code>export RUN --corrections</code>.</p>",
        img(png, f"{site} displacement correction",
            "Left: how many corrected commands each trial needed after the target's own "
            "(the dotted line: half of max_iterations, past which the bridge warns). Right: "
            "per step, the residual |target − measured| left after the last command, on the "
            "channel the correction compares; the dashed line is the tolerance, crosses mark "
            "trials that did not converge."),
        "</section>",
    ])
