"""When a twin's answer may use what its source measured: one type for the coupling loop
(``integrator/coupling.py``), the replay of recorded histories (``updating/replay.py``: its
``lag`` is ``lags(causality)``), the bridge's twins (config, controller, learner, worker).

``previous-step``: the twin's answer at step i uses the source's committed steps through
i − 1 (always possible; what a served twin can always do). ``same-step``: also the source's
measurement of step i, learned before the twin answers (the paper's order; one moving trial
per step: explicit schemes). Whatever the causality, an updater *trains* on committed
measurements only.
"""

from __future__ import annotations

from typing import Literal, get_args

__all__ = ["CAUSALITIES", "Causality", "lags"]

Causality = Literal["same-step", "previous-step"]
CAUSALITIES: tuple[Causality, ...] = get_args(Causality)


def lags(causality: Causality) -> bool:
    """The twin's step i is answered before the source's step i is learned."""
    return causality == "previous-step"
