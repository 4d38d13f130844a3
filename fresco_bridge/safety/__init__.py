"""The safety layer between setup and controller: ctrl/daq limits, policies, site states.

Pure logic (no I/O): the site calls ``Limiter.check_ctrl`` on every command and
``Limiter.check_daq`` on every measurement, and moves through ``states.TRANSITIONS``.
"""

from .config import ControlPointLimitsConfig
from .limits import ControlPointLimits, Limiter, LimitHit, Policy, Verdict, all_finite, split
from .states import TRANSITIONS, SiteState, TransitionRefused, Trigger, next_state

__all__ = [
    "TRANSITIONS",
    "ControlPointLimits",
    "ControlPointLimitsConfig",
    "LimitHit",
    "Limiter",
    "Policy",
    "SiteState",
    "TransitionRefused",
    "Trigger",
    "Verdict",
    "all_finite",
    "next_state",
    "split",
]
