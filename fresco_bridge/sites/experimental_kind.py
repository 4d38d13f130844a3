"""The ``experimental`` site kind: a controller (``controls/``) behind a setup and the limits.

Its config adds the ``[sites.controller]`` table (a discriminated union of the controller
kinds of ``controls/registry.py``; ``sim`` when omitted); its group builds one
``ExperimentalSite`` per entry, connects the controllers at start (an unreachable one is
logged: the site HOLDs at its first command) and closes them at the end.
"""

from __future__ import annotations

import asyncio
import logging
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import TYPE_CHECKING, Annotated, Any, Literal, Union

from pydantic import Discriminator, Field, Tag

from ..config_model import ConfigError
from ..controls.base import Controller, ControllerError, InlineController
from ..controls.kind import ControllerConfigBase
from ..controls.registry import CONTROLLER_KINDS, controller_kind, make_controller
from ..controls.sim import SimControllerConfig
from ..safety import CorrectionConfig
from ..setups import make_setup
from ..tangent import TangentMethod
from .base import Site
from .experimental import ExperimentalSite
from .kind import SiteConfigBase, SiteContext, SiteKind

if TYPE_CHECKING:
    from ..telemetry.metrics import Metrics

__all__ = ["KIND", "ExperimentalSiteConfig", "controlled_site", "site_controller"]

log = logging.getLogger("fresco_bridge")


def _controller_kind(v: Any) -> str:
    """``kind`` may be omitted for the default in-process simulated controller."""
    kind = v.get("kind", "sim") if isinstance(v, dict) else getattr(v, "kind", "sim")
    return str(kind)


if TYPE_CHECKING:
    ControllerConfig = ControllerConfigBase
else:  # the discriminated union of every registered kind's config model
    ControllerConfig = Annotated[
        Union[tuple(Annotated[k.config, Tag(k.name)] for k in CONTROLLER_KINDS.values())],  # noqa: UP007
        Discriminator(_controller_kind),
    ]


class ExperimentalSiteConfig(SiteConfigBase):
    """A site whose force is measured: a controller behind the setup and the limits."""

    kind: Literal["experimental"] = "experimental"
    controller: ControllerConfig = Field(default_factory=SimControllerConfig)
    """A kind of ``controls/registry.py``: ``sim`` (in-process specimen, the default), ``rig``,
    ``modbus``, ``mts``."""
    tangent: TangentMethod = "controller"
    """The tangent answered to action 13: the controller's (``controller``), its first answer
    kept (``initial``), or estimated from the committed steps (``broyden``, ``bfgs``,
    ``transpose``; docs/openfresco-setups.md)."""
    correction: CorrectionConfig | None = None
    """``[sites.correction]``: the outer-loop displacement correction per control point
    (``sites/correcting.py``); off when absent."""

    def actuators_fit(self, n_actuators: int) -> None:
        geometry = make_setup(self.setup, self.dofs).specimen_geometry()
        problem = controller_kind(self.controller.kind).actuators_problem(
            self.controller, n_actuators, geometry)
        if problem is not None:
            raise ValueError(f"{problem} (setup {self.setup} with {self.dofs} DOF(s))")
        if self.correction is not None:
            self.correction.to_settings(n_actuators)  # a per-point list that does not fit
            if self.correction.measured == "external" and \
                    self.controller.external_channel() is None:
                raise ValueError(
                    f"[sites.correction] measured = \"external\", but [sites.controller] "
                    f"(kind {self.controller.kind}) names no external channel (rig: external = "
                    "\"specimen\", modbus: external_register, mts: external_field; "
                    "docs/configuration.md, \"Which displacement is measured\")")


def site_controller(cfg: ExperimentalSiteConfig) -> Controller:
    """The controller adapter a site's config asks for (its kind's factory, ``controls/``)."""
    setup = make_setup(cfg.setup, cfg.dofs)  # setups/ owns the count and the geometry
    return make_controller(cfg.controller, setup.n_actuators, setup.specimen_geometry())


def controlled_site(cfg: SiteConfigBase, controller: Controller, context: SiteContext) -> Site:
    """A site answering through ``controller`` behind ``cfg``'s setup and limits, with the
    shared site core (sessions, states, operator, NaN stop, listeners, record, status): how a
    kind whose force comes from a model in the bridge (a twin) serves it."""
    return ExperimentalSite(cfg, controller, context.record,
                            controller_timeout=context.controller_timeout)


class ExperimentalGroup:
    """The experimental sites of one bridge: each with its controller."""

    def __init__(self, configs: Sequence[ExperimentalSiteConfig], context: SiteContext) -> None:
        self._sites = {cfg.name: ExperimentalSite(
            cfg, site_controller(cfg), context.record,
            controller_timeout=context.controller_timeout,
            controller_recovery=context.controller_recovery) for cfg in configs}
        self._timeout = context.controller_timeout
        if context.resume is not None:
            restore = SpecimenRestore(self._sites, context.resume.directory)
            context.resume.add(restore.line, restore.end, kinds=SpecimenRestore.KINDS)

    @property
    def sites(self) -> Mapping[str, Site]:
        return self._sites

    async def start(self) -> None:
        for site in self._sites.values():
            try:
                await asyncio.wait_for(site.controller.connect(), self._timeout)
            except (ControllerError, TimeoutError) as exc:
                # Not fatal: the site serves anyway and HOLDs at the first command if the
                # controller is still unreachable (adapters reconnect on reads).
                log.error("site %s: controller not reachable at start: %s", site.name,
                          exc or "timeout")

    def wire(self, sites: Mapping[str, Site]) -> None:
        """Nothing: an experimental site needs no other site."""

    def attach_metrics(self, metrics: Metrics) -> None:
        """Nothing beyond the per-site metrics the bridge sets."""

    async def close(self) -> None:
        for site in self._sites.values():
            try:
                await asyncio.wait_for(site.controller.close(), self._timeout)
            except Exception as exc:  # closing must go on for the other sites
                log.warning("site %s: controller close failed: %s", site.name, exc)


class SpecimenRestore:
    """``serve --resume``: every in-process specimen (``sim``, ``rig``) gets back the state
    the interrupted run left it in, by replaying the record's commands in their order (a
    reader of the resume's one pass over the record, ``record/scan.py``): each trial that
    went to the controller, each commit, a fresh specimen at each new session where the
    controller resets then. A controller outside the bridge (a real specimen) is where the
    test left it: resume assumes the lab kept it there (``docs/architecture.md``, "Crash and
    resume")."""

    def __init__(self, sites: Mapping[str, ExperimentalSite], run_dir: Path) -> None:
        self.run_dir = run_dir
        self._inline: dict[str, tuple[ExperimentalSite, InlineController]] = {
            name: (site, inline) for name, site in sites.items()
            if (inline := site.controller.in_process()) is not None}
        self._session: dict[str, int] = {}
        self._sent: dict[str, tuple[float, ...] | None] = {}
        self.counts = dict.fromkeys(self._inline, 0)

    KINDS = ("trial", "commit")
    """The lines it reads."""

    def line(self, rec: dict[str, Any]) -> None:
        """A trial or commit line (``KINDS``)."""
        entry = self._inline.get(rec.get("site", ""))
        if entry is None:
            return
        site, controller = entry
        try:
            number = int(rec.get("session", 0))
            if self._session.get(site.name) != number:
                if site.name in self._session and site.resets_on_new_session:
                    controller.reset()
                self._session[site.name], self._sent[site.name] = number, None
            if rec["kind"] == "trial":
                command = tuple(float(v) for v in rec["ctrl"])
                if command != self._sent[site.name]:  # the site sends a command once
                    controller.set_ctrl_now(command)
                    self._sent[site.name] = command
            else:
                controller.commit_now()
                self.counts[site.name] += 1
        except (KeyError, ValueError, ControllerError) as exc:
            raise ConfigError(f"resuming {self.run_dir}: the in-process specimens could not "
                              f"be restored from the record: {exc}") from exc

    def end(self) -> None:
        for name, steps in self.counts.items():
            log.warning("site %s: in-process specimen restored from the record (%d committed "
                        "step(s) replayed)", name, steps)


KIND = SiteKind(
    name="experimental",
    config=ExperimentalSiteConfig,
    factory=ExperimentalGroup,
    summary="a controller (`[sites.controller]`) behind the setup and the limits; its force "
            "is measured",
)
