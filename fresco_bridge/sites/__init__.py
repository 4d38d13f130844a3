"""Sites: where trial signals meet a setup and a controller (OpenFresco: experimental sites).
Each kind's module declares its config and group (``kind.py``); ``site_kinds.py`` lists them."""

from ..safety import SiteState
from .base import Site, SiteError
from .experimental_kind import controlled_site

__all__ = ["Site", "SiteError", "SiteState", "controlled_site"]
