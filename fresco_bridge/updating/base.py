"""The one interface every model updater implements, and its errors.

An updater learns from the *tested* element's committed measurements (``observe``) and predicts
the force of its numerical *twin* elsewhere in the structure (``twin``). The twin follows OpenSees
uniaxial-material semantics, exactly like ``sim_actuator.models.HysteresisModel``: ``set_trial(d)``
always starts from the twin's last commit, so Newton iterations never advance its state, and only
``commit()`` does. A twin can therefore stand wherever a hysteresis model stands (the in-process
``sim`` controller, the study's integrator coupling, a served updatable site).

Order within one step ``i`` of a hybrid test: the tested element's step ``i`` is committed and
measured -> ``observe(d_i, F_i)``; then the twin is asked ``set_trial(d_twin_i)`` (any number of
times) and ``commit()``. Whether the twin's step ``i`` may use what was learned from step ``i``
or only through ``i - 1`` is the caller's choice, not the updater's: the *causality*
(``same-step`` / ``previous-step``) of ``integrator/coupling.py`` and of ``study paper
--causality``; replay's ``--lag`` is ``previous-step``.
"""

from __future__ import annotations

import math
from typing import Protocol, runtime_checkable

from sim_actuator.models.base import HysteresisModel

__all__ = ["SNAPSHOT_MAGIC", "OwnsTwin", "Updater", "UpdaterError", "UpdaterInputError",
           "check_measurement", "restore", "snapshot"]


class UpdaterError(ValueError):
    """An updater cannot be built or loaded (bad parameters, incompatible model file)."""


class UpdaterInputError(UpdaterError):
    """A measurement was rejected (non-finite, wrong shape); the updater is left unchanged."""


@runtime_checkable
class Updater(Protocol):
    """A model of the twin's force, updated online from the tested element's measurements."""

    name: str
    """Registry name (``none``, ``offline_ann``, ``online_ann``, ``online_ukf``, …)."""

    def observe(self, d: float, force: float) -> None:
        """Learn from one committed measurement (d in mm, force in kN) of the tested element.

        Raises :class:`UpdaterInputError` for a non-finite value, leaving every state unchanged.
        """
        ...

    @property
    def twin(self) -> HysteresisModel:
        """The twin's force model (material semantics: trial from the last commit, commit)."""
        ...

    @property
    def last_update_seconds(self) -> float:
        """Wall time the last ``observe`` spent updating (0.0 for a fixed model)."""
        ...

    @property
    def last_one_step_error(self) -> float | None:
        """|F − F̂| of the last ``observe``: the measured force against the updater's
        prediction of it from the tested element's measured past, made before learning the
        step (the source's one-step error). None: the updater makes no such prediction."""
        ...


def check_measurement(name: str, d: float, force: float) -> tuple[float, float]:
    """(d, force) as floats, or UpdaterInputError naming the updater and the bad value."""
    try:
        d_f, f_f = float(d), float(force)
    except (TypeError, ValueError) as exc:
        raise UpdaterInputError(f"{name}: measurement must be two numbers, got d={d!r}, "
                                f"force={force!r}") from exc
    if not (math.isfinite(d_f) and math.isfinite(f_f)):
        raise UpdaterInputError(f"{name}: measurement rejected, d={d_f!r} mm, force={f_f!r} kN "
                                "(must be finite); the updater is unchanged")
    return d_f, f_f


class OwnsTwin:
    """The two read-only properties of an updater that keeps its twin and times its update."""

    _twin: HysteresisModel
    _last_update: float = 0.0
    _last_one_step: float | None = None

    @property
    def twin(self) -> HysteresisModel:
        return self._twin

    @property
    def last_update_seconds(self) -> float:
        return self._last_update

    @property
    def last_one_step_error(self) -> float | None:
        return self._last_one_step


SNAPSHOT_MAGIC = b"fresco-bridge updater snapshot 1\n"
"""First bytes of :func:`snapshot`'s output (the format's version)."""


def snapshot(updater: Updater) -> bytes:
    """The updater's whole state, its twin's included, as bytes: :func:`restore` gives back an
    updater that continues exactly as this one would (same parameters, same states, same
    random streams). Why: a learner checkpointed at step N is restored by a new worker instead
    of replaying every step from 0, so catch-up is bounded by the steps since the checkpoint.

    The same pair is a served same-step twin's rollback point (``twins/worker.py``): the
    source's trial measurement is learned tentatively after a snapshot and unlearned by a
    restore if it is not the one committed, so every updater trains on commits only without
    a method of its own for it.

    The format is pickle behind a version line: restore only snapshots this software wrote
    (a checkpoint file of the bridge's own run directory), never one from elsewhere.
    """
    import pickle

    try:
        return SNAPSHOT_MAGIC + pickle.dumps(updater, protocol=pickle.HIGHEST_PROTOCOL)
    except (pickle.PicklingError, TypeError, AttributeError) as exc:
        raise UpdaterError(f"{getattr(updater, 'name', type(updater).__name__)}: cannot be "
                           f"snapshot: {exc}") from exc


def restore(blob: bytes) -> Updater:
    """The updater a :func:`snapshot` holds; UpdaterError for bytes that are not one (another
    version, truncated, corrupted)."""
    import pickle

    if not blob.startswith(SNAPSHOT_MAGIC):
        head = blob[: len(SNAPSHOT_MAGIC)].split(b"\n", 1)[0][:60]
        raise UpdaterError(f"not an updater snapshot of this version (starts with {head!r}; "
                           f"expected {SNAPSHOT_MAGIC.strip()!r})")
    try:
        updater = pickle.loads(blob[len(SNAPSHOT_MAGIC):])  # our own checkpoint (docstring)
    except Exception as exc:  # a truncated or corrupted pickle raises many kinds
        raise UpdaterError(f"the updater snapshot is truncated or corrupted: {exc}") from exc
    if not isinstance(updater, Updater):
        raise UpdaterError(f"the snapshot holds a {type(updater).__name__}, not an updater")
    return updater
