"""A rigid platform in the plane driven by two-point actuators: the geometry of every planar
OpenFresco setup, exact or linearised.

The platform's state is ``q = (x, y, θ)`` of its control point. Actuator ``i`` joins a ground
point ``g_i`` to a platform point ``p_i`` (given in the platform's frame, relative to the
control point at rest); its stroke is the change of that distance:

    s_i(q) = |c + R(θ) p_i − g_i| − La_i,      La_i = |p_i − g_i|.

Everything else follows from that one map, so the directions cannot disagree: the ctrl
velocity is ``J(q) q̇``, the acceleration ``J q̈ + q̇ᵀ H_i q̇``, the platform forces ``Jᵀ f``
(virtual work: ``Jᵀf · δq = f · δs``, exactly), and the platform state behind measured
strokes is found by Newton's method on ``s(q) = s_meas``. Linear geometry is the same map
linearised at rest (``s = J(0) q``). Degrees of freedom the actuators do not drive (the
vertical one of ``TwoActuators2d``) are held at zero, as OpenFresco does.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, field

import numpy as np
import numpy.typing as npt

Vec = npt.NDArray[np.float64]

NEWTON_MAX_ITERATIONS = 50
"""Newton's method on the strokes converges quadratically; a well-posed platform needs 3 to 6
iterations. More than this means the measured strokes have no platform state (an actuator
beyond its reach) or the platform is at a singular pose."""


class GeometryError(ValueError):
    """Measured strokes no platform state can produce, or a singular pose."""


@dataclass(frozen=True, slots=True)
class Link:
    """One actuator: ground point and platform point (platform frame), in length units."""

    ground: tuple[float, float]
    platform: tuple[float, float]

    @property
    def length(self) -> float:
        """The actuator's length at rest (OpenFresco's ``La``)."""
        return math.dist(self.ground, self.platform)


@dataclass(frozen=True)
class Platform:
    """A planar rigid platform on ``links``, moving in the DOFs ``driven`` of (x, y, θ)."""

    links: tuple[Link, ...]
    driven: tuple[int, ...] = (0, 1, 2)
    """Which of (x, y, θ) the actuators drive (in order); the others stay zero."""
    _p: Vec = field(init=False, repr=False, compare=False)
    _g: Vec = field(init=False, repr=False, compare=False)
    _la: Vec = field(init=False, repr=False, compare=False)
    _reach: float = field(init=False, repr=False, compare=False)
    _j0: Vec = field(init=False, repr=False, compare=False)

    def __post_init__(self) -> None:
        if len(self.links) != len(self.driven):
            raise GeometryError(f"{len(self.links)} actuators cannot drive "
                                f"{len(self.driven)} platform DOF(s) one to one")
        object.__setattr__(self, "_p", np.array([lk.platform for lk in self.links], float))
        object.__setattr__(self, "_g", np.array([lk.ground for lk in self.links], float))
        la = np.array([lk.length for lk in self.links], float)
        if not np.all(la > 0):
            raise GeometryError("an actuator of zero length (ground point = platform point)")
        object.__setattr__(self, "_la", la)
        object.__setattr__(self, "_reach", 0.1 * float(la.min()))
        j0 = self.jacobian(np.zeros(3))
        if abs(np.linalg.det(j0)) < 1e-12 * max(1.0, float(np.abs(j0).max())) ** 3:
            raise GeometryError("the actuators cannot hold the platform at rest (their "
                                "linearised map is singular: check the lengths)")
        object.__setattr__(self, "_j0", j0)

    @property
    def n_actuators(self) -> int:
        return len(self.links)

    # -- the map and its derivatives ----------------------------------------------------------
    def _arms(self, q: Vec) -> tuple[Vec, Vec]:
        """(w, r): the platform points rotated (``R(θ) p``) and the actuator vectors."""
        c, s = math.cos(q[2]), math.sin(q[2])
        p = self._p
        w = np.column_stack((c * p[:, 0] - s * p[:, 1], s * p[:, 0] + c * p[:, 1]))
        r = w + q[:2] - self._g
        return w, r

    def strokes(self, q: Vec) -> Vec:
        """Exact strokes at platform state ``q`` (x, y, θ)."""
        _, r = self._arms(q)
        out: Vec = np.hypot(r[:, 0], r[:, 1]) - self._la
        return out

    def jacobian(self, q: Vec) -> Vec:
        """∂s/∂q for the driven DOFs (n_actuators × n_driven)."""
        w, r = self._arms(q)
        e = r / np.hypot(r[:, 0], r[:, 1])[:, None]
        full = np.column_stack((e[:, 0], e[:, 1], -e[:, 0] * w[:, 1] + e[:, 1] * w[:, 0]))
        out: Vec = full[:, list(self.driven)]
        return out

    def rates(self, q: Vec, qd: Vec, qdd: Vec) -> tuple[Vec, Vec]:
        """(ṡ, s̈) at state ``q`` with platform velocity ``qd`` and acceleration ``qdd``."""
        w, r = self._arms(q)
        length = np.hypot(r[:, 0], r[:, 1])
        e = r / length[:, None]
        perp = np.column_stack((-w[:, 1], w[:, 0]))  # d(R p)/dθ
        rd = qd[:2] + qd[2] * perp
        rdd = qdd[:2] + qdd[2] * perp - qd[2] ** 2 * w
        sd = np.einsum("ij,ij->i", e, rd)
        sdd = np.einsum("ij,ij->i", e, rdd) + (np.einsum("ij,ij->i", rd, rd) - sd**2) / length
        return sd, sdd

    # -- the linearised map -------------------------------------------------------------------
    @property
    def linear(self) -> Vec:
        """J(0): strokes per unit platform motion at rest (linear geometry)."""
        return self._j0

    # -- the inverse --------------------------------------------------------------------------
    def state(self, strokes: Vec, start: Vec | None = None) -> Vec:
        """The platform state (x, y, θ) whose exact strokes are ``strokes`` (Newton's method
        from ``start``, or from the linear-geometry state).

        Several poses can have the same strokes (assembly modes); the platform's is the one
        reached from rest without passing a singular pose, so ``det J`` keeps its sign at rest.
        A solution of another mode is refused and sought again from the linear estimate.
        """
        for begin in (start, None) if start is not None else (None,):
            q = self._newton(strokes, begin)
            if np.linalg.det(self.jacobian(q)) * np.linalg.det(self._j0) > 0:
                return q
        raise GeometryError(f"the measured strokes {strokes.tolist()} put the platform in "
                            "another assembly mode (past a singular pose)")

    def _newton(self, strokes: Vec, start: Vec | None) -> Vec:
        d = list(self.driven)
        q = np.zeros(3)
        q[d] = np.linalg.solve(self._j0, strokes) if start is None else start[d]
        near = q[2]
        # the strokes are lengths La + s: their rounding is a few ulps of the longest length
        floor = 8 * np.finfo(float).eps * (float(self._la.max()) + float(np.abs(strokes).max()))
        previous = math.inf
        for _ in range(NEWTON_MAX_ITERATIONS):
            residual = self.strokes(q) - strokes
            size = float(np.abs(residual).max())
            if size <= floor or (size >= previous and size <= 1e3 * floor):
                # at the rounding floor (or no longer improving just above it); of the
                # rotations 2π apart, the one nearest the start
                q[2] -= 2 * math.pi * round((q[2] - near) / (2 * math.pi))
                return q
            previous = size
            try:
                step = np.linalg.solve(self.jacobian(q), residual)
            except np.linalg.LinAlgError:
                raise GeometryError(f"singular platform pose at {q.tolist()}") from None
            full = np.zeros(3)
            full[d] = step
            # damped: at most a tenth of a radian and a tenth of the shortest actuator per
            # iteration, so Newton stays in the basin of the pose it starts from
            reach = max(abs(full[2]) / 0.1, float(np.abs(full[:2]).max()) / self._reach, 1.0)
            q -= full / reach
            if not np.all(np.isfinite(q)):
                break
        raise GeometryError(f"no platform state has the measured strokes {strokes.tolist()} "
                            f"(Newton's method did not converge in {NEWTON_MAX_ITERATIONS} "
                            "iterations)")


def links(pairs: Sequence[tuple[tuple[float, float], tuple[float, float]]]) -> tuple[Link, ...]:
    """``((ground, platform), …)`` as links."""
    return tuple(Link(g, p) for g, p in pairs)
