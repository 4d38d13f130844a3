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

Plain Python on tuples: with two or three actuators that is several times faster than numpy's
per-call overhead, and the site calls this on every trial and answer.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, field

Vec = tuple[float, ...]
Rows = tuple[tuple[float, ...], ...]

NEWTON_MAX_ITERATIONS = 50
"""Newton's method on the strokes converges quadratically; a well-posed platform needs 2 to 6
iterations. More than this means the measured strokes have no platform state (an actuator
beyond its reach) or the platform is at a singular pose."""
EPS = 2.220446049250313e-16
_cos, _sin, _hypot = math.cos, math.sin, math.hypot


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


def solve(a: Rows, b: Vec) -> tuple[Vec, float]:
    """``(x, det a)`` with ``a x = b`` (Gaussian elimination, partial pivoting; n ≤ 3)."""
    n = len(b)
    m = [[*row, rhs] for row, rhs in zip(a, b, strict=True)]
    det = 1.0
    for col in range(n):
        pivot = max(range(col, n), key=lambda r: abs(m[r][col]))
        if m[pivot][col] == 0.0:
            raise GeometryError("singular platform pose (the actuators are aligned)")
        if pivot != col:
            m[col], m[pivot] = m[pivot], m[col]
            det = -det
        det *= m[col][col]
        for r in range(col + 1, n):
            factor = m[r][col] / m[col][col]
            if factor:
                m[r] = [x - factor * y for x, y in zip(m[r], m[col], strict=True)]
    x = [0.0] * n
    for r in range(n - 1, -1, -1):
        x[r] = (m[r][n] - sum(m[r][c] * x[c] for c in range(r + 1, n))) / m[r][r]
    return tuple(x), det


@dataclass(frozen=True)
class Platform:
    """A planar rigid platform on ``links``, moving in the DOFs ``driven`` of (x, y, θ)."""

    links: tuple[Link, ...]
    driven: tuple[int, ...] = (0, 1, 2)
    """Which of (x, y, θ) the actuators drive (in order); the others stay zero."""
    _la: Vec = field(init=False, repr=False, compare=False)
    _j0: Rows = field(init=False, repr=False, compare=False)
    _det0: float = field(init=False, repr=False, compare=False)
    _reach: float = field(init=False, repr=False, compare=False)
    _geometry: tuple[tuple[float, float, float, float, float], ...] = field(
        init=False, repr=False, compare=False)
    """Per actuator (px, py, gx, gy, La), flat for the step path."""

    def __post_init__(self) -> None:
        if len(self.links) != len(self.driven):
            raise GeometryError(f"{len(self.links)} actuators cannot drive "
                                f"{len(self.driven)} platform DOF(s) one to one")
        la = tuple(lk.length for lk in self.links)
        if min(la) <= 0:
            raise GeometryError("an actuator of zero length (ground point = platform point)")
        object.__setattr__(self, "_la", la)
        object.__setattr__(self, "_geometry", tuple(
            (*lk.platform, *lk.ground, length) for lk, length in zip(self.links, la, strict=True)))
        object.__setattr__(self, "_reach", 0.1 * min(la))
        j0 = self.jacobian((0.0, 0.0, 0.0))
        scale = max(abs(x) for row in j0 for x in row)
        try:
            det = solve(j0, (0.0,) * len(j0))[1]
        except GeometryError:
            det = 0.0
        if abs(det) < 1e-12 * max(1.0, scale) ** len(j0):
            raise GeometryError("the actuators cannot hold the platform at rest (their "
                                "linearised map is singular: check the lengths)")
        object.__setattr__(self, "_j0", j0)
        object.__setattr__(self, "_det0", det)

    @property
    def n_actuators(self) -> int:
        return len(self.links)

    # -- the map and its derivatives ----------------------------------------------------------
    def _arms(self, q: Sequence[float]) -> list[tuple[float, float, float, float]]:
        """Per actuator (wx, wy, rx, ry): the platform point rotated (``R(θ) p``) and the
        actuator vector."""
        c, s = math.cos(q[2]), math.sin(q[2])
        x, y = q[0], q[1]
        return [(c * px - s * py, s * px + c * py, x + c * px - s * py - gx,
                 y + s * px + c * py - gy) for px, py, gx, gy, _ in self._geometry]

    def pose(self, q: Sequence[float]) -> tuple[Vec, Rows]:
        """(strokes, full Jacobian rows ∂s/∂(x, y, θ)) at ``q``, in one pass."""
        c, s = _cos(q[2]), _sin(q[2])
        x, y = q[0], q[1]
        strokes = []
        rows = []
        for px, py, gx, gy, la in self._geometry:
            wx = c * px - s * py
            wy = s * px + c * py
            rx = x + wx - gx
            ry = y + wy - gy
            length = _hypot(rx, ry)
            strokes.append(length - la)
            ex = rx / length
            ey = ry / length
            rows.append((ex, ey, ey * wx - ex * wy))
        return tuple(strokes), tuple(rows)

    def strokes(self, q: Sequence[float]) -> Vec:
        """Exact strokes at platform state ``q`` (x, y, θ)."""
        c, s = math.cos(q[2]), math.sin(q[2])
        x, y = q[0], q[1]
        return tuple(math.hypot(x + c * px - s * py - gx, y + s * px + c * py - gy) - la
                     for px, py, gx, gy, la in self._geometry)

    def jacobian(self, q: Sequence[float]) -> Rows:
        """∂s/∂q for the driven DOFs (n_actuators rows)."""
        driven = self.driven
        return tuple(tuple(row[i] for i in driven) for row in self.pose(q)[1])

    def rates(self, q: Sequence[float], qd: Sequence[float],
              qdd: Sequence[float]) -> tuple[Vec, Vec]:
        """(ṡ, s̈) at state ``q`` with platform velocity ``qd`` and acceleration ``qdd``."""
        sd, sdd = [], []
        for wx, wy, rx, ry in self._arms(q):
            length = math.hypot(rx, ry)
            ex, ey = rx / length, ry / length
            # d(R p)/dθ = (−wy, wx); d²(R p)/dθ² = −(wx, wy)
            rdx, rdy = qd[0] - qd[2] * wy, qd[1] + qd[2] * wx
            rddx = qdd[0] - qdd[2] * wy - qd[2] ** 2 * wx
            rddy = qdd[1] + qdd[2] * wx - qd[2] ** 2 * wy
            v = ex * rdx + ey * rdy
            sd.append(v)
            sdd.append(ex * rddx + ey * rddy + (rdx * rdx + rdy * rdy - v * v) / length)
        return tuple(sd), tuple(sdd)

    # -- the linearised map -------------------------------------------------------------------
    @property
    def linear(self) -> Rows:
        """J(0): strokes per unit platform motion at rest (linear geometry)."""
        return self._j0

    def linear_state(self, strokes: Vec) -> list[float]:
        """The platform state of ``strokes`` under linear geometry."""
        q = [0.0, 0.0, 0.0]
        for i, v in zip(self.driven, solve(self._j0, strokes)[0], strict=True):
            q[i] = v
        return q

    # -- the inverse --------------------------------------------------------------------------
    def state(self, strokes: Vec, start: Sequence[float] | None = None) -> Vec:
        """The platform state (x, y, θ) whose exact strokes are ``strokes`` (Newton's method
        from ``start``, or from the linear-geometry state).

        Several poses can have the same strokes (assembly modes); the platform's is the one
        reached from rest without passing a singular pose, so ``det J`` keeps its sign at rest.
        A solution of another mode is refused and sought again from the linear estimate.
        """
        for begin in (start, None) if start is not None else (None,):
            q, det = self._newton(strokes, begin)
            if det * self._det0 > 0:
                return q
        raise GeometryError(f"the measured strokes {list(strokes)} put the platform in "
                            "another assembly mode (past a singular pose)")

    def _newton(self, strokes: Vec, start: Sequence[float] | None) -> tuple[Vec, float]:
        q = self.linear_state(strokes) if start is None else list(start)
        near = q[2]
        # the strokes are lengths La + s: their rounding is a few ulps of the longest length
        floor = 8 * EPS * (max(self._la) + max(abs(v) for v in strokes))
        previous = math.inf
        for _ in range(NEWTON_MAX_ITERATIONS):
            residual = tuple(a - b for a, b in zip(self.strokes(q), strokes, strict=True))
            size = max(abs(v) for v in residual)
            j = self.jacobian(q)
            if size <= floor or (size >= previous and size <= 1e3 * floor):
                # at the rounding floor (or no longer improving just above it); of the
                # rotations 2π apart, the one nearest the start
                q[2] -= 2 * math.pi * round((q[2] - near) / (2 * math.pi))
                return tuple(q), solve(j, residual)[1]
            previous = size
            step, _ = solve(j, residual)
            full = [0.0, 0.0, 0.0]
            for i, v in zip(self.driven, step, strict=True):
                full[i] = v
            # damped: at most a tenth of a radian and a tenth of the shortest actuator per
            # iteration, so Newton stays in the basin of the pose it starts from
            reach = max(abs(full[2]) / 0.1, max(abs(full[0]), abs(full[1])) / self._reach, 1.0)
            q = [a - b / reach for a, b in zip(q, full, strict=True)]
            if not all(math.isfinite(v) for v in q):
                break
        raise GeometryError(f"no platform state has the measured strokes {list(strokes)} "
                            f"(Newton's method did not converge in {NEWTON_MAX_ITERATIONS} "
                            "iterations)")

