"""The learners of a running bridge (found through the updatable kind's group: the daemon
itself knows only ``Site``s and their kinds' groups)."""

from __future__ import annotations

from typing import Any

from fresco_bridge.twins.kind import TwinGroup
from fresco_bridge.twins.learner import Learner


def learners_of(bridge: Any) -> dict[str, Learner]:
    """``{source site: its learner}`` of ``bridge`` (a ``Bridge`` or a ``BridgeThread``)."""
    bridge = getattr(bridge, "bridge", bridge)
    found: dict[str, Learner] = {}
    for group in bridge.groups:
        if isinstance(group, TwinGroup):
            found.update(group.learners)
    return found
