"""From the lab config to learners and twin controllers: one learner per source site, one
twin controller per updatable site."""

from __future__ import annotations

import math
from pathlib import Path
from typing import Any

from ..config import ConfigError, LabConfig, SiteConfig
from ..record.export import committed_steps
from ..updating.base import UpdaterError
from ..updating.histories import read_history
from .controller import TwinController
from .learner import Learner
from .worker import LearnerSpec, Message, TwinSpec

__all__ = ["build_twins", "preload_from_record", "twin_spec"]


def twin_spec(cfg: SiteConfig) -> TwinSpec:
    """The updater of updatable site ``cfg`` with its data read (paths already resolved)."""
    assert cfg.updater is not None
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


def build_twins(config: LabConfig) -> tuple[dict[str, Learner], dict[str, TwinController]]:
    """``({source site: its learner}, {updatable site: its controller})`` (not started)."""
    groups: dict[str, list[SiteConfig]] = {}
    for scfg in config.sites:
        if scfg.kind == "updatable":
            assert scfg.learns_from is not None
            groups.setdefault(scfg.learns_from, []).append(scfg)
    learners: dict[str, Learner] = {}
    controllers: dict[str, TwinController] = {}
    for source, twins in groups.items():
        spec = LearnerSpec(source, tuple(twin_spec(t) for t in twins))
        learner = learners[source] = Learner(source, spec,
                                             deadline=min(t.learner_deadline for t in twins))
        for t in twins:
            assert t.updater is not None
            controllers[t.name] = TwinController(learner, t.name, updater=t.updater,
                                                 causality=t.causality)
    return learners, controllers


def preload_from_record(learners: dict[str, Learner], run_dir: Path, config: LabConfig) -> None:
    """Each learner starts where the interrupted run ``run_dir`` stopped: the source's
    committed steps and each twin's committed trials, in the record's order (the order the
    bridge saw them), so the twins' answers after ``--resume`` equal an uninterrupted run's."""
    steps = committed_steps(run_dir)
    same_step = {s.name for s in config.sites if s.causality == "same-step"}
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
