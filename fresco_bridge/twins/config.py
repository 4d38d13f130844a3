"""The ``updatable`` site kind's config: the twin's keys (no controller table), and the checks
against the whole lab config (the source exists and is measured, one actuator; the deadlines
against ``bridge.controller_timeout``; the updater, its options and its data)."""

from __future__ import annotations

from typing import Any, Literal

from pydantic import Field

from ..causality import Causality
from ..config_model import ConfigPath, Name
from ..sites.kind import LabView
from ..sites.site_config import SiteConfigBase

__all__ = ["UpdatableSiteConfig", "resolve"]


class UpdatableSiteConfig(SiteConfigBase):
    """A twin: the force comes from an updater learning online from ``learns_from``."""

    kind: Literal["updatable"]
    learns_from: Name
    """The experimental site (one actuator) whose committed steps it learns from."""
    updater: str
    """A name of ``updating/registry.py`` (``none``, ``offline_ann``, ``online_ann``,
    ``online_ukf``, ``online_improved``)."""
    offline: ConfigPath | None = None
    """The offline database (CSV ``time,disp,force``, the bridge's export CSV or a run
    directory), relative to the config file's folder."""
    model: ConfigPath | None = None
    """An ANN model file (``updater pretrain``), relative to the config file's folder."""
    causality: Causality = "previous-step"
    """``previous-step``: the twin's step i answers from what was learned through the source's
    step i-1; ``same-step``: also from the source's measurement of step i (``causality.py``)."""
    on_learner_loss: Literal["hold", "freeze"] = "hold"
    """When the learner dies or misses its deadline, ``hold`` (the site's HOLD: NaN answers, the
    integrator stops) or ``freeze`` (answer from the learner's last snapshot, parameters
    frozen, until a new worker has caught up)."""
    updater_options: dict[str, Any] = Field(default_factory=dict)
    """The updater's options (as ``updater replay --option KEY=VALUE``)."""
    learner_deadline: float = Field(default=2.0, gt=0, le=600)
    """Seconds the twin waits for its learner's answer; past it the learner counts as lost
    (``on_learner_loss``). Shorter than ``bridge.controller_timeout``."""

    def actuators_fit(self, n_actuators: int) -> None:
        if n_actuators != 1:
            raise ValueError(f"an updatable site drives one actuator (its twin is uniaxial); "
                             f"setup {self.setup} with {self.dofs} DOF(s) drives {n_actuators}")
        if self.offline is not None and self.model is not None:
            raise ValueError("give offline or model, not both")


def resolve(cfg: UpdatableSiteConfig, lab: LabView) -> tuple[UpdatableSiteConfig, list[str]]:
    """``cfg`` with its data paths resolved against the config's folder, and what is wrong
    with it against the whole lab config (``key: reason``, relative to the site's entry)."""
    from ..updating.base import UpdaterError
    from ..updating.histories import read_history
    from ..updating.modelfile import load_model
    from ..updating.registry import UPDATERS, updater_options

    problems: list[str] = []
    source = lab.sites.get(cfg.learns_from)
    if source is None:
        problems.append(f"learns_from: no site named {cfg.learns_from!r} (sites: "
                        f"{', '.join(lab.sites)})")
    elif lab.predicted(source.kind):
        problems.append(f"learns_from: site {source.name!r} is {source.kind}; a twin learns "
                        "from a site whose force is measured")
    elif (n := source.n_actuators) != 1:
        problems.append(f"learns_from: site {source.name!r} drives {n} actuators (setup "
                        f"{source.setup}, dofs {source.dofs}); a twin learns from a "
                        "one-actuator site")
    if cfg.learner_deadline >= lab.controller_timeout:
        problems.append(f"learner_deadline: {cfg.learner_deadline:g} s must be shorter than "
                        f"bridge.controller_timeout ({lab.controller_timeout:g} s)")
    if cfg.causality == "same-step" and 2 * cfg.learner_deadline >= lab.controller_timeout:
        problems.append("learner_deadline: same-step waits up to it for the source's trial, "
                        "then for the learner: twice it must be shorter than "
                        f"bridge.controller_timeout ({lab.controller_timeout:g} s)")
    name = cfg.updater
    if name not in UPDATERS:
        problems.append(f"updater: unknown updater {name!r}; known: {', '.join(UPDATERS)}")
        return cfg, problems
    paths = {k: p if p is None or p.is_absolute() else lab.base / p
             for k, p in (("offline", cfg.offline), ("model", cfg.model))}
    cfg = cfg.model_copy(update=paths)
    accepted = updater_options(name)
    for k, option in (("offline", "offline"), ("model", "model_file")):
        if paths[k] is not None and option not in accepted:
            problems.append(f"{k}: updater {name!r} takes no {k}")
    needs = UPDATERS[name].needs
    if needs and cfg.offline is None and (cfg.model is None or "model_file" not in needs):
        wanted = " or ".join(f"{k} = \"...\"" for k, o in (("offline", "offline"),
                                                            ("model", "model_file")) if o in needs)
        problems.append(f"updater: updater {name!r} needs {wanted} (the offline database or a "
                        "pre-trained model)")
    given = set(cfg.updater_options)
    unknown = sorted(given - set(accepted))
    if unknown:
        problems.append(f"updater_options: unknown option(s) {', '.join(unknown)} of updater "
                        f"{name!r}; allowed: {', '.join(accepted) or '(none)'}")
    for option, instead in (("offline", "offline"), ("model_file", "model")):
        if option in given:
            problems.append(f"updater_options.{option}: give it as the site's {instead} = "
                            "\"...\" (a path)")
    try:
        if cfg.model is not None:
            load_model(cfg.model)
        if cfg.offline is not None:
            read_history(cfg.offline)
    except UpdaterError as exc:
        problems.append(f"{'model' if cfg.model is not None else 'offline'}: {exc}")
    return cfg, problems
