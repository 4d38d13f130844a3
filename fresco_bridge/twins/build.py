"""From the updatable sites' configs to their learners and sites: one learner per source site,
one twin site per updatable site, and the wiring to the sources once every site exists."""

from __future__ import annotations

import math
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any

from ..config_model import ConfigError
from ..sites import controlled_site
from ..sites.base import Site
from ..updating.base import UpdaterError
from ..updating.histories import read_history
from .checkpoint import CheckpointWriter, load_checkpoint
from .controller import TwinController
from .learner import Learner
from .source import SourceFeed
from .worker import LearnerSpec, Message, TwinSpec

if TYPE_CHECKING:
    from ..sites.kind import SiteContext
    from .config import UpdatableSiteConfig

__all__ = ["RecordedHistory", "build_twins", "twin_spec", "wire_twins"]


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
        if context.record is not None:
            learner.checkpoints = CheckpointWriter(context.record.directory, spec)
        same_step = [t for t in twins if t.causality == "same-step"]
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


def _any_in_session(sites: list[Site]) -> Callable[[], bool]:
    return lambda: any(site.in_session for site in sites)


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
        learner.twins_active = _any_in_session([twins[t.name] for t in learner.spec.twins])
        for spec in learner.spec.twins:
            site = twins[spec.name]
            learner.add_event_sink(_event_sink(site, spec.on_loss))
            controller = controllers[spec.name]
            controller.bind(site)
            site.add_listener(controller)


@dataclass
class _Replayed:
    """One learner's history being rebuilt from a record (``RecordedHistory``)."""

    log: list[Message] = field(default_factory=list)
    source_session: int = 0
    source_step: int = 0
    commits: int = 0
    awaiting: dict[str, tuple[float, int]] = field(default_factory=dict)
    """Twin -> (its committed trial, its step) until its update line says how far it
    learned."""

    def twin_committed(self, twin: str, through: tuple[int, int] | None = None) -> None:
        d, step = self.awaiting.pop(twin)
        self.log += [("trial", 0, twin, d, through or (self.source_session, step - 1)),
                     ("commit", twin)]
        self.commits += 1


class RecordedHistory:
    """Each learner starts where the interrupted run stopped (a reader of the resume's one
    pass over the record, ``record/scan.py``): the source's committed steps keyed by
    (session, step) and each twin's committed trials with how far each learned (its update
    line's ``upto`` if it has one, else the source's session open then, through the twin's
    step if its update line says same-step, else the step before), in the record's order
    (the order the bridge saw them), so the twins' answers after ``--resume`` equal an
    uninterrupted run's."""

    def __init__(self, learners: Mapping[str, Learner], run_dir: Path,
                 configs: Sequence[UpdatableSiteConfig]) -> None:
        self.learners = learners
        self.run_dir = run_dir
        self._same_step = {c.name for c in configs if c.causality == "same-step"}
        self._by_source = {learner.source: _Replayed() for learner in learners.values()}
        self._of_twin = {t.name: self._by_source[learner.source]
                         for learner in learners.values() for t in learner.spec.twins}
        self._last_trial: dict[tuple[str, int], dict[str, Any]] = {}
        self._last_daq: dict[tuple[str, int], dict[str, Any]] = {}

    KINDS = ("trial", "daq", "commit", "event", "update")
    """The lines it reads."""

    def line(self, rec: dict[str, Any]) -> None:
        """A line of one of ``KINDS`` (``read_record``'s complete dicts)."""
        kind, site = rec["kind"], rec.get("site", "")
        if site not in self._by_source and site not in self._of_twin:
            return
        key = (site, int(rec.get("session", 0)))
        if kind == "trial":
            self._last_trial[key] = rec
            self._last_daq.pop(key, None)
        elif kind == "daq":
            self._last_daq[key] = rec
        elif kind == "event" and site in self._by_source and rec.get("event") == "session-open":
            self._by_source[site].source_session = key[1]
        elif kind == "commit" and key in self._last_trial and key in self._last_daq:
            self._committed(site, key, int(rec["step"]))
        elif kind == "update" and site in self._of_twin and site in self._of_twin[site].awaiting:
            replayed = self._of_twin[site]
            upto = rec.get("upto")
            if upto is not None:  # learned less than it asked for: exactly this far
                replayed.twin_committed(site, (int(upto[0]), int(upto[1])))
                return
            step = replayed.awaiting[site][1]
            same = site in self._same_step and int(rec.get("through", -1)) == step
            replayed.twin_committed(site, (replayed.source_session, step if same else step - 1))

    def _committed(self, site: str, key: tuple[str, int], step: int) -> None:
        if site in self._by_source:
            src = self._by_source[site]
            daq = self._last_daq[key]
            d, f = float(daq["disp"][0]), float(daq["force"][0])
            src.source_session, src.source_step = key[1], step
            if math.isfinite(d) and math.isfinite(f):
                src.log.append(("observe", key[1], step, d, f))
        else:
            replayed = self._of_twin[site]
            if site in replayed.awaiting:  # a commit without its update line
                replayed.twin_committed(site)
            replayed.awaiting[site] = (float(self._last_trial[key]["ctrl"][0]), step)

    def end(self) -> None:
        for learner in self.learners.values():
            replayed = self._by_source[learner.source]
            for twin in list(replayed.awaiting):
                replayed.twin_committed(twin)
            learner.preload(replayed.log, source_step=replayed.source_step,
                            commits=replayed.commits,
                            checkpoint=load_checkpoint(self.run_dir, learner.spec))
            learner.source_session = replayed.source_session
            replayed.log = []
