"""The interface layer's gap of a run — measured displacement against the integrator's target —
and how much of it a displacement correction closed against the uncorrected run of the same
record (``diagnose RUN --site S --against OTHER``).

The diagnosis' own interface figures (``localization.layers.interface``) compare the
*command* with the measurement; on a corrected run the command is the last corrected one, so
they show what the controller did, not what the integrator got. The integrator assumes the
specimen sits at its target: the gap it sees is target vs measured, on the channel the
correction compared (``element_history.read_interface``). The two runs are compared only on
the same channel; a different one is said in ``notes`` (an uncorrected run measures the
external channel only if it has ``[sites.correction]``: docs/diagnosis.md says how).
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np

from .. import indicators as ind
from ..element_history import HistoryInputError, InterfaceHistory, read_interface
from ..numbers import fmt, pct
from .load import DiagnosisInputError

__all__ = ["interface_gap", "interface_lines", "run_figures"]


def run_figures(h: InterfaceHistory) -> dict[str, Any]:
    """One run's interface figures (JSON-ready): NRMS and peak |target − measured|, and its
    corrections when it has correction lines."""
    error = np.abs(h.measured - h.target)
    try:
        nrms = 100.0 * ind.nrms_error(h.target, h.measured)
    except ind.IndicatorError:
        nrms = None
    out: dict[str, Any] = {
        "source": h.source, "steps": int(h.step.size), "channel": h.channel,
        "nrms_pct": nrms, "peak_error_mm": float(np.max(error)) if error.size else None,
        "correction_lines": h.corrections is not None,
        "corrections_median": None, "corrections_max": None, "not_converged": None,
        "tolerance_mm": h.tolerance,
    }
    if h.corrections is not None and h.corrections.size:
        out.update(corrections_median=float(np.median(h.corrections)),
                   corrections_max=int(np.max(h.corrections)),
                   not_converged=sum(o != "converged" for o in h.outcomes))
    return out


def _corrected(h: InterfaceHistory) -> bool:
    return h.corrections is not None and bool(np.any(h.corrections > 0))


def _read(path: Path, site: str | None) -> InterfaceHistory:
    try:
        return read_interface(path, site=site)
    except HistoryInputError as exc:
        raise DiagnosisInputError(str(exc)) from None


def interface_gap(path: Path, site: str | None,
                  against: Path | None = None) -> dict[str, Any] | None:
    """The ``interface_gap`` section of a diagnosis: ``run`` (this run's figures), ``against``
    (the other run's, or None), ``closed_pct`` = 100·(1 − this NRMS / the other's) (None without
    ``against``), ``notes``. None for a run without correction lines and no ``against``: nothing
    beyond the diagnosis' own interface figures to say."""
    this = _read(path, site)
    if this.corrections is None and against is None:
        return None
    other = None if against is None else _read(against, site)
    notes = [*this.notes, *([] if other is None else other.notes)]
    closed = None
    if other is not None:
        if other.channel != this.channel:
            notes.append(
                f"the runs measured different channels ({this.channel} here, {other.channel} "
                f"in {against}): the fraction closed compares different displacements; give "
                "the uncorrected run [sites.correction] with the same measured channel and a "
                "tolerance above any error (it then records without correcting)")
        if not _corrected(this) and _corrected(other):
            notes.append(f"this run corrected nothing and {against} did: give the corrected "
                         "run first and the uncorrected one to --against")
        if other.step.size != this.step.size:
            notes.append(f"the runs differ in length ({this.step.size} and {other.step.size} "
                         "committed steps): not the same record?")
        mine, theirs = run_figures(this)["nrms_pct"], run_figures(other)["nrms_pct"]
        if mine is not None and theirs:
            closed = 100.0 * (1.0 - mine / theirs)
    return {"run": run_figures(this), "against": None if other is None else run_figures(other),
            "closed_pct": closed, "notes": notes}


def interface_lines(gap: dict[str, Any]) -> list[str]:
    """The summary's lines for an ``interface_gap`` section."""
    def one(r: dict[str, Any]) -> str:
        corr = ("" if not r["correction_lines"] or r["corrections_median"] is None else
                f"; corrections a step median {fmt(r['corrections_median'])} max "
                f"{r['corrections_max']}, {r['not_converged']} not converged")
        return (f"NRMS {pct(r['nrms_pct'])}, peak {fmt(r['peak_error_mm'], 'mm')} over "
                f"{r['steps']} steps{corr}")

    run, other = gap["run"], gap["against"]
    lines = [f"interface target vs measured ({run['channel']} channel): this run {one(run)}"]
    if other is not None:
        lines.append(f"          against {other['source']}: {one(other)}")
        lines.append(f"          gap closed {pct(gap['closed_pct'])}")
    lines.extend(f"note      {n}" for n in gap["notes"])
    return lines
