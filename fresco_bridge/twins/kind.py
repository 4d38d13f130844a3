"""The ``updatable`` site kind: the twin of an experimental site's element, its force an
updater's (``updating/``) learned online from that site's committed steps.

Its config (``twins/config.py``) has the twin's keys and no controller table. Its group
holds one learner per source site (one worker process, one updater per twin) and one site per
twin; it starts the learners before any site listens and wires each to its source once every
kind's sites exist.
"""

from __future__ import annotations

import asyncio
import logging
from collections.abc import Mapping, Sequence
from typing import TYPE_CHECKING

from ..config_model import ConfigError
from ..sites.base import Site
from ..sites.kind import SiteContext, SiteKind
from .config import UpdatableSiteConfig, resolve

if TYPE_CHECKING:
    from ..telemetry.metrics import Metrics
    from .learner import Learner

__all__ = ["KIND", "UpdatableSiteConfig"]

log = logging.getLogger("fresco_bridge")


class TwinGroup:
    """The updatable sites of one bridge: one learner per source, one site per twin."""

    def __init__(self, configs: Sequence[UpdatableSiteConfig], context: SiteContext) -> None:
        from .build import RecordedHistory, build_twins

        self.learners: dict[str, Learner]
        self.learners, self._sites, self._controllers, self._feeds = build_twins(configs,
                                                                                 context)
        if context.resume is not None:  # the learners' histories, from the resume's one pass
            history = RecordedHistory(self.learners, context.resume.directory, configs)
            context.resume.add(history.line, history.end, kinds=RecordedHistory.KINDS)

    @property
    def sites(self) -> Mapping[str, Site]:
        return self._sites

    async def start(self) -> None:
        """Every learner's worker built and ready (a resumed run's first caught up)."""
        from .learner import LearnerError

        results = await asyncio.gather(*(learner.start() for learner in self.learners.values()),
                                       return_exceptions=True)
        for source, result in zip(self.learners, results, strict=True):
            if isinstance(result, LearnerError):
                raise ConfigError(f"the learner of site {source} did not start: {result}")
            if isinstance(result, BaseException):
                raise result

    def wire(self, sites: Mapping[str, Site]) -> None:
        """Each learner follows its source's trials and commits; its events go to its twins."""
        from .build import wire_twins

        wire_twins(self.learners, self._sites, self._controllers, self._feeds, sites)

    def attach_metrics(self, metrics: Metrics) -> None:
        for learner in self.learners.values():
            learner.update_observer = metrics.observe_updater_step

    async def close(self) -> None:
        for learner in self.learners.values():
            await learner.close()


def _describe(cfg: UpdatableSiteConfig) -> str:
    return f" (updatable: {cfg.updater} learning from {cfg.learns_from}, {cfg.causality})"


KIND = SiteKind(
    name="updatable",
    config=UpdatableSiteConfig,
    factory=TwinGroup,
    summary="the twin of an experimental site's element, with `learns_from`, `updater`, "
            "`offline` or `model`, `causality`, `on_learner_loss`, `learner_deadline` (2.0 s), "
            "`[sites.updater_options]` and no controller table ([Updatable "
            "sites](updatable-sites.md))",
    predicted=True,
    describe=_describe,
    resolve=resolve,
)

