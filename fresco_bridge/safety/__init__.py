"""The safety layer between setup and controller: ctrl/daq limits, policies, site states.

Pure logic (no I/O): the site calls ``Limiter.check_ctrl`` on every command and
``Limiter.check_daq`` on every measurement, and moves through ``states.TRANSITIONS``;
``correction.correct`` proposes the next command of the outer-loop displacement correction.
"""

from .config import ControlPointLimitsConfig, CorrectionConfig
from .correction import CONVERGED, CorrectionSettings, Terminal, correct
from .limits import ControlPointLimits, Limiter, LimitHit, Policy, Verdict, all_finite, split
from .states import TRANSITIONS, SiteState, TransitionRefused, Trigger, next_state

__all__ = [
    "CONVERGED",
    "TRANSITIONS",
    "ControlPointLimits",
    "ControlPointLimitsConfig",
    "CorrectionConfig",
    "CorrectionSettings",
    "LimitHit",
    "Limiter",
    "Policy",
    "SiteState",
    "Terminal",
    "TransitionRefused",
    "Trigger",
    "Verdict",
    "all_finite",
    "correct",
    "next_state",
    "split",
]
