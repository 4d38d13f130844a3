"""Sites: where trial signals meet a setup and a controller (OpenFresco: experimental sites)."""

from .experimental import ExperimentalSite, SiteError, SiteState

__all__ = ["ExperimentalSite", "SiteError", "SiteState"]
