"""The Bouc-Wen kinds stepped through their JIT kernels (``paths``): the same objects, the
same bits, a tenth of the time per trial.

Why: ``online_improved`` steps Bouc-Wen laws thousands of times per replay — each expert's
tested element, twin and shadow, and the refitted law's state replays after every refit — and
the Python RK4 substeps were a third of its replay time (BENCHMARKS.md, updating part 11). A
trial here is one call of the kernel that ``paths.drive`` runs (its operations are the
object's, in the same order, so force and state are identical, which
``tests/sim_actuator/models/test_stepped.py`` checks to the bit); the tangent comes from the
object's own slope. A trial the kernel refuses (too many substeps, degradation exhausted) is
repeated by the object's own ``set_trial``, which raises its usual error. Everything else
(commit, clone, state, ``with_params``) is the object's.
"""

from __future__ import annotations

import math

from sim_actuator.models.base import trial_input_error
from sim_actuator.models.bouc_wen import BoucWen
from sim_actuator.models.bwbn import BoucWenBaberNoori
from sim_actuator.models.paths import bouc_wen_trial, bouc_wen_vector, bwbn_trial, bwbn_vector

__all__ = ["SteppedBaberNoori", "SteppedBoucWen"]


class SteppedBoucWen(BoucWen):
    """:class:`BoucWen`, each trial by the JIT kernel (module docstring)."""

    __slots__ = ("_prm",)

    def __init__(self, **params: float) -> None:
        super().__init__(**params)
        self._prm = bouc_wen_vector(self.parameters)

    def set_trial(self, d: float) -> tuple[float, float]:
        d_c, f_c, k_c, z_c = self._committed
        du = (d - d_c) / self._dy
        if not math.isfinite(du):
            raise trial_input_error(self.name, d)
        if du == 0.0:
            self._trial = self._committed
            return f_c, k_c
        force, z, ok = bouc_wen_trial(self._prm, d_c, z_c, f_c, float(d), self.dz_max)
        if not ok:
            return super().set_trial(d)
        tangent = self._k_el + self._k_hyst * self._slope(z, 1.0 if du > 0.0 else -1.0)
        self._trial = (d, force, tangent, z)
        return force, tangent


class SteppedBaberNoori(BoucWenBaberNoori):
    """:class:`BoucWenBaberNoori`, each trial by the JIT kernel (module docstring)."""

    __slots__ = ("_prm",)

    def __init__(self, **params: float) -> None:
        super().__init__(**params)
        self._prm = bwbn_vector(self.parameters)

    def set_trial(self, d: float) -> tuple[float, float]:
        d_c, f_c, k_c, z_c, e_c = self._committed
        du = (d - d_c) / self._dy
        if not math.isfinite(du):
            raise trial_input_error(self.name, d)
        if du == 0.0:
            self._trial = self._committed
            return f_c, k_c
        force, z, e, ok = bwbn_trial(self._prm, d_c, z_c, e_c, f_c, float(d), self.dz_max)
        if not ok:
            return super().set_trial(d)
        tangent = self._k_el + self._k_hyst * self._slope(z, e, 1.0 if du > 0.0 else -1.0)
        self._trial = (d, force, tangent, z, e)
        return force, tangent
