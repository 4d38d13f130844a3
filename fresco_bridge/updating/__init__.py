"""Online model updating: pure numerics (features, MLP, Levenberg-Marquardt, UKF, updaters).

No I/O and no asyncio here: the serving side (a site whose forces come from an updater) lives in
``fresco_bridge/`` and only calls the :class:`~fresco_bridge.updating.base.Updater` interface.
Build updaters by name with :func:`make_updater` (the registry is :data:`UPDATERS`); checkpoint
one mid-run with :func:`snapshot` and bring it back with :func:`restore`. Importing
this package is cheap: numpy-heavy modules, filterpy and torch load when an updater needs them.
"""

from .base import Updater, UpdaterError, UpdaterInputError, restore, snapshot
from .registry import UPDATERS, make_updater, updater_options

__all__ = [
    "UPDATERS",
    "Updater",
    "UpdaterError",
    "UpdaterInputError",
    "make_updater",
    "restore",
    "snapshot",
    "updater_options",
]
