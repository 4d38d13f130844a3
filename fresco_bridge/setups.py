"""Setups: the kinematic map between an element's basic DOFs and the actuators.

OpenFresco's experimental setups transform *trial* signals (basic DOFs of the element) into
*ctrl* signals (actuator commands) and *daq* signals back into *out* signals. Both setups we
ship are linear, ``ctrl = T · trial``: ``NoTransformation`` (T = I) and ``OneActuator`` (one
actuator along the element: stroke = u_j − u_i for a two-node element, forces equal and
opposite). Forces go back as ``q = Tᵀ · f`` and stiffness as ``K = Tᵀ · k · T``.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Literal

SetupKind = Literal["NoTransformation", "OneActuator"]


class SetupError(ValueError):
    """The setup cannot serve an element of this size."""


@dataclass(frozen=True, slots=True)
class LinearSetup:
    """``ctrl = T · trial`` with T of shape (n_actuators, n_basic), stored row by row."""

    kind: SetupKind
    n_basic: int
    n_actuators: int
    t: tuple[tuple[float, ...], ...]

    def ctrl_disp(self, trial_disp: tuple[float, ...]) -> tuple[float, ...]:
        return tuple(sum(c * u for c, u in zip(row, trial_disp, strict=True)) for row in self.t)

    def basic_force(self, daq_force: tuple[float, ...]) -> tuple[float, ...]:
        n = self.n_basic
        return tuple(
            sum(self.t[a][i] * daq_force[a] for a in range(self.n_actuators)) for i in range(n)
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
        na, nb, t = self.n_actuators, self.n_basic, self.t
        out: list[float] = []
        for c in range(nb):
            for r in range(nb):
                s = 0.0
                for a in range(na):
                    tra = t[a][r]
                    if tra == 0.0:
                        continue
                    for b in range(na):
                        s += tra * k_act[b * na + a] * t[b][c]
                out.append(s)
        return tuple(out)


def make_setup(kind: SetupKind, n_basic: int) -> LinearSetup:
    """Build the setup for an element with ``n_basic`` basic DOFs."""
    if n_basic < 1:
        raise SetupError(f"{kind}: the element must have at least one basic DOF, got {n_basic}")
    if kind == "NoTransformation":
        eye = tuple(tuple(1.0 if i == j else 0.0 for j in range(n_basic)) for i in range(n_basic))
        return LinearSetup(kind, n_basic, n_basic, eye)
    if kind == "OneActuator":
        if n_basic == 1:
            return LinearSetup(kind, 1, 1, ((1.0,),))
        if n_basic == 2:
            return LinearSetup(kind, 2, 1, ((-1.0, 1.0),))
        raise SetupError(
            f"OneActuator drives a grounded 1-DOF element or a two-node element with one DOF "
            f"per node (-dof 1 -dof 1); this element has {n_basic} basic DOFs"
        )
    raise SetupError(f"unknown setup {kind!r}; expected NoTransformation or OneActuator")
