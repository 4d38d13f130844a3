"""Sites: where trial signals meet a setup and a controller (OpenFresco: experimental sites)."""

from ..safety import SiteState
from .experimental import ExperimentalSite, SiteError

__all__ = ["ExperimentalSite", "SiteError", "SiteState"]
