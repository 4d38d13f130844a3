"""Bouc-Wen with beta = gamma, an exponent scheduled on the previous plastic excursion and
isotropic hardening of the hysteretic strength with the largest displacement range.

Why it is here: issue 9 needs a law with a real internal state, outside both study specimens'
laws, that can be identified online (``fresco_bridge.updating.refit``) for the Menegotto-Pinto
(Steel02) specimen. Steel02 leaves every reversal with tangent k0 and softens at once after a
large excursion while staying sharp after small ones; a Chaboche law (elastic range, exponential
approach) cannot (BENCHMARKS "updating part 8a"). Here the unloading tangent is exactly k0
(beta = gamma) and the sharpness n of the transition drops with the previous excursion.

It is not Menegotto-Pinto (any variant): no branch equation from the last reversal point, no
asymptote intersection, no memory of reversal points — the state is one hysteretic force and
one scalar (the plastic travel of the previous half-cycle); the branch is the solution of a
Bouc-Wen ODE. It is not BWBN: no degradation with energy, no pinching; its only changes are the
exponent and the strength.

Law (``dy = fy/k0``, ``u = d/dy``; hysteretic variable w, dimensionless)::

    f     = alpha*k0*d + (1 - alpha)*fy*w
    dw/du = 1 - |w/h|**n   while du*w > 0 (loading),   1 while unloading (beta = gamma = 1/2)
    h     = 1 + a*(r/dy)**p,   r = (max d - min d)/2 over the history (isotropic hardening)
    n     = n_min + (n0 - n_min)/(1 + xi/xi0)

``xi`` is the plastic travel (``|du| - sign(du)*dw``, in dy) of the previous half-cycle: at
each reversal it takes the travel accumulated since the one before. Under monotonic loading w
tends to h; a reversal unloads at tangent k0 exactly.

Integration: within one trial the path is monotonic and n constant. On the unloading side w
moves linearly (exact); on the loading side ``s = sign(du)*w`` follows ``ds/dt = 1 - (s/h)**n``
(t the travel, h a function of the position), classic RK4 on equal substeps, their number
chosen so that s changes by at most ``dz_max`` per substep (bound ``1 + n``). The kernel
:func:`_step` is plain arithmetic: the class runs it in Python, :func:`drive` (the fast form
for fitting) the same source JIT-compiled by numba.

OpenSees semantics: ``set_trial(d)`` from the last commit, ``commit()``; repeated trials never
advance the state. No OpenSees material has this law.
"""

from __future__ import annotations

import math
from typing import NamedTuple

import numpy as np
import numpy.typing as npt
from numba import njit

from sim_actuator.checks import NON_NEGATIVE, POSITIVE, Bound, within
from sim_actuator.models.base import (
    HysteresisBase,
    ModelInputError,
    ModelParameterError,
    Param,
    trial_input_error,
)
from sim_actuator.models.bouc_wen import DZ_MAX, MAX_SUBSTEPS

__all__ = ["ExcursionBoucWen", "ExcursionBoucWenState", "drive"]

FloatArray = npt.NDArray[np.float64]

DEFAULT_DZ_MAX = 0.02
"""Largest change of w per RK4 substep by default."""


class ExcursionBoucWenState(NamedTuple):
    """Committed state of an :class:`ExcursionBoucWen` law."""

    d: float
    f: float
    k: float
    """Tangent stiffness at the committed point."""
    w: float
    """Hysteretic variable (dimensionless; the hysteretic force is (1 - alpha)*fy*w)."""
    d_max: float
    """Largest displacement so far (>= 0)."""
    d_min: float
    """Smallest displacement so far (<= 0)."""
    travel: float
    """Plastic travel (in dy) since the last reversal."""
    xi: float
    """Plastic travel of the previous half-cycle (in dy): sets the exponent."""
    direction: float
    """Direction of the last committed motion (+1, -1; 0 before any)."""


def _step(
    k0: float,
    fy: float,
    alpha: float,
    n0: float,
    n_min: float,
    xi0: float,
    a: float,
    p: float,
    c: float,
    dz_max: float,
    d_c: float,
    w_c: float,
    d_max: float,
    d_min: float,
    travel: float,
    xi: float,
    direction: float,
    d: float,
) -> tuple[float, float, float, float, float, float, float, float, float]:
    """One trial from the committed state to ``d`` (``d != d_c``): the new state tuple in
    :class:`ExcursionBoucWenState` order. Plain arithmetic (numba compiles the same source);
    NaN force when the step needs more than ``MAX_SUBSTEPS`` substeps."""
    dy = fy / k0
    du = (d - d_c) / dy
    sgn = 1.0 if du > 0.0 else -1.0
    if direction != 0.0 and sgn != direction:
        xi = travel
        travel = 0.0
    n = n_min + (n0 - n_min) / (1.0 + xi / xi0)
    remaining = abs(du)
    u = d_c / dy
    s = sgn * w_c
    s_start = s
    u_max, u_min = d_max / dy, d_min / dy
    count = int(remaining * (1.0 + n) / dz_max) + 1
    if count > MAX_SUBSTEPS:
        nan = math.nan
        return d, nan, nan, nan, d_max, d_min, travel, xi, sgn
    ht = remaining / count
    for i in range(count):
        u0 = u + sgn * ht * i
        # hardening at the substep's start, middle and end (h = 1 + a r**p, r the half range)
        r0 = 0.5 * (max(u_max, u0) - min(u_min, u0))
        um = u0 + sgn * 0.5 * ht
        rm = 0.5 * (max(u_max, um) - min(u_min, um))
        ue = u0 + sgn * ht
        re = 0.5 * (max(u_max, ue) - min(u_min, ue))
        h0 = 1.0 + a * r0**p
        hm = 1.0 + a * rm**p
        he = 1.0 + a * re**p
        g1 = 1.0 - (max(s + c * h0, 0.0) / ((1.0 + c) * h0)) ** n
        s2 = s + 0.5 * ht * g1
        g2 = 1.0 - (max(s2 + c * hm, 0.0) / ((1.0 + c) * hm)) ** n
        s3 = s + 0.5 * ht * g2
        g3 = 1.0 - (max(s3 + c * hm, 0.0) / ((1.0 + c) * hm)) ** n
        s4 = s + ht * g3
        g4 = 1.0 - (max(s4 + c * he, 0.0) / ((1.0 + c) * he)) ** n
        s += ht / 6.0 * (g1 + 2.0 * g2 + 2.0 * g3 + g4)
    travel += remaining - (s - s_start)
    ue = d / dy
    he = 1.0 + a * (0.5 * (max(u_max, ue) - min(u_min, ue))) ** p
    slope = 1.0 - (max(s + c * he, 0.0) / ((1.0 + c) * he)) ** n
    w = sgn * s
    force = alpha * k0 * d + (1.0 - alpha) * fy * w
    tangent = alpha * k0 + (1.0 - alpha) * k0 * slope
    return d, force, tangent, w, max(d_max, d), min(d_min, d), travel, xi, sgn


_step_fast = njit(cache=True)(_step)


@njit(cache=True)
def _drive(prm: FloatArray, disp: FloatArray, dz_max: float) -> FloatArray:
    out = np.empty(disp.size)
    d_c, f_c = 0.0, 0.0
    w_c, d_max, d_min, travel, xi, direction = 0.0, 0.0, 0.0, 0.0, 0.0, 0.0
    for i in range(disp.size):
        d = disp[i]
        if d != d_c:
            (d_c, f_c, _, w_c, d_max, d_min, travel, xi, direction) = _step_fast(
                prm[0],
                prm[1],
                prm[2],
                prm[3],
                prm[4],
                prm[5],
                prm[6],
                prm[7],
                prm[8],
                dz_max,
                d_c,
                w_c,
                d_max,
                d_min,
                travel,
                xi,
                direction,
                d,
            )
            if not math.isfinite(f_c):
                out[i:] = math.nan
                return out
        out[i] = f_c
    return out


class ExcursionBoucWen(HysteresisBase):
    """Bouc-Wen (beta = gamma), exponent on the previous excursion, strength on the range
    (module docstring)."""

    __slots__ = ("a", "alpha", "c", "dz_max", "fy", "k0", "n0", "n_min", "p", "xi0")

    name = "excursion-bouc-wen"
    PARAMS = (
        Param(
            "k0",
            "initial (and every unloading) stiffness",
            "force/displacement (e.g. kN/mm)",
            POSITIVE,
        ),
        Param(
            "fy",
            "virgin strength of the hysteretic part: its force is (1-alpha)*fy*w",
            "force (e.g. kN)",
            POSITIVE,
        ),
        Param("alpha", "post-yield to initial stiffness ratio", "-", within(0.0, 0.99)),
        Param(
            "n0",
            "transition sharpness after no (or a tiny) previous excursion",
            "-",
            within(0.5, 200.0),
        ),
        Param(
            "n_min",
            "transition sharpness after a very long previous excursion (<= n0)",
            "-",
            within(0.5, 200.0),
        ),
        Param("xi0", "previous plastic travel (in dy) halving n0 - n_min", "-", POSITIVE),
        Param(
            "a",
            "isotropic hardening: strength factor 1 + a*(half range/dy)**p",
            "-",
            NON_NEGATIVE,
            0.0,
        ),
        Param("p", "exponent of the isotropic hardening", "-", within(0.05, 4.0), 1.0),
        Param(
            "c",
            "origin of the transition: 0 at w = 0 (beta = gamma), 1 at the opposite bound",
            "-",
            Bound(low=0.0, high=1.0, high_open=False),
            0.0,
        ),
    )
    STATE = ExcursionBoucWenState

    k0: float
    fy: float
    alpha: float
    n0: float
    n_min: float
    xi0: float
    a: float
    p: float
    c: float

    def __init__(
        self,
        *,
        k0: float,
        fy: float,
        alpha: float,
        n0: float,
        n_min: float,
        xi0: float,
        a: float = 0.0,
        p: float = 1.0,
        c: float = 0.0,
        dz_max: float = DEFAULT_DZ_MAX,
    ) -> None:
        self._init_params(k0=k0, fy=fy, alpha=alpha, n0=n0, n_min=n_min, xi0=xi0, a=a, p=p, c=c)
        self.dz_max = DZ_MAX.check(self.name, dz_max)
        self._start()

    def _check_relations(self) -> None:
        if self.n_min > self.n0:
            raise ModelParameterError(
                self.name, f"n_min must be <= n0, got {self.n_min!r} > {self.n0!r}", "n_min"
            )

    def _settings(self) -> dict[str, float]:
        return {"dz_max": self.dz_max}

    def _virgin(self) -> tuple[float, ...]:
        return (0.0, 0.0, self.k0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0)

    @property
    def initial_tangent(self) -> float:
        return self.k0

    def set_trial(self, d: float) -> tuple[float, float]:
        c = self._committed
        if not math.isfinite(d):
            raise trial_input_error(self.name, d)
        if d == c[0]:
            self._trial = c
            return c[1], c[2]
        state = _step(
            self.k0,
            self.fy,
            self.alpha,
            self.n0,
            self.n_min,
            self.xi0,
            self.a,
            self.p,
            self.c,
            self.dz_max,
            c[0],
            c[3],
            c[4],
            c[5],
            c[6],
            c[7],
            c[8],
            d,
        )
        if not math.isfinite(state[1]):
            raise ModelInputError(
                f"{self.name}: trial step of {d - c[0]!r} needs more than {MAX_SUBSTEPS} "
                "substeps; check units of the displacement"
            )
        self._trial = state
        return state[1], state[2]

    def vector(self) -> FloatArray:
        """The parameters in :func:`drive`'s order."""
        return np.array([self.k0, self.fy, self.alpha, self.n0, self.n_min, self.xi0, self.a,
                         self.p, self.c], dtype=np.float64)  # fmt: skip


def drive(params: FloatArray, disp: FloatArray, dz_max: float = DEFAULT_DZ_MAX) -> FloatArray:
    """Force of a virgin law with ``params`` (k0, fy, alpha, n0, n_min, xi0, a, p, c) committed at
    every sample of ``disp``; the same kernel as the class, JIT-compiled; NaN from a refused
    step on."""
    return _drive(np.asarray(params, dtype=np.float64),
                  np.ascontiguousarray(disp, dtype=np.float64), float(dz_max))  # fmt: skip
