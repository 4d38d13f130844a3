# Indexing a float64 array is typed Any by numpy's stubs; the kernels return floats.
# mypy: disable-error-code="no-any-return"
"""Whole-history drives of the hysteresis laws, JIT-compiled (numba): the fast form for fitting.

A fit evaluates a law over a whole displacement history hundreds of times; the per-step Python
objects (``set_trial``/``commit``) cost tens of ms per 3000-step history, this form well under
one. It is the *same* algorithm as the scalar models, operation for operation — Steel01 of
``bilinear``; the BWBN equations, RK4 substeps sized by ``dz_max`` and the split at z = 0 of
``bwbn`` (classic Bouc-Wen is BWBN with no degradation and no pinching); Steel02 of
``menegotto_pinto`` (closed form per trial: no substeps); the return map of
``isotropic_bilinear`` — and
``tests/sim_actuator/test_model_paths.py`` checks it against them to ~1e-12. Change a law in
both places or in neither.

``drive(law, params, d, gap, dz_max)`` commits the law at every sample of ``d`` (material
semantics: each sample is one trial from the last committed state, then committed) and returns
the force history. ``gap > 0`` puts the law behind a pin with that clearance on each side, as
``sim_actuator.effects.LoadPath`` does with a rigid frame: the force is zero while the pin is
free, and the specimen rests where its own force is zero.

A history the law refuses (degradation exhausted, a step needing more than ``MAX_SUBSTEPS``)
returns NaN from that sample on: the fitter reads NaN as "not this parameter set".
"""

from __future__ import annotations

import math
from collections.abc import Mapping

import numpy as np
import numpy.typing as npt
from numba import njit

from sim_actuator.models.bouc_wen import DEFAULT_DZ_MAX, MAX_SUBSTEPS
from sim_actuator.models.isotropic_bilinear import NEWTON_ITERATIONS as _ISO_NEWTON_ITERATIONS
from sim_actuator.models.menegotto_pinto import MenegottoPinto

__all__ = [
    "BOUC_WEN_PARAMETERS",
    "BWBN_PARAMETERS",
    "ISOTROPIC_BILINEAR_PARAMETERS",
    "LAW_BILINEAR",
    "LAW_BOUC_WEN",
    "LAW_BWBN",
    "LAW_ISOTROPIC_BILINEAR",
    "LAW_MENEGOTTO_PINTO",
    "MENEGOTTO_PINTO_PARAMETERS",
    "STATE_SIZE",
    "bouc_wen_advance",
    "bouc_wen_vector",
    "bwbn_advance",
    "bwbn_vector",
    "drive",
    "drive_from",
    "drive_many",
    "law_vector",
]

FloatArray = npt.NDArray[np.float64]

LAW_BILINEAR = 0
"""``params`` = [k0, fy, alpha]."""
LAW_BWBN = 1
"""``params`` = :data:`BWBN_PARAMETERS` in that order (Bouc-Wen: A0 = A, the rest zero)."""
LAW_MENEGOTTO_PINTO = 2
"""``params`` = :data:`MENEGOTTO_PINTO_PARAMETERS` in that order (Steel02)."""
LAW_BOUC_WEN = 3
"""``params`` = :data:`BOUC_WEN_PARAMETERS` in that order: the classic ``bouc_wen`` object's
own algorithm (its Simpson split at z = 0), bit for bit; ``LAW_BWBN`` with the classic
parameters is the same law to rounding, not to the bit."""
LAW_ISOTROPIC_BILINEAR = 4
"""``params`` = :data:`ISOTROPIC_BILINEAR_PARAMETERS` in that order."""
ISOTROPIC_BILINEAR_PARAMETERS = ("k0", "fy", "alpha", "q_iso", "p_sat")
BOUC_WEN_PARAMETERS = ("k0", "fy", "alpha", "n", "beta", "gamma", "A")
MENEGOTTO_PINTO_PARAMETERS = ("k0", "fy", "alpha", "R0", "cR1", "cR2", "a1", "a2", "a3", "a4")

BWBN_PARAMETERS = (
    "k0", "fy", "alpha", "n", "beta", "gamma", "A0", "delta_a", "delta_nu", "delta_eta",
    "zeta_s", "p", "q", "psi0", "delta_psi", "lam",
)  # fmt: skip
_BWBN_DEFAULTS = {"A0": 1.0, "delta_a": 0.0, "delta_nu": 0.0, "delta_eta": 0.0, "zeta_s": 0.0,
                  "p": 0.0, "q": 0.0, "psi0": 1.0, "delta_psi": 0.0, "lam": 1.0}
_DBL_EPSILON = float(np.finfo(np.float64).eps)


def bwbn_vector(params: Mapping[str, float]) -> FloatArray:
    """The BWBN parameter vector from a ``bwbn`` or ``bouc-wen`` parameter dict."""
    values = dict(_BWBN_DEFAULTS)
    for name, value in params.items():
        values["A0" if name == "A" else name] = float(value)
    return np.array([values[name] for name in BWBN_PARAMETERS], dtype=np.float64)


def bouc_wen_vector(params: Mapping[str, float]) -> FloatArray:
    """The ``LAW_BOUC_WEN`` parameter vector from a ``bouc-wen`` parameter dict (A = 1 unless
    given)."""
    return np.array([float(params[name]) if name in params else 1.0
                     for name in BOUC_WEN_PARAMETERS], dtype=np.float64)  # fmt: skip


def law_vector(kind: str, params: Mapping[str, float]) -> tuple[int, FloatArray]:
    """(law code, parameter vector) for a model kind of ``sim_actuator.models``."""
    if kind == "bilinear":
        return LAW_BILINEAR, np.array([params["k0"], params["fy"], params["alpha"]], np.float64)
    if kind in ("bouc-wen", "bwbn"):
        return LAW_BWBN, bwbn_vector(params)
    if kind == "menegotto-pinto":
        values = {p.name: p.default for p in MenegottoPinto.PARAMS if p.default is not None}
        values.update(params)
        return LAW_MENEGOTTO_PINTO, np.array(
            [float(values[name]) for name in MENEGOTTO_PINTO_PARAMETERS], np.float64)
    if kind == "isotropic-bilinear":
        values = {"q_iso": 0.0, "p_sat": 10.0, **params}
        return LAW_ISOTROPIC_BILINEAR, np.array(
            [float(values[name]) for name in ISOTROPIC_BILINEAR_PARAMETERS], np.float64)
    raise ValueError(f"no fast drive for model kind {kind!r} "
                     "(bilinear, bouc-wen, bwbn, menegotto-pinto, isotropic-bilinear)")


# -- BWBN (bwbn.py, line by line) ----------------------------------------------------------------
@njit(cache=True)
def _slope(prm: FloatArray, z: float, e: float, direction: float) -> float:
    n, beta, gamma = prm[3], prm[4], prm[5]
    a0, delta_a, delta_nu, delta_eta = prm[6], prm[7], prm[8], prm[9]
    zeta_s = prm[10]
    nu = 1.0 + delta_nu * e
    core = a0 - delta_a * e
    if z != 0.0:
        sign = 1.0 if (z > 0.0) == (direction > 0.0) else -1.0
        core -= nu * abs(z) ** n * (beta * sign + gamma)
    if zeta_s > 0.0:
        e_pos = e if e > 0.0 else 0.0
        zeta1 = zeta_s * (1.0 - math.exp(-prm[11] * e_pos))
        if zeta1 > 0.0:
            zeta2 = (prm[13] + prm[14] * e_pos) * (prm[15] + zeta1)
            z_u = (1.0 / (nu * (beta + gamma))) ** (1.0 / n)
            x = (z * direction - prm[12] * z_u) / zeta2
            core *= 1.0 - zeta1 * math.exp(-x * x)
    return core / (1.0 + delta_eta * e)


@njit(cache=True)
def _rk4(prm: FloatArray, z: float, e: float, h: float, direction: float) -> tuple[float, float]:
    w = 1.0 - prm[2]
    k1 = _slope(prm, z, e, direction)
    z2, e2 = z + 0.5 * h * k1, e + 0.5 * h * w * z
    k2 = _slope(prm, z2, e2, direction)
    z3, e3 = z + 0.5 * h * k2, e + 0.5 * h * w * z2
    k3 = _slope(prm, z3, e3, direction)
    z4, e4 = z + h * k3, e + h * w * z3
    k4 = _slope(prm, z4, e4, direction)
    return (
        z + h / 6.0 * (k1 + 2.0 * k2 + 2.0 * k3 + k4),
        e + h / 6.0 * w * (z + 2.0 * z2 + 2.0 * z3 + z4),
    )


@njit(cache=True)
def _substep(prm: FloatArray, z: float, e: float, h: float,
             direction: float) -> tuple[float, float]:
    z_end, e_end = _rk4(prm, z, e, h, direction)
    if z * z_end >= 0.0:
        return z_end, e_end
    # the u-distance to z = 0 by one RK4 step in z (bwbn._to_zero)
    w = 1.0 - prm[2]
    dz = -z
    s1 = _slope(prm, z, e, direction)
    if s1 <= 0.0:
        return z_end, e_end
    z2 = z + 0.5 * dz
    e2 = e + 0.5 * dz * w * z / s1
    s2 = _slope(prm, z2, e2, direction)
    if s2 <= 0.0:
        return z_end, e_end
    e3 = e + 0.5 * dz * w * z2 / s2
    s3 = _slope(prm, z2, e3, direction)
    if s3 <= 0.0:
        return z_end, e_end
    e4 = e + dz * w * z2 / s3
    s4 = _slope(prm, 0.0, e4, direction)
    if s4 <= 0.0:
        return z_end, e_end
    to_zero = dz / 6.0 * (1.0 / s1 + 2.0 / s2 + 2.0 / s3 + 1.0 / s4)
    e_zero = e + dz / 6.0 * w * (z / s1 + 2.0 * z2 / s2 + 2.0 * z2 / s3)
    if not 0.0 < to_zero / h < 1.0:
        return z_end, e_end
    return _rk4(prm, 0.0, e_zero, h - to_zero, direction)


@njit(cache=True)
def _bwbn_advance(prm: FloatArray, z: float, e: float, du: float,
                  dz_max: float) -> tuple[float, float, bool]:
    """(z, e, ok) after ``du`` yield displacements from (z, e): ``bwbn._advance``; not ok where
    it needs more than ``MAX_SUBSTEPS``."""
    n = prm[3]
    direction = 1.0 if du > 0.0 else -1.0
    nu = 1.0 + prm[8] * e
    z_scale = max(abs(z), (prm[6] / (nu * (prm[4] + prm[5]))) ** (1.0 / n))
    bound = (prm[6] + n * nu * (prm[4] + abs(prm[5])) * z_scale**n) / (1.0 + prm[9] * e)
    count = int(abs(du) * bound / dz_max) + 1
    if count > MAX_SUBSTEPS:
        return z, e, False
    h = du / count
    for _ in range(count):
        z, e = _substep(prm, z, e, h, direction)
    return z, e, True


@njit(cache=True)
def _bwbn_trial(prm: FloatArray, d_c: float, z_c: float, e_c: float, f_c: float, d: float,
                dz_max: float) -> tuple[float, float, float, bool]:
    """(force, z, e, ok) of a trial to ``d`` from the committed (d_c, z_c, e_c, f_c)."""
    k0, fy, alpha = prm[0], prm[1], prm[2]
    du = (d - d_c) / (fy / k0)
    if not math.isfinite(du):
        return math.nan, z_c, e_c, False
    if du == 0.0:
        return f_c, z_c, e_c, True
    z, e, ok = _bwbn_advance(prm, z_c, e_c, du, dz_max)
    if not ok:
        return math.nan, z_c, e_c, False
    if prm[6] - prm[7] * e <= 0.0:
        return math.nan, z, e, False
    force = alpha * k0 * d + (1.0 - alpha) * fy * z
    return force, z, e, True


# -- classic Bouc-Wen (bouc_wen.py, line by line) -----------------------------------------------
@njit(cache=True)
def _bw_slope(prm: FloatArray, z: float, direction: float) -> float:
    if z == 0.0:
        return prm[6]
    beta, gamma = prm[4], prm[5]
    coef = beta + gamma if (z > 0.0) == (direction > 0.0) else gamma - beta
    power = abs(z) ** prm[3]
    return prm[6] - power * coef


@njit(cache=True)
def _bw_rk4(prm: FloatArray, z: float, h: float, direction: float) -> float:
    k1 = _bw_slope(prm, z, direction)
    k2 = _bw_slope(prm, z + 0.5 * h * k1, direction)
    k3 = _bw_slope(prm, z + 0.5 * h * k2, direction)
    k4 = _bw_slope(prm, z + h * k3, direction)
    return z + h / 6.0 * (k1 + 2.0 * k2 + 2.0 * k3 + k4)


@njit(cache=True)
def _bw_substep(prm: FloatArray, z: float, h: float, direction: float) -> float:
    z_end = _bw_rk4(prm, z, h, direction)
    if z * z_end >= 0.0:
        return z_end
    s1 = _bw_slope(prm, z, direction)
    s2 = _bw_slope(prm, 0.5 * z, direction)
    if s1 <= 0.0 or s2 <= 0.0:
        return z_end
    to_zero = -z / 6.0 * (1.0 / s1 + 4.0 / s2 + 1.0 / prm[6])
    fraction = to_zero / h
    if not 0.0 < fraction < 1.0:
        return z_end
    return _bw_rk4(prm, 0.0, h - to_zero, direction)


@njit(cache=True)
def _bw_advance(prm: FloatArray, z: float, du: float, dz_max: float) -> tuple[float, bool]:
    """(z, ok) after ``du`` yield displacements from z: ``bouc_wen._advance``; not ok where it
    needs more than ``MAX_SUBSTEPS``."""
    n, beta, gamma, a = prm[3], prm[4], prm[5], prm[6]
    direction = 1.0 if du > 0.0 else -1.0
    z_ultimate = (a / (beta + gamma)) ** (1.0 / n)
    bound = a + n * (beta + abs(gamma)) * max(abs(z), z_ultimate) ** n
    count = int(abs(du) * bound / dz_max) + 1
    if count > MAX_SUBSTEPS:
        return z, False
    h = du / count
    for _ in range(count):
        z = _bw_substep(prm, z, h, direction)
    return z, True


@njit(cache=True)
def _bw_trial(prm: FloatArray, d_c: float, z_c: float, f_c: float, d: float,
              dz_max: float) -> tuple[float, float, bool]:
    """(force, z, ok) of a trial to ``d`` from the committed (d_c, z_c, f_c)."""
    k0, fy, alpha = prm[0], prm[1], prm[2]
    du = (d - d_c) / (fy / k0)
    if not math.isfinite(du):
        return math.nan, z_c, False
    if du == 0.0:
        return f_c, z_c, True
    z, ok = _bw_advance(prm, z_c, du, dz_max)
    if not ok:
        return math.nan, z_c, False
    force = alpha * k0 * d + (1.0 - alpha) * fy * z
    return force, z, True


bouc_wen_advance = _bw_advance
"""The classic Bouc-Wen object's ``_advance`` (``stepped.SteppedBoucWen``)."""
bwbn_advance = _bwbn_advance
"""The BWBN object's ``_advance`` (``stepped.SteppedBaberNoori``)."""


# -- Steel01 without isotropic hardening (bilinear.py) -----------------------------------------
@njit(cache=True)
def _bilinear_trial(prm: FloatArray, d_c: float, f_c: float, d: float) -> float:
    k0, fy, alpha = prm[0], prm[1], prm[2]
    d_step = d - d_c
    if abs(d_step) > _DBL_EPSILON:
        c1 = alpha * k0 * d
        predictor = f_c + k0 * d_step
        upper = c1 + fy * (1.0 - alpha)
        force = upper if upper < predictor else predictor
        lower = c1 - fy * (1.0 - alpha)
        if lower > force:
            force = lower
        return force
    return f_c


# -- kinematic + saturating isotropic hardening (isotropic_bilinear.py, line by line) -----------
@njit(cache=True)
def _iso_trial(prm: FloatArray, c: FloatArray, d: float, out: FloatArray) -> bool:
    """``isotropic_bilinear.return_map`` from the committed [d, f, back, p] into ``out``."""
    k0, fy, alpha, q_iso, p_sat = prm[0], prm[1], prm[2], prm[3], prm[4]
    d_c, f_c, back, p = c[0], c[1], c[2], c[3]
    if not math.isfinite(d - d_c):
        return False
    h = alpha * k0 / (1.0 - alpha)
    scale = p_sat * fy / k0
    grow = q_iso * fy
    trial = f_c + k0 * (d - d_c)
    xi = trial - back
    size = abs(xi)
    radius = fy + grow * (1.0 - math.exp(-p / scale))
    out[0], out[1], out[2], out[3] = d, trial, back, p
    if size <= radius:
        return math.isfinite(trial)
    lam = 0.0
    for _ in range(_ISO_NEWTON_ITERATIONS):
        decay = math.exp(-(p + lam) / scale)
        g = size - (k0 + h) * lam - fy - grow * (1.0 - decay)
        step = g / (k0 + h + grow / scale * decay)
        lam += step
        if abs(step) <= 1e-15 * (abs(lam) + fy / k0):
            break
    sign = 1.0 if xi > 0.0 else -1.0
    out[1], out[2], out[3] = trial - k0 * lam * sign, back + h * lam * sign, p + lam
    return math.isfinite(out[1])


# -- Giuffre-Menegotto-Pinto, Steel02 (menegotto_pinto.py, line by line) ----------------------
_MP_VIRGIN, _MP_LOADING, _MP_UNLOADING, _MP_AT_REST = 0.0, 1.0, 2.0, 3.0


@njit(cache=True)
def _mp_trial(prm: FloatArray, c: FloatArray, d: float, out: FloatArray) -> bool:
    """Trial of ``MenegottoPinto.set_trial`` from the committed state ``c`` into ``out``
    (layout of :func:`_drive`'s state; the tangent is not kept)."""
    d_step = d - c[0]
    if not math.isfinite(d_step):
        return False
    k0, fy, alpha = prm[0], prm[1], prm[2]
    esh = alpha * k0
    dy = fy / k0
    d_max, d_min, d_pl, d_0, f_0, d_r, f_r, kon = c[4], c[5], c[6], c[7], c[8], c[9], c[10], c[11]
    if kon in (_MP_VIRGIN, _MP_AT_REST):
        if abs(d_step) < 10.0 * _DBL_EPSILON:
            out[:] = c
            out[0], out[1], out[11] = d, 0.0, _MP_AT_REST
            return True
        d_max = dy
        d_min = -dy
        if d_step < 0.0:
            kon, d_0, f_0, d_pl = _MP_UNLOADING, d_min, -fy, d_min
        else:
            kon, d_0, f_0, d_pl = _MP_LOADING, d_max, fy, d_max
    if kon == _MP_UNLOADING and d_step > 0.0:
        kon = _MP_LOADING
        d_r, f_r = c[0], c[1]
        if c[0] < d_min:
            d_min = c[0]
        d1 = (d_max - d_min) / (2.0 * (prm[9] * dy))
        shift = 1.0 + prm[8] * d1**0.8
        d_0 = (fy * shift - esh * dy * shift - f_r + k0 * d_r) / (k0 - esh)
        f_0 = fy * shift + esh * (d_0 - dy * shift)
        d_pl = d_max
    elif kon == _MP_LOADING and d_step < 0.0:
        kon = _MP_UNLOADING
        d_r, f_r = c[0], c[1]
        if c[0] > d_max:
            d_max = c[0]
        d1 = (d_max - d_min) / (2.0 * (prm[7] * dy))
        shift = 1.0 + prm[6] * d1**0.8
        d_0 = (-fy * shift + esh * dy * shift - f_r + k0 * d_r) / (k0 - esh)
        f_0 = -fy * shift + esh * (d_0 + dy * shift)
        d_pl = d_min
    if d_0 == d_r:
        force = f_r + esh * (d - d_r)
    else:
        xi = abs((d_pl - d_0) / dy)
        r = prm[3] * (1.0 - (prm[4] * xi) / (prm[5] + xi))
        ratio = (d - d_r) / (d_0 - d_r)
        dum1 = 1.0 + abs(ratio) ** r
        # Python's pow raises OverflowError where numba's is inf: the scalar law then takes
        # (1 + |ratio|**r)**(1/r) as |ratio|, exactly
        dum2 = abs(ratio) if math.isinf(dum1) else dum1 ** (1 / r)
        force = alpha * ratio + (1.0 - alpha) * ratio / dum2
        force = force * (f_0 - f_r) + f_r
    out[0], out[1], out[2], out[3] = d, force, 0.0, 0.0
    out[4], out[5], out[6], out[7], out[8] = d_max, d_min, d_pl, d_0, f_0
    out[9], out[10], out[11] = d_r, f_r, kon
    return math.isfinite(force)


# -- one trial of any law, and the whole-history drive -------------------------------------------
STATE_SIZE = 12
"""[d, f, z, e] (the Bouc-Wen family's committed state; bilinear uses d, f; the isotropic
bilinear d, f, back force, accumulated plastic displacement), then Steel02's
d_max, d_min, d_pl, d_0, f_0, d_r, f_r, kon."""


@njit(cache=True)
def _initial(law: int, prm: FloatArray) -> FloatArray:
    state = np.zeros(STATE_SIZE)
    if law == LAW_MENEGOTTO_PINTO:
        dy = prm[1] / prm[0]
        state[4], state[5] = dy, -dy
    return state


@njit(cache=True)
def _trial(law: int, prm: FloatArray, state: FloatArray, d: float, dz_max: float,
           out: FloatArray) -> bool:
    """Trial to ``d`` from the committed ``state`` into ``out``; False if the law refuses."""
    if law == LAW_MENEGOTTO_PINTO:
        return _mp_trial(prm, state, d, out)
    if law == LAW_ISOTROPIC_BILINEAR:
        return _iso_trial(prm, state, d, out)
    if law == LAW_BILINEAR:
        f = _bilinear_trial(prm, state[0], state[1], d)
        out[0], out[1] = d, f
        return math.isfinite(f)
    if law == LAW_BOUC_WEN:
        f, z, ok = _bw_trial(prm, state[0], state[2], state[1], d, dz_max)
        out[0], out[1], out[2] = d, f, z
        return ok
    f, z, e, ok = _bwbn_trial(prm, state[0], state[2], state[3], state[1], d, dz_max)
    out[0], out[1], out[2], out[3] = d, f, z, e
    return ok


@njit(cache=True)
def _free_position(law: int, prm: FloatArray, state: FloatArray, lo: float, hi: float,
                   f_lo: float, f_hi: float, dz_max: float, out: FloatArray) -> float:
    """Where the unloaded specimen rests inside [lo, hi], f(lo) <= 0 <= f(hi): its force is
    zero there. Illinois regula falsi from the committed position (a handful of trials where
    bisection took ~45: each trial of a stiff law across a wide gap is hundreds of substeps)."""
    d_c = state[0]
    tol = 1e-12 * (1.0 + abs(hi))
    u = min(max(d_c, lo), hi)
    side = 0
    for _ in range(200):
        if not _trial(law, prm, state, u, dz_max, out):
            return math.nan
        f = out[1]
        if f == 0.0:
            return u
        if f > 0.0:
            hi, f_hi = u, f
            if side == 1:
                f_lo *= 0.5
            side = 1
        else:
            lo, f_lo = u, f
            if side == -1:
                f_hi *= 0.5
            side = -1
        if hi - lo <= tol:
            return u
        step_to = (lo * f_hi - hi * f_lo) / (f_hi - f_lo) if f_hi != f_lo else 0.5 * (lo + hi)
        if not lo < step_to < hi:
            step_to = 0.5 * (lo + hi)
        if abs(step_to - u) <= tol:
            return step_to
        u = step_to
    return u


@njit(cache=True)
def _drive(law: int, prm: FloatArray, d: FloatArray, gap: float, dz_max: float) -> FloatArray:
    out = np.empty(d.size)
    state = _initial(law, prm)
    trial = np.empty(STATE_SIZE)
    free = gap > 0.0
    for k in range(d.size):
        p = d[k]
        if gap == 0.0:
            if not _trial(law, prm, state, p, dz_max, trial):
                out[k:] = math.nan
                return out
            state[:] = trial
            out[k] = trial[1]
            continue
        ok = _trial(law, prm, state, p - gap, dz_max, trial)
        f = trial[1]
        if ok and f > 0.0:
            state[:] = trial
            out[k] = f
            free = False
            continue
        f_lo = f
        if ok:
            ok = _trial(law, prm, state, p + gap, dz_max, trial)
            f = trial[1]
        if ok and f < 0.0:
            state[:] = trial
            out[k] = f
            free = False
            continue
        if not ok:
            out[k:] = math.nan
            return out
        if free and p - gap <= state[0] <= p + gap:
            u = state[0]
        else:
            u = _free_position(law, prm, state, p - gap, p + gap, f_lo, f, dz_max, trial)
        if not _trial(law, prm, state, u, dz_max, trial):
            out[k:] = math.nan
            return out
        state[:] = trial
        out[k] = 0.0
        free = True
    return out


def drive(law: int, params: FloatArray, d: FloatArray, gap: float = 0.0,
          dz_max: float = DEFAULT_DZ_MAX) -> FloatArray:
    """Force history of the law committed at every sample of ``d`` (see module docstring)."""
    prm = np.ascontiguousarray(params, dtype=np.float64)
    path = np.ascontiguousarray(d, dtype=np.float64)
    result: FloatArray = _drive(int(law), prm, path, float(gap), float(dz_max))
    return result


@njit(cache=True)
def _drive_from(law: int, prm: FloatArray, d: FloatArray, start: FloatArray,
                dz_max: float) -> FloatArray:
    out = np.empty(d.size)
    state = start.copy()
    trial = np.empty(STATE_SIZE)
    for k in range(d.size):
        if not _trial(law, prm, state, d[k], dz_max, trial):
            out[k:] = math.nan
            return out
        state[:] = trial
        out[k] = trial[1]
    return out


def drive_from(law: int, params: FloatArray, d: FloatArray, start: FloatArray,
               dz_max: float = DEFAULT_DZ_MAX) -> FloatArray:
    """``drive`` (no gap) from the committed kernel state ``start`` (``STATE_SIZE`` values:
    [d, f, z, e, …]) instead of the virgin one: an online refit's window, which starts where the
    element's history before it left the law."""
    prm = np.ascontiguousarray(params, dtype=np.float64)
    path = np.ascontiguousarray(d, dtype=np.float64)
    state = np.ascontiguousarray(start, dtype=np.float64)
    if state.shape != (STATE_SIZE,):
        raise ValueError(f"drive_from: start must hold {STATE_SIZE} values, got {state.shape}")
    result: FloatArray = _drive_from(int(law), prm, path, state, float(dz_max))
    return result


def drive_many(law: int, params: FloatArray, paths: FloatArray, gaps: FloatArray,
               dz_max: float = DEFAULT_DZ_MAX) -> FloatArray:
    """``drive`` for a population: row i drives ``params[i]`` along ``paths[i]`` with
    ``gaps[i]`` (a finite-difference Jacobian is one population). One call, one thread:
    parallelism belongs to the records (a process per record), which scales on a loaded
    machine where threads inside one fit did not (they ran slower than serial)."""
    prm = np.ascontiguousarray(np.atleast_2d(params), dtype=np.float64)
    rows = np.ascontiguousarray(np.atleast_2d(paths), dtype=np.float64)
    gap = np.broadcast_to(np.asarray(gaps, dtype=np.float64), (prm.shape[0],))
    out = np.empty((prm.shape[0], rows.shape[1]))
    for i in range(prm.shape[0]):  # a Python loop: one compiled kernel less (compile time)
        out[i] = _drive(int(law), prm[i], rows[i if rows.shape[0] > 1 else 0], float(gap[i]),
                        float(dz_max))
    return out
