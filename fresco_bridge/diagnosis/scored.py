"""A candidate's score on the withheld part, and the flags that say a number is not measured.

The gap of a prediction is the NRMS of measured − predicted on a part of the record, over the
*whole record's* RMS force and command, so a quiet part cannot inflate it; a candidate's shrink
is measured from the gap it is compared with (the baseline's, or the best baseline of the law
family it drives) and its score charges :data:`PARSIMONY_PCT` per parameter. A fitted effect
parameter at a bound or with a relative std above :data:`MAX_RELATIVE_STD` is flagged
(``verdict`` lowers the confidence for each).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace
from typing import Any

import numpy as np
import numpy.typing as npt

from .fit import Fit
from .load import Record
from .model import Param, baseline_report

__all__ = ["BOUND_TOLERANCE", "MAX_RELATIVE_STD", "PARSIMONY_PCT", "Scored",
           "at_bound", "effect_size", "evidence_samples", "finite", "gap", "information", "rms",
           "systematic_floor", "without_noise"]

FloatArray = npt.NDArray[np.float64]

PARSIMONY_PCT = 2.0
"""Score = shrink % − this per fitted parameter: the candidate table's ranking only; the
verdict (of one record and of ``--same-device``) is chosen by :func:`information`."""
GAP_ZERO_PCT = 1e-6
"""A withheld gap below this (NRMS %) is rounding noise: no shrink is defined against it."""
MAX_RELATIVE_STD = 0.5
"""A fitted effect parameter whose std exceeds this share of its value (of 5 % of its range
for a value nearer zero than that) is not measured by the record: flagged."""
BOUND_TOLERANCE = 1e-3
"""A parameter within this share of its range from a bound is at the bound: flagged (except a
zero lower bound, which says the part of the effect it measures is absent)."""


@dataclass
class Scored:
    """A candidate (or another law family's baseline) fitted and scored on the withheld part."""

    name: str
    effects: tuple[str, ...]
    params: list[Param]
    fit: Fit | None
    values: dict[str, float]
    std: dict[str, float]
    before: dict[str, float | None]
    after: dict[str, float | None]
    force: FloatArray | None = None
    disp: FloatArray | None = None
    compared_with: str | None = None
    """The baseline the shrink is measured from when it is not the diagnosis' own (a candidate
    on another law family is compared with the best baseline of that family)."""
    extra_law_params: int = 0
    """Law parameters a family alternative has beyond the baseline's (counted in its score)."""
    role: str = "candidate"
    """``candidate``; for another law family's baseline ``alternative`` or ``reference``."""
    size: float = math.inf
    """How far the candidate moves the baseline's prediction on the withheld part, NRMS % in
    the gap's units (:func:`effect_size`); inf when not measured (``sensor_noise``)."""

    @property
    def shrink(self) -> float:
        b, a = self.before["total_pct"], self.after["total_pct"]
        if b is None or a is None or not math.isfinite(a) or b < GAP_ZERO_PCT:
            return -math.inf  # undefined (JSON null, "–"): there was no gap to shrink
        return 100.0 * (1.0 - a / b)

    @property
    def score(self) -> float:
        return self.shrink - PARSIMONY_PCT * (len(self.params) + self.extra_law_params)

    @property
    def free(self) -> frozenset[str]:
        """The effect parameters (sensor noise's excepted) the record estimates: those not at a
        bound — at a bound the candidate takes the simpler form there (a rate law at its
        smallest exponent is Coulomb friction, a slip of zero is a rigid fixture)."""
        out = set()
        for p in self.params:
            value = self.values.get(p.name)
            if p.role == "noise" or value is None:
                continue
            if at_bound(value, p.lo, p.hi, "lower") or (
                    math.isfinite(p.hi) and at_bound(value, p.lo, p.hi, "upper")):
                continue
            out.add(p.name)
        return frozenset(out)

    @property
    def n_free(self) -> int:
        """Parameters the record estimates: :attr:`free`, and the law parameters another
        family has beyond the baseline's."""
        return len(self.free) + self.extra_law_params

    @property
    def flags(self) -> dict[str, str]:
        """Parameters the record does not measure: at a bound, or too uncertain (module doc)."""
        out: dict[str, str] = {}
        for p in self.params:
            value, std = self.values.get(p.name), self.std.get(p.name)
            if p.role == "noise" or value is None:
                continue
            span = p.hi - p.lo if math.isfinite(p.hi) else abs(value) or 1.0
            if p.lo != 0.0 and at_bound(value, p.lo, p.hi, "lower"):
                out[p.name] = f"at its lower bound {p.lo:.4g}"
            elif math.isfinite(p.hi) and at_bound(value, p.lo, p.hi, "upper"):
                out[p.name] = f"at its upper bound {p.hi:.4g}"
            elif p.lo == 0.0 and at_bound(value, p.lo, p.hi, "lower"):
                continue  # absent, not unsure
            elif std is None or not math.isfinite(std):
                out[p.name] = "no uncertainty estimate"
            else:
                relative = std / max(abs(value), 0.05 * span)
                if relative > MAX_RELATIVE_STD:
                    out[p.name] = (f"relative std {relative:.3g} above {MAX_RELATIVE_STD:g}")
        return out

    def as_dict(self, systematic: Scored | None = None) -> dict[str, Any]:
        """The JSON row; ``systematic``: this candidate scored without the white noise
        (:func:`without_noise`), whose gap, shrink and score the row carries beside the raw
        ones (a verdict on that basis quotes them)."""
        flags = self.flags
        return {
            "name": self.name,
            "params": {p.name: {"value": self.values.get(p.name), "std": self.std.get(p.name),
                                "unit": p.unit, "meaning": p.meaning,
                                "flag": flags.get(p.name)} for p in self.params},
            "n_params": len(self.params),
            "law_family": None if self.fit is None else self.fit.spec.law_kind,
            "compared_with": self.compared_with,
            "law": None if self.fit is None else baseline_report(self.fit.spec.law_kind,
                                                                 self.fit.values),
            "gap_before": self.before, "gap_after": self.after,
            "shrink_pct": finite(self.shrink), "score": finite(self.score),
            "systematic": None if systematic is None else {
                "gap_after_pct": finite(systematic.after["total_pct"]),
                "shrink_pct": finite(systematic.shrink), "score": finite(systematic.score)},
            "fit": None if self.fit is None else {
                "converged": self.fit.ok, "evaluations": self.fit.evaluations,
                "calibration_cost": self.fit.cost},
        }


def finite(x: float | None) -> float | None:
    return None if x is None or not math.isfinite(x) else float(x)


def rms(x: FloatArray) -> float:
    return float(np.sqrt(np.mean(x * x))) if x.size else math.nan


def gap(record: Record, force: FloatArray, disp: FloatArray | None, part: slice,
         noise: tuple[float, float] = (0.0, 0.0)) -> dict[str, float | None]:
    """NRMS gap in % per channel on ``part``, over the whole record's RMS force and command
    (a quiet part cannot inflate it); ``noise`` (std) is removed from the variance."""
    rf = (record.force - force)[part]
    var_f = max(float(np.mean(rf * rf)) - noise[0] ** 2, 0.0)
    g_f = 100.0 * math.sqrt(var_f) / (rms(record.force) or 1.0)
    g_d: float | None = None
    if record.meas_disp is not None and disp is not None:
        rd = (record.meas_disp - disp)[part]
        var_d = max(float(np.mean(rd * rd)) - noise[1] ** 2, 0.0)
        g_d = 100.0 * math.sqrt(var_d) / (rms(record.cmd) or 1.0)
    total = math.hypot(g_f, g_d or 0.0)
    if not math.isfinite(total):
        total = math.inf
    return {"force_pct": finite(g_f), "disp_pct": finite(g_d), "total_pct": total}


def effect_size(record: Record, s: Scored, base_force: FloatArray,
                base_disp: FloatArray | None, part: slice) -> float:
    """NRMS % (the gap's scales) of the candidate's prediction minus the baseline's on
    ``part``: an effect smaller than the floor is below what the user asked to hear about,
    however much of a small systematic gap it absorbs (a 0.4 % "offset" taking up a law's
    misfit)."""
    if s.force is None:
        return math.inf
    g_f = 100.0 * rms((s.force - base_force)[part]) / (rms(record.force) or 1.0)
    g_d = 0.0
    if s.disp is not None and base_disp is not None:
        g_d = 100.0 * rms((s.disp - base_disp)[part]) / (rms(record.cmd) or 1.0)
    return math.hypot(g_f, g_d)


def without_noise(s: Scored, record: Record, part: slice, noise: tuple[float, float],
                  before: dict[str, float | None],
                  references: dict[str, dict[str, float | None]]) -> Scored:
    """``s`` scored on the *systematic* gap: its withheld gap with the white noise (std
    estimated on the calibration residual) removed from the variance, measured from
    ``before`` (the baseline's systematic gap) or, for a candidate compared with another
    family, from that family's systematic gap in ``references`` (by name). White measurement
    noise is in every record and no systematic candidate can predict it: on the raw gap it
    dilutes every real effect's shrink, while the noise candidate claims all of it."""
    if s.force is None:
        return s
    base = before
    if s.compared_with is not None:
        base = references.get(s.compared_with.removesuffix(" baseline"), before)
    return replace(s, before=base, after=gap(record, s.force, s.disp, part, noise))


NOISE_ESTIMATE_SPREAD = 2.7
"""Variance of the white-noise estimate (MAD of the differences) relative to a sample
variance's, for Gaussian noise (the MAD's efficiency is 37 %)."""
NOISE_SIGMAS = 2.0
"""How many standard errors of (withheld variance − estimated noise variance) a systematic gap
must exceed to be told from white noise."""


def systematic_floor(floor: float, noise_only: float, n_cal: int, n_withheld: int) -> float:
    """The smallest systematic gap (white noise removed) the record resolves: the noise floor,
    or :data:`NOISE_SIGMAS` standard errors of a variance difference whose two terms are each
    estimated from a finite sample (withheld: 2/N relative variance; calibration: the MAD
    estimate's, :data:`NOISE_ESTIMATE_SPREAD` times that), whichever is larger."""
    if noise_only <= 0.0 or n_cal < 2 or n_withheld < 2:
        return floor
    relative = math.sqrt(2.0 / n_withheld + 2.0 * NOISE_ESTIMATE_SPREAD / n_cal)
    return max(floor, math.sqrt(NOISE_SIGMAS * relative) * noise_only)


def at_bound(value: float, lo: float, hi: float, side: str) -> bool:
    """``value`` within :data:`BOUND_TOLERANCE` of its range (of itself, for an unbounded
    range) from its ``side`` (``lower`` or ``upper``) bound: the one test of "at a bound"."""
    span = hi - lo if math.isfinite(hi) else abs(value) or 1.0
    tol = BOUND_TOLERANCE * span
    return value <= lo + tol if side == "lower" else value >= hi - tol


def evidence_samples(residual: FloatArray) -> float:
    """The effective number of independent samples in ``residual`` (the baseline's withheld
    residual of one channel): n / τ, τ = 1 + 2 Σ ρ_k summed while the autocorrelation ρ_k
    stays positive (Geyer's initial positive sequence). A misfit that follows the loop is
    correlated over a part of a cycle: its evidence is a few samples a cycle, not every
    sample; white noise is every sample."""
    r = np.asarray(residual, dtype=float)
    r = r - float(np.mean(r)) if r.size else r
    n = r.size
    if n < 4 or not np.any(r):
        return float(max(n, 1))
    spectrum = np.fft.rfft(r, 2 * n)
    acf = np.fft.irfft(spectrum * np.conj(spectrum))[:n]
    acf = acf / acf[0]
    negative = np.nonzero(acf[1:] <= 0.0)[0]
    m = int(negative[0]) + 1 if negative.size else n
    tau = 1.0 + 2.0 * float(np.sum(acf[1:m]))
    return n / max(tau, 1.0)


def information(gaps: dict[str, float | None], n_eff: tuple[float, float | None],
                k: int) -> float:
    """The Bayesian information criterion of a prediction on the withheld part, up to a
    constant shared by every candidate: Σ_channel n_eff · ln(gap²) + k · ln(Σ n_eff) (a
    Gaussian likelihood with its variance the channel's mean squared residual; the gap is that
    residual's RMS over a fixed scale)."""
    total = 0.0
    samples = 0.0
    for key, n in (("force_pct", n_eff[0]), ("disp_pct", n_eff[1])):
        g = gaps.get(key)
        if n is None or g is None or not math.isfinite(g):
            continue
        total += n * math.log(max(g, GAP_ZERO_PCT) ** 2)
        samples += n
    return total + k * math.log(max(samples, 2.0))
