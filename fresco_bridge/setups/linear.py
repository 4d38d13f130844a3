"""The linear setups ``ctrl = T · trial``: ``NoTransformation`` (T = I) and ``OneActuator``
(one actuator along basic DOF ``dir``, or along a two-node element: stroke = u_j − u_i,
forces equal and opposite). Forces go back as ``q = Tᵀ · f`` and stiffness as
``K = Tᵀ · k · T``; velocities and accelerations transform as displacements.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Literal

import numpy as np
import numpy.typing as npt

from .base import SetupError

SetupKind = Literal["NoTransformation", "OneActuator"]


@dataclass(frozen=True, slots=True)
class LinearSetup:
    """``ctrl = T · trial`` with T of shape (n_actuators, n_basic), stored row by row.

    The geometry never changes during a run, so what each transform needs is derived once:
    an identity T (``NoTransformation``) makes every transform a pass-through (nothing to
    compute at any size), any other T is held as an array too, so ``Tᵀ k T`` is one BLAS
    product instead of an O(n³) Python loop.
    """

    kind: SetupKind
    n_basic: int
    n_actuators: int
    t: tuple[tuple[float, ...], ...]
    identity: bool = field(init=False)
    _t: npt.NDArray[np.float64] = field(init=False, repr=False, compare=False)

    def __post_init__(self) -> None:
        t = np.array(self.t, dtype=np.float64).reshape(self.n_actuators, self.n_basic)
        object.__setattr__(self, "_t", t)
        object.__setattr__(self, "identity", self.n_actuators == self.n_basic
                           and bool(np.array_equal(t, np.eye(self.n_basic))))

    def ctrl_disp(self, trial_disp: tuple[float, ...]) -> tuple[float, ...]:
        if self.identity:
            return trial_disp
        return tuple(sum(c * u for c, u in zip(row, trial_disp, strict=True)) for row in self.t)

    def ctrl_vel(self, trial_disp: tuple[float, ...],
                 trial_vel: tuple[float, ...]) -> tuple[float, ...]:
        return self.ctrl_disp(trial_vel)

    def ctrl_accel(self, trial_disp: tuple[float, ...], trial_vel: tuple[float, ...],
                   trial_accel: tuple[float, ...]) -> tuple[float, ...]:
        return self.ctrl_disp(trial_accel)

    def out_vel(self, daq_vel: tuple[float, ...]) -> tuple[float, ...]:
        return self._pseudo_inverse(daq_vel)

    def out_accel(self, daq_accel: tuple[float, ...]) -> tuple[float, ...]:
        return self._pseudo_inverse(daq_accel)

    def _pseudo_inverse(self, daq: tuple[float, ...]) -> tuple[float, ...]:
        if self.identity:
            return daq
        out: list[float] = (np.linalg.pinv(self._t) @ np.asarray(daq, float)).tolist()
        return tuple(out)

    def basic_force(self, daq_force: tuple[float, ...],
                    daq_disp: tuple[float, ...] | None = None) -> tuple[float, ...]:
        if self.identity:
            return daq_force
        t = self.t
        return tuple(
            sum(t[a][i] * daq_force[a] for a in range(self.n_actuators))
            for i in range(self.n_basic)
        )

    def out_disp(
        self, trial_disp: tuple[float, ...], ctrl: tuple[float, ...], daq: tuple[float, ...]
    ) -> tuple[float, ...]:
        """Measured basic displacements: the trial corrected by the actuator tracking error."""
        if self.kind == "NoTransformation":
            return daq
        # OneActuator: spread the stroke error along the actuator direction (pseudo-inverse).
        row = self.t[0]
        norm2 = sum(c * c for c in row)
        err = daq[0] - ctrl[0]
        return tuple(u + c * err / norm2 for u, c in zip(trial_disp, row, strict=True))

    def basic_matrix(self, k_act: tuple[float, ...]) -> tuple[float, ...]:
        """Tᵀ k T, with ``k_act`` and the result column-major (the wire order)."""
        if self.identity:
            return k_act
        na, t = self.n_actuators, self._t
        k = np.array(k_act, dtype=np.float64).reshape(na, na, order="F")
        out: list[float] = (t.T @ k @ t).ravel(order="F").tolist()
        return tuple(out)


def make_linear(kind: SetupKind, n_basic: int, direction: int | None = None) -> LinearSetup:
    """Build the setup for an element with ``n_basic`` basic DOFs (``direction``: OneActuator
    along that basic DOF, 1-based, as OpenFresco's ``$dir``)."""
    if n_basic < 1:
        raise SetupError(f"{kind}: the element must have at least one basic DOF, got {n_basic}")
    if kind == "NoTransformation":
        eye = tuple(tuple(1.0 if i == j else 0.0 for j in range(n_basic)) for i in range(n_basic))
        return LinearSetup(kind, n_basic, n_basic, eye)
    if kind == "OneActuator":
        if direction is not None:
            if not 1 <= direction <= n_basic:
                raise SetupError(f"OneActuator: dir = {direction} is not a basic DOF of the "
                                 f"element (1 to {n_basic})")
            return LinearSetup(kind, n_basic, 1, (tuple(
                1.0 if i == direction - 1 else 0.0 for i in range(n_basic)),))
        if n_basic == 1:
            return LinearSetup(kind, 1, 1, ((1.0,),))
        if n_basic == 2:
            return LinearSetup(kind, 2, 1, ((-1.0, 1.0),))
        raise SetupError(
            f"OneActuator drives a grounded 1-DOF element or a two-node element with one DOF "
            f"per node (-dof 1 -dof 1), or give dir; this element has {n_basic} basic DOFs"
        )
    raise SetupError(f"unknown setup {kind!r}; expected NoTransformation or OneActuator")
