"""A planar OpenFresco setup: which trial components are the platform's (x, y, θ), the local
axes' rotation (``phiLocX``), linear or exact geometry, and the platform of actuators.

Under linear geometry every direction is the constant ``J(0)``. Under ``nlGeom`` trial → ctrl
is exact for displacement, velocity and acceleration, and daq → out is exact for displacement
and force (the platform state from the measured strokes by Newton's method, forces by virtual
work). OpenFresco has no exact daq → out velocity or acceleration: it warns and uses linear
geometry; so do we (one warning per setup, in the log).
"""

from __future__ import annotations

import logging
import math

import numpy as np

from .base import SetupError, Values
from .platform import GeometryError, Platform, Vec

log = logging.getLogger(__name__)


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
        self._driven = list(platform.driven)
        self._j0 = platform.linear
        # trial (n_basic) → local platform DOFs (3): select, rotate, drop the undriven ones
        select = np.zeros((3, n_basic))
        for row, col in enumerate(dofs):
            select[row, col] = 1.0
        rot = np.array([[self._c, -self._s, 0.0], [self._s, self._c, 0.0], [0.0, 0.0, 1.0]])
        held = np.diag([1.0 if i in self._driven else 0.0 for i in range(3)])
        self._to_local = held @ rot @ select
        self._t = self._j0 @ self._to_local[self._driven]
        """The linear transformation, trial → ctrl (n_actuators × n_basic)."""
        self._back = select.T @ rot.T
        """Local platform vector (3) → out vector (n_basic): rotate back, place."""
        self._j0_inv = np.linalg.inv(self._j0)
        self._last: tuple[Values, Vec] | None = None
        self._warned = False

    # -- trial → ctrl -------------------------------------------------------------------------
    def _local(self, trial: Values) -> Vec:
        out: Vec = self._to_local @ np.asarray(trial, dtype=np.float64)
        return out

    def ctrl_disp(self, trial_disp: Values) -> Values:
        if not self.nl_geom:
            return tuple((self._t @ np.asarray(trial_disp, dtype=np.float64)).tolist())
        return tuple(self.platform.strokes(self._local(trial_disp)).tolist())

    def ctrl_vel(self, trial_disp: Values, trial_vel: Values) -> Values:
        if not self.nl_geom:
            return self.ctrl_disp(trial_vel)
        q, qd = self._local(trial_disp), self._local(trial_vel)
        return tuple(self.platform.rates(q, qd, np.zeros(3))[0].tolist())

    def ctrl_accel(self, trial_disp: Values, trial_vel: Values, trial_accel: Values) -> Values:
        if not self.nl_geom:
            return self.ctrl_disp(trial_accel)
        q, qd, qdd = self._local(trial_disp), self._local(trial_vel), self._local(trial_accel)
        return tuple(self.platform.rates(q, qd, qdd)[1].tolist())

    # -- daq → out ----------------------------------------------------------------------------
    def _state(self, daq_disp: Values) -> Vec:
        """The platform's local state behind measured strokes (cached: disp and force ask
        for the same one each step; Newton starts from the previous state)."""
        last = self._last
        if last is not None and last[0] == daq_disp:
            return last[1]
        s = np.asarray(daq_disp, dtype=np.float64)
        if self.nl_geom:
            try:
                q = self.platform.state(s, None if last is None else last[1])
            except GeometryError:
                try:
                    q = self.platform.state(s)  # from the linear estimate (a far jump)
                except GeometryError as exc:
                    log.warning("%s: %s; the answer is NaN", self.kind, exc)
                    q = np.full(3, np.nan)
        else:
            q = np.zeros(3)
            q[self._driven] = self._j0_inv @ s
        self._last = (daq_disp, q)
        return q

    def _out(self, local: Vec) -> Values:
        return tuple((self._back @ local).tolist())

    def out_disp(self, trial_disp: Values, ctrl: Values, daq_disp: Values) -> Values:
        return self._out(self._state(daq_disp))

    def _linear_out(self, daq: Values, what: str) -> Values:
        if self.nl_geom and not self._warned:
            self._warned = True
            log.warning("%s: daq %s under nonlinear geometry uses linear geometry (as "
                        "OpenFresco does)", self.kind, what)
        q = np.zeros(3)
        q[self._driven] = self._j0_inv @ np.asarray(daq, dtype=np.float64)
        return self._out(q)

    def out_vel(self, daq_vel: Values) -> Values:
        return self._linear_out(daq_vel, "velocity")

    def out_accel(self, daq_accel: Values) -> Values:
        return self._linear_out(daq_accel, "acceleration")

    def basic_force(self, daq_force: Values, daq_disp: Values | None = None) -> Values:
        """Platform forces by virtual work, ``Jᵀ f`` at the measured state (linear: J(0))."""
        if self.nl_geom and daq_disp is not None:
            j = self.platform.jacobian(self._state(daq_disp))
        else:
            j = self._j0
        local = np.zeros(3)
        local[self._driven] = j.T @ np.asarray(daq_force, dtype=np.float64)
        return self._out(local)

    def basic_matrix(self, k_act: Values) -> Values:
        """Tᵀ k T with the linear transformation (the tangent at rest), column-major."""
        na = self.n_actuators
        k = np.array(k_act, dtype=np.float64).reshape(na, na, order="F")
        return tuple((self._t.T @ k @ self._t).ravel(order="F").tolist())

    @property
    def t(self) -> tuple[tuple[float, ...], ...]:
        """The linear transformation, row by row (trial → ctrl)."""
        return tuple(tuple(row) for row in self._t.tolist())
