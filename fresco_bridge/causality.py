"""When a twin's answer may use what its source measured: one type for the coupling loop, the
replay of recorded histories, the bridge's learner and its worker.

``previous-step``: the twin's answer at step i uses the source's committed steps through
i − 1 (always possible; what a served twin can always do). ``same-step``: also the source's
measurement of step i, learned before the twin answers (the paper's order; one trial per step:
explicit schemes). Whatever the causality, an updater *trains* on committed measurements only.
"""

from __future__ import annotations

from enum import StrEnum

__all__ = ["CAUSALITIES", "Causality"]


class Causality(StrEnum):
    PREVIOUS_STEP = "previous-step"
    SAME_STEP = "same-step"

    @property
    def lag(self) -> bool:
        """The twin's step i is answered before the source's step i is learned."""
        return self is Causality.PREVIOUS_STEP


CAUSALITIES: tuple[Causality, ...] = tuple(Causality)
