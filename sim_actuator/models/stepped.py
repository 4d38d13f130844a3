"""The Bouc-Wen kinds with their substeps run by the JIT kernels of ``paths``: the same
objects, the same bits, a fraction of the time per trial.

Why: ``online_improved`` steps Bouc-Wen laws thousands of times per replay — each expert's
tested element, twin and shadow, and the refitted law's state replays after every refit — and
the Python RK4 substeps were a large share of its replay time (``BENCHMARKS.md``, "Online
updating"). Only ``_advance`` (the substeps of one trial) is replaced, by the kernel
``paths.drive`` runs: its operations are the object's in the same order, so every state and
force is identical, which ``tests/sim_actuator/models/test_stepped.py`` checks to the bit. A
trial the kernel refuses (more than ``MAX_SUBSTEPS``) is repeated by the object's own
``_advance``, which raises its usual error. Everything else (``set_trial``'s force and
tangent, commit, clone, state, ``with_params``) is the object's.
"""

from __future__ import annotations

from sim_actuator.models.bouc_wen import BoucWen
from sim_actuator.models.bwbn import BoucWenBaberNoori
from sim_actuator.models.paths import bouc_wen_advance, bouc_wen_vector, bwbn_advance, bwbn_vector

__all__ = ["SteppedBaberNoori", "SteppedBoucWen"]


class SteppedBoucWen(BoucWen):
    """:class:`BoucWen`, its substeps by the JIT kernel (module docstring)."""

    __slots__ = ("_prm",)

    def __init__(self, **params: float) -> None:
        super().__init__(**params)
        self._prm = bouc_wen_vector(self.parameters)

    def _advance(self, z: float, du: float) -> float:
        z_end, ok = bouc_wen_advance(self._prm, z, du, self.dz_max)
        return float(z_end) if ok else super()._advance(z, du)


class SteppedBaberNoori(BoucWenBaberNoori):
    """:class:`BoucWenBaberNoori`, its substeps by the JIT kernel (module docstring)."""

    __slots__ = ("_prm",)

    def __init__(self, **params: float) -> None:
        super().__init__(**params)
        self._prm = bwbn_vector(self.parameters)

    def _advance(self, z: float, e: float, du: float) -> tuple[float, float]:
        z_end, e_end, ok = bwbn_advance(self._prm, z, e, du, self.dz_max)
        return (float(z_end), float(e_end)) if ok else super()._advance(z, e, du)
