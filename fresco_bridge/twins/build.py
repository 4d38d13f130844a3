"""From the updatable sites' configs to their learners and sites: one learner per source site,
one twin site per updatable site, and the wiring to the sources once every site exists."""

from __future__ import annotations

import math
from collections.abc import Callable, Mapping, Sequence
from pathlib import Path
from typing import TYPE_CHECKING, Any

from ..causality import Causality
from ..config_model import ConfigError
from ..record.export import committed_steps
from ..sites import controlled_site
from ..sites.base import Site
from ..updating.base import UpdaterError
from ..updating.histories import read_history
from .controller import TwinController
from .learner import Learner
from .source import SourceFeed
from .worker import LearnerSpec, Message, TwinSpec

if TYPE_CHECKING:
    from ..sites.kind import SiteContext
    from .config import UpdatableSiteConfig

__all__ = ["build_twins", "preload_from_record", "twin_spec", "wire_twins"]


def twin_spec(cfg: UpdatableSiteConfig) -> TwinSpec:
    """The updater of updatable site ``cfg`` with its data read (paths already resolved)."""
    options: dict[str, Any] = dict(cfg.updater_options)
    try:
        if cfg.offline is not None:
            history = read_history(cfg.offline)
            options["offline"] = (history.disp, history.force)
    except UpdaterError as exc:
        raise ConfigError(f"site {cfg.name}: offline: {exc}") from None
    if cfg.model is not None:
        options["model_file"] = str(cfg.model)
    return TwinSpec(cfg.name, cfg.updater, options, cfg.on_learner_loss)


def build_twins(configs: Sequence[UpdatableSiteConfig], context: SiteContext
                ) -> tuple[dict[str, Learner], dict[str, Site], dict[str, TwinController],
                           dict[str, SourceFeed | None]]:
    """``({source site: its learner}, {updatable site: its site}, {updatable site: its twin
    controller}, {source site: its feed of trials, if a twin of it is same-step})`` (not
    started)."""
    groups: dict[str, list[UpdatableSiteConfig]] = {}
    for cfg in configs:
        groups.setdefault(cfg.learns_from, []).append(cfg)
    learners: dict[str, Learner] = {}
    sites: dict[str, Site] = {}
    controllers: dict[str, TwinController] = {}
    feeds: dict[str, SourceFeed | None] = {}
    for source, twins in groups.items():
        spec = LearnerSpec(source, tuple(twin_spec(t) for t in twins))
        learner = learners[source] = Learner(source, spec,
                                             deadline=min(t.learner_deadline for t in twins))
        same_step = [t for t in twins if t.causality is Causality.SAME_STEP]
        feed = feeds[source] = SourceFeed(source) if same_step else None
        for t in twins:
            controller = controllers[t.name] = TwinController(
                learner, t.name, updater=t.updater, causality=t.causality,
                feed=feed if t in same_step else None)
            sites[t.name] = controlled_site(t, controller, context)
    return learners, sites, controllers, feeds


def _event_sink(site: Site, on_loss: str) -> Callable[[str, str, dict[str, object]],
                                                                  None]:
    """A learner's events as events of one of its twin sites; a lost learner HOLDs a ``hold``
    twin at once, not only at its next request (a ``freeze`` twin answers from its snapshot)."""
    def sink(kind: str, reason: str, extra: dict[str, object]) -> None:
        site.event(kind, reason, **extra)
        if kind == "learner-lost" and site.in_session and on_loss == "hold":
            site.enter_hold(reason)
    return sink


def wire_twins(learners: Mapping[str, Learner], twins: Mapping[str, Site],
               controllers: Mapping[str, TwinController],
               feeds: Mapping[str, SourceFeed | None],
               sites: Mapping[str, Site]) -> None:
    """Each learner listens to its source's committed steps; its events go to its twins, and
    each twin site writes its update lines after its step lines."""
    for source_name, learner in learners.items():
        source = sites[source_name]
        feed = feeds.get(source_name)
        if feed is not None:
            source.add_listener(feed)  # its trials, commits and state
        source.add_listener(learner)
        for spec in learner.spec.twins:
            site = twins[spec.name]
            learner.add_event_sink(_event_sink(site, spec.on_loss))
            controller = controllers[spec.name]
            controller.bind(site)
            site.add_listener(controller)


def preload_from_record(learners: Mapping[str, Learner], run_dir: Path,
                        configs: Sequence[UpdatableSiteConfig]) -> None:
    """Each learner starts where the interrupted run ``run_dir`` stopped: the source's
    committed steps and each twin's committed trials, in the record's order (the order the
    bridge saw them), so the twins' answers after ``--resume`` equal an uninterrupted run's."""
    steps = committed_steps(run_dir)
    same_step = {c.name for c in configs if c.causality == "same-step"}
    for learner in learners.values():
        twins = {t.name for t in learner.spec.twins}
        log: list[Message] = []
        source_step = commits = 0
        for step in steps:
            if step.site == learner.source:
                d, f = step.meas_disp[0], step.meas_force[0]
                source_step = step.step
                if math.isfinite(d) and math.isfinite(f):
                    log.append(("observe", step.step, d, f))
            elif step.site in twins:
                log += [("trial", 0, step.site, step.cmd_disp[0], step.site in same_step),
                        ("commit", step.site)]
                commits += 1
        learner.preload(log, source_step=source_step, commits=commits)
