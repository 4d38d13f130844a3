"""What a site kind declares, in one place: its ``[[sites]]`` config model, the factory of its
sites (a group: the kind's sites and what they share, started and closed together), and the
line docs/configuration.md's table shows for it.

Each kind's module ends with its ``KIND``; ``fresco_bridge/site_kinds.py`` lists them (one
line each), and the config's discriminated union on ``kind``, its error texts and the docs'
table derive from that list. The keys every kind shares are ``SiteConfigBase``'s
(``site_config.py``).
"""

from __future__ import annotations

from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any, Protocol

from .site_config import SiteConfigBase

if TYPE_CHECKING:
    from ..record import RunRecord
    from ..record.scan import ResumeScan
    from ..telemetry.metrics import Metrics
    from .base import Site

__all__ = ["LabView", "SiteConfigBase", "SiteContext", "SiteGroup", "SiteKind"]


@dataclass(frozen=True)
class LabView:
    """The whole lab config as a kind's ``resolve`` sees it (cross-site checks, paths)."""

    sites: Mapping[str, SiteConfigBase]
    controller_timeout: float
    base: Path
    """The config file's folder: relative data paths resolve against it."""
    predicted: Callable[[str], bool]
    """Whether sites of kind ``name`` answer predicted forces (not measured ones)."""


@dataclass(frozen=True)
class SiteContext:
    """What the bridge gives every kind's factory."""

    record: RunRecord | None
    controller_timeout: float
    """``bridge.controller_timeout``: the deadline of every call a site makes outside."""
    controller_recovery: float
    resume: ResumeScan | None = None
    """The interrupted run being resumed: a kind that needs what its record holds (an
    in-process specimen's commands, a learner's history) adds a reader to it when its group
    is built; the daemon reads the record once for all, before any group starts."""


class SiteGroup(Protocol):
    """A kind's sites of one bridge and what they share (a twin's learner), with their life:
    ``start`` before any site listens, ``wire`` once every kind's sites exist (a twin's source
    is another kind's site), ``close`` after the sessions ended."""

    @property
    def sites(self) -> Mapping[str, Site]: ...

    async def start(self) -> None:
        """Reach what the sites need (a controller, a learner's worker); a failure that
        makes the configuration unusable raises ``ConfigError``, a controller that is merely
        unreachable is logged (the site HOLDs at its first command)."""
        ...

    def wire(self, sites: Mapping[str, Site]) -> None: ...

    def attach_metrics(self, metrics: Metrics) -> None: ...

    async def close(self) -> None: ...


@dataclass(frozen=True)
class SiteKind:
    """One site kind: ``kind = "<name>"`` in ``[[sites]]``."""

    name: str
    config: type[SiteConfigBase]
    factory: Callable[[Sequence[Any], SiteContext], SiteGroup]
    """``factory(configs, context)``: the group of this kind's sites (configs in file order)."""
    summary: str
    """The kind's description in docs/configuration.md's table (markdown, one cell)."""
    predicted: bool = False
    """The site's force is a prediction, not a measurement (telemetry says so; a replay never
    scores against it)."""
    describe: Callable[[Any], str] = lambda cfg: ""
    """What ``fresco-bridge check`` adds after a site of this kind (``" (…)"`` or empty)."""
    resolve: Callable[[Any, LabView], tuple[Any, list[str]]] | None = None
    """``resolve(config, lab)``: the config with its paths resolved and the problems it has
    against the whole lab (``key: reason``, relative to the site's entry); None: none."""

    def build(self, configs: Sequence[SiteConfigBase], context: SiteContext) -> SiteGroup:
        return self.factory(configs, context)
