"""The simulation of a test and its candidate augmentations: baseline law + one or two effects.

The baseline "sim" is a hysteresis law of ``sim_actuator.models`` driven by the *commanded*
displacement. Each candidate effect adds a few parameters where the physics puts them, in the
order of the load path of ``sim_actuator`` (the simulated lab the bench generates with)::

    command c -> [actuator: undershoot u, amplitude a, delay tau] -> piston x  (the LVDT reads x)
    x -> [pin gap g] -> specimen law (Bouc-Wen, + pinching, + degradation) -> connection force
    force + fixture friction Fc (behind a spring, tanh(v/v0)) + rate law c_v*sign(v)|v|^a
      -> load cell -> [sensor bias, noise]

so every candidate predicts both channels: the measured displacement and the measured force.
``sensor_noise`` predicts nothing new: it claims the white part of the gap (see ``fit``).
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import Literal

import numpy as np
import numpy.typing as npt

from sim_actuator.models.paths import (
    BWBN_PARAMETERS,
    LAW_BILINEAR,
    LAW_BWBN,
    LAW_ISOTROPIC_BILINEAR,
    LAW_MENEGOTTO_PINTO,
    drive,
)

from .load import DiagnosisInputError, Record
from .names import AUTO, BASELINES, EFFECT_NAMES

__all__ = [
    "AUTO",
    "BASELINES",
    "EFFECT_NAMES",
    "Context",
    "Param",
    "Spec",
    "law_parameters",
]

FloatArray = npt.NDArray[np.float64]
Role = Literal["law", "path", "gap", "out", "noise"]

DZ_MAX = 0.2
"""RK4 resolution of the law drives while fitting: the law's force error is ~3e-6 of fy
(``sim_actuator/models/paths.py`` at this setting, measured), far below any sensor noise."""


@dataclass(frozen=True, slots=True)
class Param:
    """A fitted parameter: bounds and start relative to the record's scales (see Context)."""

    name: str
    role: Role
    unit: str
    lo: float
    hi: float
    init: float
    meaning: str


@dataclass(frozen=True, slots=True)
class Context:
    """The record and the scales that bound every parameter."""

    record: Record
    d_peak: float
    """max |cmd|, mm."""
    f_peak: float
    """max |force|, kN."""
    k_est: float
    """Initial stiffness estimated from the first loading, kN/mm."""
    v_rms: float
    """RMS command velocity, mm/s."""
    dt: float
    """Median sample interval, s."""
    duration: float

    @classmethod
    def of(cls, record: Record) -> Context:
        c, f, t = record.cmd, record.force, record.time
        d_peak = float(np.max(np.abs(c)))
        f_peak = float(np.max(np.abs(f)))
        if f_peak == 0.0:
            raise DiagnosisInputError(f"{record.source}: meas_force is zero throughout")
        dt = float(np.median(np.diff(t)))
        v = np.diff(c) / np.diff(t)
        return cls(record, d_peak, f_peak, _initial_stiffness(c, f, d_peak, f_peak),
                   float(np.sqrt(np.mean(v * v))) or 1.0, dt, float(t[-1] - t[0]))


def _initial_stiffness(c: FloatArray, f: FloatArray, d_peak: float, f_peak: float) -> float:
    """The elastic (unloading) stiffness: the 90th percentile of the step slopes dF/dc.

    Unloading branches of every law here start at the initial stiffness, and they are a good
    share of any cyclic record; friction jumps and gaps are too rare to move the percentile.
    """
    dc, df = np.diff(c), np.diff(f)
    moving = np.abs(dc) > 1e-3 * d_peak
    slopes = df[moving] / dc[moving]
    k = float(np.percentile(slopes, 90)) if slopes.size >= 10 else 0.0
    return k if k > 0.0 and math.isfinite(k) else 3.0 * f_peak / d_peak


def law_parameters(ctx: Context) -> dict[str, tuple[Param, ...]]:
    """Baseline law parameters per baseline kind, bounded by the record's scales."""
    k, fp = ctx.k_est, ctx.f_peak
    stiff = Param("k0", "law", "kN/mm", k / 30.0, k * 30.0, k, "initial stiffness")
    yield_ = Param("fy", "law", "kN", 0.02 * fp, 3.0 * fp, 0.7 * fp, "yield force scale")
    alpha = Param("alpha", "law", "1", 0.0, 0.8, 0.05, "post-yield stiffness ratio")
    shape = (
        Param("n", "law", "1", 1.0, 10.0, 2.0, "sharpness of the elastic-plastic transition"),
        Param("bg_sum", "law", "1", 0.1, 5.0, 1.0, "beta + gamma (sets z_u with A = 1)"),
        Param("beta_share", "law", "1", 0.02, 3.0, 0.5, "beta / (beta + gamma)"),
    )
    steel = (
        Param("R0", "law", "1", 1.5, 40.0, 15.0,
              "sharpness of the virgin elastic-plastic transition (Steel02 R0)"),
        Param("cR1", "law", "1", 0.0, 0.99, 0.925,
              "softening of the transition with the plastic excursion (Bauschinger, cR1)"),
        Param("cR2", "law", "1", 0.005, 1.0, 0.15, "excursion scale of that softening (cR2)"),
    )
    isotropic = (
        Param("a1", "law", "1", 0.0, 0.5, 0.02,
              "isotropic growth of the yield force, both signs (Steel02 a1 = a3; a2 = a4 = 1)"),
    )
    saturating = (
        Param("q_iso", "law", "1", 0.0, 3.0, 0.2,
              "saturated growth of the yield force, fraction of fy"),
        Param("p_sat", "law", "1", 0.5, 500.0, 10.0,
              "accumulated plastic displacement (yield displacements) for 63 % of it"),
    )
    return {
        "bilinear": (stiff, yield_, alpha),
        "bouc-wen": (stiff, yield_, alpha, *shape),
        "bwbn": (stiff, yield_, alpha, *shape, *_PINCHING, *_DEGRADATION),
        "menegotto-pinto": (stiff, yield_, alpha, *steel),
        "steel02": (stiff, yield_, alpha, *steel, *isotropic),
        "isotropic-bilinear": (stiff, yield_, alpha, *saturating),
        "elastic": (Param("k", "law", "kN/mm", k / 30.0, k * 30.0, fp / ctx.d_peak,
                          "stiffness (secant at the peak to start)"),),
    }


STEEL02_FIXED = {"a2": 1.0, "a4": 1.0}
"""Steel02's isotropic shift is ``1 + a1·(excursion / (2·a2·dy))**0.8``: only a1·a2**-0.8
enters, so a2 (and a4) are held at 1 and a1 carries the growth. The growth is symmetric
(a3 = a1): with a3 free, an asymmetric growth mimicked a load-cell offset (four of the five
``sensor_bias`` records of the plain bench chose it, and their offsets came out wrong)."""


_PINCHING = (
    Param("zeta_s", "law", "1", 0.0, 0.97, 0.3, "pinching severity (BWBN zeta_s)"),
    Param("psi0", "law", "1", 0.02, 1.5, 0.2, "pinching spread (BWBN psi0)"),
    Param("q", "law", "1", 0.0, 0.6, 0.1, "pinching centre, fraction of z_u (BWBN q)"),
    Param("p", "law", "1", 0.01, 20.0, 1.0,
          "build-up rate of pinching per unit normalised hysteretic energy (BWBN p)"),
    Param("delta_psi", "law", "1", 0.0, 0.2, 1e-4,
          "growth of the pinching spread per unit normalised energy (BWBN delta_psi)"),
)
_DEGRADATION = (
    Param("delta_nu", "law", "1", 0.0, 0.5, 2e-4, "strength degradation per unit energy"),
    Param("delta_eta", "law", "1", 0.0, 0.5, 2e-4, "stiffness degradation per unit energy"),
)
"""No degrading A (delta_a): to first order it lowers the stiffness like delta_eta and the
strength like delta_nu, so the three are not identifiable together (with delta_a fitted too,
the degradation rate of a bench record comes out far off)."""
PINCHING_FIXED = {"lam": 0.5}
"""The BWBN pinching term the candidate holds fixed: Foliente's coupling lambda = 0.5 (the
sim-actuator preset; with psi0 fitted, the spread psi0 (lambda + zeta1) is what the data fix
once pinching has built up). Both evolution terms are fitted: the build-up rate p (pinching
that develops over several cycles is a different loop history from pinching present from the
first one) and the growth of the spread with energy delta_psi (the pinched zone widens as the
damage grows; without it the loop's drift over a record was taken by a degradation pair)."""


RATE_EXPONENT = (0.1, 2.0)
"""Bounds of the rate law's velocity exponent: fluid dampers and rate-sensitive fixtures span
0.1-1 (1: linear viscous), a few exceed 1. Below 0.1 the law is Coulomb friction in all but
name, which is its own candidate."""


FRICTION_V0_MAX = 0.25
"""Upper bound of the friction's regularisation velocity v0, in units of the record's RMS
command velocity. Dry friction is a force that does not change with velocity: regularised as
``F_c tanh(v/v0)`` (a common lab and solver form of it) it reaches 96 % of F_c at 2 v0, so up
to this bound it is saturated from half the RMS velocity on, over most of the record. A law
still building up beyond that changes with velocity over the record: the rate law's form,
which is its own candidate."""


LIMIT_FORMS = {("rate_dependence", "rate_exponent", "lower"): "friction"}
"""The nesting of the candidates: (effect, parameter, bound) -> the candidate whose form the
effect takes at that bound. A rate law at its smallest exponent is Coulomb friction in all but
name: a single record's rate law fitted there is named ``friction`` (``decision``), the
withheld evidence of both stories counted for it; ``--same-device`` drops such a joint rate
law when friction is a candidate too (``multi``)."""


def effect_parameters(ctx: Context) -> dict[str, tuple[Param, ...]]:
    """Candidate effects and their parameters, bounded by the record's scales."""
    d, f = ctx.d_peak, ctx.f_peak
    v_ref = ctx.record.velocity_scale
    tau_max = min(0.5, 0.1 * ctx.duration)
    return {
        "actuator_delay": (Param("tau", "path", "s", 0.0, tau_max, 2.0 * ctx.dt,
                                 "pure delay of the piston behind the command"),),
        "actuator_amplitude": (Param("amplitude_error", "path", "1", -0.5, 0.5, 0.0,
                                     "piston/command - 1"),),
        "actuator_undershoot": (Param("undershoot", "path", "mm", 0.0, 0.3 * d, 0.01 * d,
                                      "each move's end point falls short by this against the "
                                      "direction of motion (OpenFresco ErrorSimUndershoot)"),),
        "backlash": (Param("gap", "gap", "mm", 0.0, 0.3 * d, 0.01 * d,
                           "clearance of the pin on each side"),),
        "friction": (Param("coulomb", "out", "kN", 0.0, f, 0.02 * f,
                           "Coulomb friction of the fixture"),
                     Param("slip", "out", "mm", 0.0, 0.2 * d, 0.005 * d,
                           "piston travel after a reversal until the fixture slips (Coulomb "
                           "behind a spring; 0: rigid)"),
                     Param("v0", "out", "mm/s", 0.0, FRICTION_V0_MAX * v_ref,
                           0.02 * v_ref,
                           "velocity over which the Coulomb force builds up, tanh(v/v0) "
                           "(0: sign(v), dry friction's limit)")),
        "pinching": _PINCHING,
        "degradation": _DEGRADATION,
        "rate_dependence": (Param("viscous", "out", "kN*s/mm", 0.0, 2.0 * f / ctx.v_rms,
                                  0.02 * f / ctx.v_rms,
                                  "force per velocity at the record's RMS command velocity"),
                            Param("rate_exponent", "out", "1", RATE_EXPONENT[0],
                                  RATE_EXPONENT[1], 1.0,
                                  "velocity exponent a of c·sign(v)|v|^a (1: linear viscous)")),
        "sensor_bias": (Param("force_bias", "out", "kN", -f, f, 0.0, "load-cell offset"),
                        *([] if ctx.record.meas_disp is None else
                          [Param("disp_bias", "out", "mm", -d, d, 0.0, "LVDT offset")])),
        "sensor_noise": (Param("force_noise_std", "noise", "kN", 0.0, math.inf, 0.0,
                               "white noise on the load cell"),
                         Param("disp_noise_std", "noise", "mm", 0.0, math.inf, 0.0,
                               "white noise on the LVDT")),
    }




@dataclass(frozen=True, slots=True)
class Spec:
    """A model to fit: a baseline law kind plus zero or more effects."""

    baseline: str
    effects: tuple[str, ...]
    params: tuple[Param, ...]
    fixed: Mapping[str, float]
    """Parameters held (user-given baseline values that are not fitted)."""

    @property
    def name(self) -> str:
        return "+".join(self.effects) if self.effects else "none"

    @property
    def law_kind(self) -> str:
        """The law actually driven: pinching/degradation need the Bouc-Wen family."""
        if self.baseline in NOT_BOUC_WEN and {"pinching", "degradation"} & set(self.effects):
            return "bwbn"
        return self.baseline


NOT_BOUC_WEN = frozenset(BASELINES) - {"bouc-wen", "bwbn"}
"""Baselines whose pinching and degradation candidates drive BWBN instead (with a sharp start,
n = 8: both laws have a sharp elastic-plastic transition)."""


def make_spec(ctx: Context, baseline: str, effects: Sequence[str],
              fixed: Mapping[str, float] | None = None) -> Spec:
    """The parameters of ``baseline`` + ``effects`` (effects already in a bwbn baseline are
    not added twice; bilinear + pinching/degradation drives BWBN with n fitted)."""
    law = list(law_parameters(ctx)[baseline])
    names = {p.name for p in law}
    eff = effect_parameters(ctx)
    extra: list[Param] = []
    for effect in effects:
        for p in eff[effect]:
            if p.name not in names:
                extra.append(p)
                names.add(p.name)
    if baseline in NOT_BOUC_WEN and {"pinching", "degradation"} & set(effects):
        bw = law_parameters(ctx)["bouc-wen"]
        law = [p for p in law if p.name in {q.name for q in bw}]
        law = [*law, *(p for p in bw if p.name not in names)]
        law = [Param("n", "law", "1", 1.0, 20.0, 8.0, p.meaning) if p.name == "n" else p
               for p in law]
    held = dict(fixed or {})
    return Spec(baseline, tuple(effects),
                tuple(p for p in (*law, *extra) if p.name not in held), held)


# -- prediction -----------------------------------------------------------------------------------
def law_vector(kind: str, values: Mapping[str, float]) -> tuple[int, FloatArray]:
    if kind == "bilinear":
        return LAW_BILINEAR, np.array([values["k0"], values["fy"], values["alpha"]])
    if kind == "elastic":  # a bilinear with alpha = 1 is k·d exactly, whatever fy
        return LAW_BILINEAR, np.array([values["k"], 1.0, 1.0])
    if kind in ("menegotto-pinto", "steel02"):  # menegotto-pinto: no isotropic hardening
        return LAW_MENEGOTTO_PINTO, np.array([
            values["k0"], values["fy"], values["alpha"], values.get("R0", 15.0),
            values.get("cR1", 0.925), values.get("cR2", 0.15), values.get("a1", 0.0),
            STEEL02_FIXED["a2"], values.get("a3", values.get("a1", 0.0)), STEEL02_FIXED["a4"]])
    if kind == "isotropic-bilinear":
        return LAW_ISOTROPIC_BILINEAR, np.array([
            values["k0"], values["fy"], values["alpha"], values.get("q_iso", 0.0),
            values.get("p_sat", 10.0)])
    s, r = values.get("bg_sum", 1.0), values.get("beta_share", 0.5)
    full = {"k0": values["k0"], "fy": values["fy"], "alpha": values["alpha"],
            "n": values.get("n", 2.0), "beta": r * s, "gamma": (1.0 - r) * s, "A0": 1.0,
            "delta_a": 0.0, "delta_nu": values.get("delta_nu", 0.0),
            "delta_eta": values.get("delta_eta", 0.0), "zeta_s": values.get("zeta_s", 0.0),
            "q": values.get("q", 0.0), "psi0": values.get("psi0", 0.2),
            "p": values.get("p", 1.0), "delta_psi": values.get("delta_psi", 0.0),
            **PINCHING_FIXED}
    return LAW_BWBN, np.array([full[name] for name in BWBN_PARAMETERS])


def baseline_report(kind: str, values: Mapping[str, float]) -> dict[str, float]:
    """Law parameters in ``sim_actuator.models`` names (beta, gamma instead of sum/share)."""
    if kind == "bilinear" and "n" not in values:
        return {k: float(values[k]) for k in ("k0", "fy", "alpha")}
    if kind == "menegotto-pinto":
        return {k: float(values[k]) for k in ("k0", "fy", "alpha", "R0", "cR1", "cR2")
                if k in values}
    if kind == "steel02":
        out = {k: float(values[k]) for k in ("k0", "fy", "alpha", "R0", "cR1", "cR2", "a1")
               if k in values}
        return {**out, "a2": STEEL02_FIXED["a2"], "a3": out.get("a1", 0.0),
                "a4": STEEL02_FIXED["a4"]}
    if kind == "isotropic-bilinear":
        return {k: float(values[k]) for k in ("k0", "fy", "alpha", "q_iso", "p_sat")
                if k in values}
    if kind == "elastic":
        return {"k": float(values["k"])}
    s, r = values.get("bg_sum", 1.0), values.get("beta_share", 0.5)
    out = {k: float(values[k]) for k in ("k0", "fy", "alpha", "n") if k in values}
    out.update(beta=float(r * s), gamma=float((1.0 - r) * s))
    for k in ("zeta_s", "psi0", "q", "p", "delta_psi", "delta_nu", "delta_eta"):
        if k in values:
            out[k] = float(values[k])
    return out


IntArray = npt.NDArray[np.int64]


def reference(cmd: FloatArray, values: Mapping[str, float]) -> FloatArray:
    """Each move's end point after undershoot and amplitude: ``(1 + a) (c - u s)``, s the
    direction of the move from the previous command, held through moves of zero length and 0
    before the first move (the rig's ``Actuator.end_point``, OpenFresco's ErrorSimUndershoot:
    the undershoot acts on the reference, the gain after it)."""
    u = values.get("undershoot", 0.0)
    out = cmd
    if u:
        direction = np.zeros_like(cmd)
        direction[1:] = np.diff(cmd)
        out = cmd - u * held_sign(direction)
    a = values.get("amplitude_error", 0.0)
    return out * (1.0 + a) if a else out


def piston_path(ctx: Context, values: Mapping[str, float]) -> tuple[FloatArray, IntArray]:
    """(drive path, indices of the record's samples in it): the piston after undershoot,
    amplitude and delay. A delayed piecewise-linear command passes through its own vertices
    between samples, so the vertices are part of the path (a reversal is never cut short)."""
    rec = ctx.record
    c = reference(rec.cmd, values)
    tau = values.get("tau", 0.0)
    if tau <= 0.0:
        return c, np.arange(c.size, dtype=np.int64)
    t = rec.time
    shifted = t - tau
    x = np.interp(shifted, t, c)
    vertex_times = t + tau  # the piston reaches c_j at t_j + tau
    inside = vertex_times < t[-1]
    merged_t = np.concatenate([t, vertex_times[inside]])
    merged_x = np.concatenate([x, c[inside]])
    order = np.argsort(merged_t, kind="stable")
    where = np.empty(order.size, dtype=np.int64)
    where[order] = np.arange(order.size)
    path: FloatArray = merged_x[order]
    return path, where[: t.size]


def law_force(spec: Spec, ctx: Context, values: Mapping[str, float]) -> FloatArray:
    """Connection force at the record's samples (the law behind the pin gap, if any)."""
    path, index = piston_path(ctx, values)
    law, vec = law_vector(spec.law_kind, values)
    force: FloatArray = drive(law, vec, path, values.get("gap", 0.0), DZ_MAX)[index]
    return force


def finish(ctx: Context, values: Mapping[str, float],
           force: FloatArray) -> tuple[FloatArray, FloatArray]:
    """(predicted force, predicted displacement) from the connection force: fixture friction
    and viscosity on the piston velocity, sensor offsets."""
    rec = ctx.record
    x = reference(rec.cmd, values)
    if values.get("tau", 0.0) > 0.0:
        x = np.interp(rec.time - values["tau"], rec.time, x)
    out = force + values.get("force_bias", 0.0)
    fc, cv = values.get("coulomb", 0.0), values.get("viscous", 0.0)
    if fc or cv:
        v = np.zeros_like(x)
        v[1:] = np.diff(x) / np.diff(rec.time)
        out = (out + friction_force(x, v, fc, values.get("slip", 0.0), values.get("v0", 0.0))
               + rate_force(v, cv, values.get("rate_exponent", 1.0), rec.velocity_scale))
    return out, x + values.get("disp_bias", 0.0)


def friction_force(x: FloatArray, v: FloatArray, coulomb: float, slip: float,
                   v0: float = 0.0) -> FloatArray:
    """Coulomb friction behind a spring (a Jenkins element: elastic-perfectly-plastic on the
    piston travel, slipping at ``coulomb`` after ``slip`` mm), regularised in velocity by
    ``tanh(v/v0)``. Both regularisations of dry friction's ``coulomb·sign(v)`` have it as their
    limit: ``slip`` 0 is the rigid fixture (``sign(v)`` held through holds), ``v0`` 0 the
    unregularised slider; with both, the Jenkins force times ``|tanh(v/v0)|``."""
    if not coulomb:
        return np.zeros_like(x)
    rigid = slip <= 1e-9 * (float(np.max(np.abs(x))) or 1.0)
    if rigid and v0 > 0.0:
        smooth: FloatArray = coulomb * np.tanh(v / v0)
        return smooth
    if rigid:
        return coulomb * held_sign(v)
    out: FloatArray = drive(LAW_BILINEAR, np.array([coulomb / slip, coulomb, 0.0]), x, 0.0,
                            DZ_MAX)
    return out * np.abs(np.tanh(v / v0)) if v0 > 0.0 else out


def rate_force(v: FloatArray, viscous: float, exponent: float, v_ref: float) -> FloatArray:
    """The rate law ``c·v_ref·sign(v)·|v/v_ref|^a``: ``viscous`` (c) is the force per
    velocity at ``v_ref`` whatever the exponent, so c and a stay separable in the fit."""
    if not viscous:
        return np.zeros_like(v)
    if exponent == 1.0:
        return viscous * v
    out: FloatArray = viscous * v_ref * np.sign(v) * np.abs(v / v_ref) ** exponent
    return out


def held_sign(v: FloatArray) -> FloatArray:
    """sign(v), keeping the last non-zero sign through holds (Coulomb memory of the rig)."""
    s = np.sign(v)
    idx = np.where(s != 0.0, np.arange(s.size), 0)
    np.maximum.accumulate(idx, out=idx)
    held: FloatArray = s[idx]
    return held
