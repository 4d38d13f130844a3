"""A specimen several actuators load together: a rigid platform with linear geometry.

The platform has n basic DOFs q (e.g. a column top's u, v, theta) and n actuators whose strokes
are ``x = T·q`` (T: n×n, one row per actuator, as a linear OpenFresco setup such as
``ThreeActuators2d`` without ``-nlGeom``). The specimen is one uniaxial law per basic DOF,
``p_j(q_j)``; platform equilibrium ``Tᵀ·f = p`` gives the actuator forces ``f = T⁻ᵀ·p``. So
moving one actuator loads the others: the coupling a multi-actuator rig has.

Each actuator's rig drives the platform through :meth:`Platform.channel`, a ``SpecimenModel``
view: a trial moves that actuator's stroke with the others where they are (material semantics,
from the committed state), a commit makes it the platform's state. The rigs move one after the
other; :meth:`Platform.force` is any actuator's force in the current committed state.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
import numpy.typing as npt

from sim_actuator.models import HysteresisModel

__all__ = ["Platform", "PlatformError"]

_MAX_CONDITION = 1e12


class PlatformError(ValueError):
    """The geometry is not square, not invertible or does not fit the specimen laws."""


class Platform:
    """n actuators on a rigid platform with n basic DOFs; see the module docstring."""

    def __init__(self, geometry: Sequence[Sequence[float]],
                 laws: Sequence[HysteresisModel]) -> None:
        t = np.array(geometry, dtype=np.float64)
        n = len(laws)
        if t.ndim != 2 or t.shape != (n, n):
            raise PlatformError(f"geometry must be {n}×{n} (one row per actuator, one column "
                                f"per basic DOF, {n} specimen laws), got shape {t.shape}")
        if not np.all(np.isfinite(t)) or np.linalg.cond(t) > _MAX_CONDITION:
            raise PlatformError(f"geometry {t.tolist()} is singular: the strokes do not fix "
                                "the platform")
        self.n = n
        self.laws = list(laws)
        self._t_inv: npt.NDArray[np.float64] = np.asarray(np.linalg.inv(t), dtype=np.float64)
        self._x = np.zeros(n)
        self._f = self._forces(np.array([law.committed[1] for law in self.laws]))
        self._trial: tuple[npt.NDArray[np.float64], npt.NDArray[np.float64]] | None = None

    def _forces(self, p: npt.NDArray[np.float64]) -> npt.NDArray[np.float64]:
        return self._t_inv.T @ p

    def basic(self, strokes: Sequence[float]) -> tuple[float, ...]:
        """The platform DOFs q for actuator strokes ``strokes``."""
        return tuple(float(v) for v in self._t_inv @ np.asarray(strokes, dtype=np.float64))

    def force(self, actuator: int) -> float:
        """Actuator ``actuator``'s force (0-based) in the committed state, kN."""
        return float(self._f[actuator])

    @property
    def strokes(self) -> tuple[float, ...]:
        """The committed actuator strokes, mm."""
        return tuple(float(v) for v in self._x)

    def set_trial(self, actuator: int, stroke: float) -> tuple[float, float]:
        """Actuator ``actuator`` at ``stroke``, the others where they are: its (force, tangent
        stiffness ∂f_i/∂x_i)."""
        x = self._x.copy()
        x[actuator] = stroke
        q = self._t_inv @ x
        p, k = np.empty(self.n), np.empty(self.n)
        for j, law in enumerate(self.laws):
            p[j], k[j] = law.set_trial(float(q[j]))
        f = self._forces(p)
        self._trial = (x, f)
        row = self._t_inv[:, actuator]
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
