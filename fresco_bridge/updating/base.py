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
or only through ``i - 1`` is the caller's choice (replay's ``--lag`` flag), not the updater's.
"""

from __future__ import annotations

from typing import Protocol, runtime_checkable

from sim_actuator.models.base import HysteresisModel

__all__ = ["Updater", "UpdaterError", "UpdaterInputError"]


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
