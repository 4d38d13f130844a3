"""Sites: where trial signals meet a setup and a controller (OpenFresco: experimental sites)."""

from ..safety import SiteState
from .base import Site, SiteError
from .experimental import ExperimentalSite

__all__ = ["ExperimentalSite", "Site", "SiteError", "SiteState"]
