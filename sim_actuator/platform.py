"""A specimen several actuators load together: a rigid platform whose geometry the caller gives.

The platform has n basic DOFs q (a column top's u, v, θ) and n actuators. Where the strokes put
the platform is the *geometry*'s business (:class:`Geometry`: the platform state behind some
strokes and the Jacobian ``J = ∂s/∂q`` there — linear or exact). The bridge hands its site's
setup geometry (``fresco_bridge/setups/``), so the rig's platform is the one the setup
transforms for: one home for the kinematics. The specimen is one uniaxial law per basic DOF,
``p_j(q_j)``; platform equilibrium by virtual work ``Jᵀ·f = p`` gives the actuator forces
``f = J⁻ᵀ·p``. So moving one actuator loads the others: the coupling a multi-actuator rig has.

Each actuator's rig drives the platform through :meth:`Platform.channel`, a ``SpecimenModel``
view: a trial moves that actuator's stroke with the others where they are (material semantics,
from the committed state), a commit makes it the platform's state. The rigs move one after the
other; :meth:`Platform.force` is any actuator's force in the current committed state.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Protocol

import numpy as np
import numpy.typing as npt

from sim_actuator.models import HysteresisModel

__all__ = ["Geometry", "Platform", "PlatformError"]

_MAX_CONDITION = 1e12


class PlatformError(ValueError):
    """The geometry does not fit the specimen laws, or strokes no platform state has."""


class Geometry(Protocol):
    """Where n actuator strokes put a platform of n basic DOFs."""

    @property
    def n_actuators(self) -> int: ...

    def state(self, strokes: Sequence[float]) -> tuple[tuple[float, ...],
                                                       tuple[tuple[float, ...], ...]]:
        """(q, J): the platform's basic DOFs behind ``strokes`` and ``∂s/∂q`` there (n×n, one
        row per actuator); ``ValueError`` for strokes no platform state has."""
        ...


class Platform:
    """n actuators on a rigid platform with n basic DOFs; see the module docstring."""

    def __init__(self, geometry: Geometry, laws: Sequence[HysteresisModel]) -> None:
        n = len(laws)
        if geometry.n_actuators != n:
            raise PlatformError(f"the platform has {geometry.n_actuators} actuators and "
                                f"{n} specimen laws: give one law per basic DOF")
        self.n = n
        self.geometry = geometry
        self.laws = list(laws)
        self._rows: object = None
        """The last J the geometry gave and its inverse (kept while the geometry gives the
        very same rows: a linear one)."""
        self._inv: npt.NDArray[np.float64] = np.eye(n)
        self._x = np.zeros(n)
        _, inv = self._pose(self._x)
        self._f = self._forces(inv, np.array([law.committed[1] for law in self.laws]))
        self._trial: tuple[npt.NDArray[np.float64], npt.NDArray[np.float64]] | None = None

    def _pose(self, strokes: npt.NDArray[np.float64]) -> tuple[npt.NDArray[np.float64],
                                                               npt.NDArray[np.float64]]:
        """(q, J⁻¹) behind ``strokes``: one inverse serves the forces and the tangent (a rig
        asks on every substep of a move, so this is the platform's hot path)."""
        try:
            q, j = self.geometry.state(tuple(float(v) for v in strokes))
        except ValueError as exc:
            raise PlatformError(f"the strokes {strokes.tolist()} put the platform nowhere "
                                f"(singular or out of reach): {exc}") from None
        if j is self._rows:  # a linear geometry: the same J every time
            return np.array(q, dtype=np.float64), self._inv
        jac = np.array(j, dtype=np.float64)
        try:
            inv = np.asarray(np.linalg.inv(jac), dtype=np.float64) \
                if jac.shape == (self.n, self.n) else None
        except np.linalg.LinAlgError:
            inv = None
        # ‖J‖·‖J⁻¹‖ (max-norms): a condition estimate without an SVD per call
        if inv is None or not np.all(np.isfinite(inv)) or \
                float(np.abs(jac).max()) * float(np.abs(inv).max()) > _MAX_CONDITION:
            raise PlatformError(f"the strokes {strokes.tolist()} do not fix the platform "
                                f"(∂s/∂q = {jac.tolist()} is singular)")
        self._rows, self._inv = j, inv
        return np.array(q, dtype=np.float64), inv

    @staticmethod
    def _forces(inv: npt.NDArray[np.float64], p: npt.NDArray[np.float64]
                ) -> npt.NDArray[np.float64]:
        return np.asarray(inv.T @ p, dtype=np.float64)

    def basic(self, strokes: Sequence[float]) -> tuple[float, ...]:
        """The platform DOFs q for actuator strokes ``strokes``."""
        q, _ = self._pose(np.asarray(strokes, dtype=np.float64))
        return tuple(float(v) for v in q)

    def force(self, actuator: int) -> float:
        """Actuator ``actuator``'s force (0-based) in the committed state, kN."""
        return float(self._f[actuator])

    @property
    def strokes(self) -> tuple[float, ...]:
        """The committed actuator strokes, mm."""
        return tuple(float(v) for v in self._x)

    def set_trial(self, actuator: int, stroke: float) -> tuple[float, float]:
        """Actuator ``actuator`` at ``stroke``, the others where they are: its (force, tangent
        stiffness ∂f_i/∂x_i — the specimen's part, ``J⁻ᵀ k J⁻¹``; the geometric part of an
        exact geometry is left out)."""
        x = self._x.copy()
        x[actuator] = stroke
        q, inv = self._pose(x)
        p, k = np.empty(self.n), np.empty(self.n)
        for i, law in enumerate(self.laws):
            p[i], k[i] = law.set_trial(float(q[i]))
        f = self._forces(inv, p)
        self._trial = (x, f)
        row = inv[:, actuator]
        return float(f[actuator]), float(row @ (k * row))

    def commit(self) -> None:
        """The last trial becomes the platform's state."""
        if self._trial is not None:
            for law in self.laws:
                law.commit()
            self._x, self._f = self._trial
            self._trial = None

    def channel(self, actuator: int) -> _Channel:
        """Actuator ``actuator``'s view of the platform (a rig's specimen)."""
        if not 0 <= actuator < self.n:
            raise PlatformError(f"actuator {actuator} of {self.n} does not exist")
        return _Channel(self, actuator)


class _Channel:
    """One actuator's specimen: the platform seen along that actuator."""

    def __init__(self, platform: Platform, actuator: int) -> None:
        self.platform = platform
        self.actuator = actuator

    def set_trial(self, d: float) -> tuple[float, float]:
        return self.platform.set_trial(self.actuator, d)

    def commit(self) -> None:
        self.platform.commit()

    @property
    def committed(self) -> tuple[float, float]:
        p = self.platform
        return p.strokes[self.actuator], p.force(self.actuator)
