"""A planar OpenFresco setup: which trial components are the platform's (x, y, θ), the local
axes' rotation (``phiLocX``), linear or exact geometry, and the platform of actuators.

Under linear geometry every direction is the constant ``J(0)``. Under ``nlGeom`` trial → ctrl
is exact for displacement, velocity and acceleration, and daq → out is exact for displacement
and force (the platform state from the measured strokes by Newton's method, forces by virtual
work). OpenFresco has no exact daq → out velocity or acceleration: it warns and uses linear
geometry; so do we (one warning per setup, in the log).

The step path asks the same things several times (a force and a displacement of one
measurement, the stiffness of one controller answer), so each answer is kept for its input;
measured strokes equal to the last command put the platform where it was commanded, and
other strokes start Newton's method there (a tracking error away: one or two iterations).
"""

from __future__ import annotations

import logging
import math

from .base import SetupError, Values
from .platform import GeometryError, Platform, Rows, Vec

log = logging.getLogger(__name__)

NAN3 = (math.nan, math.nan, math.nan)


class PlanarSetup:
    """``kind`` with ``platform`` on trial components ``dofs`` (x, y, θ) of ``n_basic``."""

    identity = False

    def __init__(self, kind: str, platform: Platform, n_basic: int,
                 dofs: tuple[int, int, int] = (0, 1, 2), *, nl_geom: bool = False,
                 phi_loc_x: float = 0.0) -> None:
        if len(set(dofs)) != 3 or min(dofs) < 0 or max(dofs) >= n_basic:
            raise SetupError(f"{kind}: the platform DOFs {[d + 1 for d in dofs]} must be three "
                             f"different DOFs of the element's {n_basic}")
        self.kind = kind
        self.platform = platform
        self.n_basic = n_basic
        self.n_actuators = platform.n_actuators
        self.dofs = dofs
        self.nl_geom = nl_geom
        phi = math.radians(phi_loc_x)
        self._c, self._s = math.cos(phi), math.sin(phi)
        self._driven = platform.driven
        self._held = tuple(i not in platform.driven for i in range(3))
        self._direct = dofs == (0, 1, 2) and n_basic == 3 and phi == 0.0 \
            and not any(self._held)
        """The trial is the platform's local state as it is (the usual column)."""
        # the linear transformation trial → ctrl: J(0) · (drop undriven) · R(phi) · select
        columns = []
        for k in range(n_basic):
            unit = [0.0] * n_basic
            unit[k] = 1.0
            q = self._local(unit)
            columns.append(tuple(sum(r * q[i] for r, i in zip(row, self._driven, strict=True))
                                 for row in platform.linear))
        self._linear_rows = platform.pose((0.0, 0.0, 0.0))[1]
        self.t: Rows = tuple(tuple(col[a] for col in columns) for a in range(self.n_actuators))
        """The linear transformation, row by row (trial → ctrl)."""
        self._commanded: tuple[Values, Vec, Rows] | None = None
        """(ctrl, platform state, Jacobian rows) of the last trial."""
        self._trial: tuple[Values, Values] | None = None  # (trial, ctrl)
        self._force: tuple[Values, Values | None, Values] | None = None  # (f, daq, out)
        self._measured: tuple[Values, Vec] | None = None  # (daq, platform state)
        self._jacobian: tuple[Values, Rows] | None = None  # (daq, Jacobian rows)
        self._matrix: tuple[Values, Values] | None = None
        self._warned = False

    # -- trial → ctrl -------------------------------------------------------------------------
    def _local(self, trial: Values | list[float]) -> Vec:
        """The platform's local (x, y, θ) of a trial vector (undriven DOFs zero)."""
        if self._direct:
            return tuple(trial)
        d0, d1, d2 = self.dofs
        x, y = trial[d0], trial[d1]
        q = (self._c * x - self._s * y, self._s * x + self._c * y, trial[d2])
        held = self._held
        return (0.0 if held[0] else q[0], 0.0 if held[1] else q[1], 0.0 if held[2] else q[2])

    def _linear(self, trial: Values) -> Values:
        return tuple(sum(a * b for a, b in zip(row, trial, strict=True)) for row in self.t)

    def ctrl_disp(self, trial_disp: Values) -> Values:
        last = self._trial
        if last is not None and last[0] == trial_disp:
            return last[1]  # Newton's iterations often send a trial again
        if not self.nl_geom:
            ctrl = self._linear(trial_disp)
            self._trial = (trial_disp, ctrl)
            return ctrl
        q = trial_disp if self._direct else self._local(trial_disp)
        ctrl, rows = self.platform.pose(q)
        self._commanded = (ctrl, q, rows)
        self._trial = (trial_disp, ctrl)
        return ctrl

    def ctrl_vel(self, trial_disp: Values, trial_vel: Values) -> Values:
        if not self.nl_geom:
            return self._linear(trial_vel)
        zero = (0.0, 0.0, 0.0)
        return self.platform.rates(self._local(trial_disp), self._local(trial_vel), zero)[0]

    def ctrl_accel(self, trial_disp: Values, trial_vel: Values, trial_accel: Values) -> Values:
        if not self.nl_geom:
            return self._linear(trial_accel)
        return self.platform.rates(self._local(trial_disp), self._local(trial_vel),
                                   self._local(trial_accel))[1]

    # -- daq → out ----------------------------------------------------------------------------
    def _state(self, daq_disp: Values) -> Vec:
        """The platform's local state behind measured strokes."""
        measured = self._measured
        if measured is not None and measured[0] == daq_disp:
            return measured[1]
        if not self.nl_geom:
            q: Vec = tuple(self.platform.linear_state(daq_disp))
        elif self._commanded is not None and self._commanded[0] == daq_disp:
            q = self._commanded[1]  # the strokes commanded: the platform where commanded
        else:
            start = (self._commanded or measured or (None, None))[1]
            try:
                q = self.platform.state(daq_disp, start)
            except GeometryError as exc:
                log.warning("%s: %s; the answer is NaN", self.kind, exc)
                q = NAN3
        self._measured = (daq_disp, q)
        return q

    def _out(self, local: Vec | list[float]) -> Values:
        """A local platform vector as the element's out vector: rotated back, placed."""
        if self._direct:
            return tuple(local)
        c, s = self._c, self._s
        out = [0.0] * self.n_basic
        d0, d1, d2 = self.dofs
        out[d0] = c * local[0] + s * local[1]
        out[d1] = -s * local[0] + c * local[1]
        out[d2] = local[2]
        return tuple(out)

    def out_disp(self, trial_disp: Values, ctrl: Values, daq_disp: Values) -> Values:
        return self._out(self._state(daq_disp))

    def _linear_out(self, daq: Values, what: str) -> Values:
        if self.nl_geom and not self._warned:
            self._warned = True
            log.warning("%s: daq %s under nonlinear geometry uses linear geometry (as "
                        "OpenFresco does)", self.kind, what)
        return self._out(self.platform.linear_state(daq))

    def out_vel(self, daq_vel: Values) -> Values:
        return self._linear_out(daq_vel, "velocity")

    def out_accel(self, daq_accel: Values) -> Values:
        return self._linear_out(daq_accel, "acceleration")

    def basic_force(self, daq_force: Values, daq_disp: Values | None = None) -> Values:
        """Platform forces by virtual work, ``Jᵀ f`` at the measured state (linear: J(0))."""
        last = self._force
        if last is not None and last[0] == daq_force and last[1] == daq_disp:
            return last[2]
        if not self.nl_geom or daq_disp is None:
            rows = self._linear_rows
        elif self._commanded is not None and self._commanded[0] == daq_disp:
            rows = self._commanded[2]
        elif self._jacobian is not None and self._jacobian[0] == daq_disp:
            rows = self._jacobian[1]
        else:
            rows = self.platform.pose(self._state(daq_disp))[1]
            self._jacobian = (daq_disp, rows)
        fx = fy = m = 0.0
        for (ex, ey, em), f in zip(rows, daq_force, strict=True):
            fx += f * ex
            fy += f * ey
            m += f * em
        held = self._held
        out = self._out((0.0 if held[0] else fx, 0.0 if held[1] else fy,
                         0.0 if held[2] else m))
        self._force = (daq_force, daq_disp, out)
        return out

    def basic_matrix(self, k_act: Values) -> Values:
        """Tᵀ k T with the linear transformation (the tangent at rest), column-major."""
        cached = self._matrix
        if cached is not None and cached[0] == k_act:
            return cached[1]
        na, nb, t = self.n_actuators, self.n_basic, self.t
        kt = [[sum(k_act[b * na + a] * t[b][c] for b in range(na)) for c in range(nb)]
              for a in range(na)]  # k T
        out = tuple(sum(t[a][r] * kt[a][c] for a in range(na))
                    for c in range(nb) for r in range(nb))
        self._matrix = (k_act, out)
        return out
