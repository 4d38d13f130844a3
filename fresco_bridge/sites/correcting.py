"""The displacement correction of an experimental site (``[sites.correction]``).

Each trial of a site with a correction goes here instead of the direct step path: the loop of
``correction_loop.py`` moves the controller to the target and corrects, every command through
the site's own gate (``SiteCommandPath``: the pause, the ctrl limits, the state table, the
controller guard, each command a trial line in the record) and every measurement through the
site's acquisition (daq limits, non-finite checks, a daq line). The measurement at the last
command reached is the trial's measurement, so the integrator's answer is the force there. A
terminal verdict that is not convergence follows the policy: HOLD (the loop enters it through
the path: NaN answers, nothing beyond is forwarded) or an event and the answer. Every trial
leaves a correction line in the record (``record/lines.py``, format 6); the last trial's
corrections and residual are in ``ctl status`` and the metrics, and a trial that needed more than
half of ``max_iterations`` is logged (rate-limited) and raised as a ``correction-warning`` event
at most once per log interval.

Not compiled (``_compiled.py``): a corrected step waits for several controller round trips; the
site's direct path, without a correction, is unchanged.
"""

from __future__ import annotations

import logging
from typing import TYPE_CHECKING, Protocol

from protocol import Signals

from ..config_model import ConfigError
from ..controls.base import Controller, Daq
from ..logs import RateLimitedLog
from ..safety import CorrectionConfig, SiteState
from ..setups import Setup
from ..telemetry.schema import CorrectionSample
from .correction_loop import CorrectionLoop, StepCorrection
from .gate import CommandGate

if TYPE_CHECKING:
    from ..record.site import SiteRecorder
    from ..telemetry.metrics import SiteMetrics

__all__ = ["CorrectedSite", "SiteCommandPath", "SiteCorrection"]

log = logging.getLogger("fresco_bridge.site")
RUNNING = SiteState.RUNNING


class CorrectedSite(Protocol):
    """What the correction needs of its site (``ExperimentalSite``)."""

    name: str

    @property
    def state(self) -> SiteState: ...

    @property
    def session(self) -> int: ...

    step: int
    time: float
    trial: Signals
    ctrl: tuple[float, ...]
    setup: Setup
    controller: Controller
    gate: CommandGate
    recorder: SiteRecorder | None
    metrics: SiteMetrics | None

    @property
    def sent(self) -> tuple[float, ...] | None: ...

    async def measure(self) -> Daq | None:
        """A fresh, checked and recorded measurement; None when no longer RUNNING."""
        ...

    def enter_hold(self, reason: str) -> None: ...

    def event(self, kind: str, reason: str, **extra: object) -> None: ...

    def forwarded(self) -> None:
        """The trial's last command is reached: the site's trial listeners get it."""
        ...


class SiteCommandPath:
    """``CommandPath`` through an experimental site: its gate, guard, record and state."""

    __slots__ = ("site", "trial")

    def __init__(self, site: CorrectedSite) -> None:
        self.site = site
        self.trial: Signals = site.trial
        """The integrator's trial being corrected (its trial lines in the record)."""

    async def send(self, ctrl: tuple[float, ...]) -> tuple[float, ...] | None:
        site = self.site
        await site.gate.set_trial_later(self.trial, ctrl)
        if site.state is not RUNNING or site.sent != site.ctrl:
            return None
        return site.ctrl

    async def acquire(self) -> Daq | None:
        return await self.site.measure()

    async def hold(self, reason: str) -> None:
        self.site.enter_hold(reason)


class SiteCorrection:
    """One experimental site's correction: the loop over its path, and what it last did."""

    def __init__(self, site: CorrectedSite, config: CorrectionConfig) -> None:
        self.site = site
        self.path = SiteCommandPath(site)
        try:
            settings = config.to_settings(site.setup.n_actuators)
            self.loop = CorrectionLoop(self.path, settings, site.controller,
                                       external=config.measured == "external")
        except ValueError as exc:  # what the controller built from the config cannot give
            raise ConfigError(f"site {site.name}: [sites.correction]: {exc}") from None
        self.settings = settings
        self.last: StepCorrection | None = None
        self.last_step = 0
        """The step the last trial belongs to (its commit's number)."""
        self.trials = 0
        """Trials corrected (every trial: Newton iterations of one step too)."""
        self.warnings = 0
        """Trials that needed more than half of ``max_iterations`` corrections."""
        self.unconverged = 0
        """Trials that ended otherwise than converged."""
        self.most = 0
        """The most corrections one trial needed."""
        self._log = RateLimitedLog(log)

    async def trial(self, trial: Signals, target: tuple[float, ...]) -> None:
        """Move to ``target`` and correct (the site's code 3 while it has a correction)."""
        site = self.site
        self.path.trial = trial
        held = self._held(target)
        if held is not None and site.recorder is not None:  # its trial line, as any trial's
            site.recorder.trial(site.session, site.step, site.time, trial.disp, held)
        step = await self.loop.run(target, held=held)
        self.last, self.last_step = step, site.step + 1
        self.trials += 1
        self.most = max(self.most, step.corrections)
        verdict = step.verdict
        if verdict.event:
            self.unconverged += 1
        if site.recorder is not None:
            site.recorder.correction(
                site.session, site.step + 1, target, verdict.outcome, step.residual,
                [(i.command, i.measured) for i in step.iterations])
        if site.metrics is not None:
            site.metrics.correction(step.corrections, step.residual)
        if verdict.event and not verdict.hold and verdict.outcome != "refused":
            site.event("correction", f"displacement correction: {verdict.describe()}; "
                       "answered with the force measured at the last position reached",
                       step=site.step, outcome=verdict.outcome, corrections=step.corrections,
                       residual=step.residual)
        if step.warn:
            self.warnings += 1
            if self._log.warning("many corrections", "site %s: step %d needed %d of "
                                 "max_iterations %d displacement corrections (residual %.4g "
                                 "mm): the rig drifts or the gain is low", site.name,
                                 site.step + 1, step.corrections, self.settings.max_iterations,
                                 step.residual):
                site.event("correction-warning", f"{step.corrections} of max_iterations "
                           f"{self.settings.max_iterations} corrections needed",
                           step=site.step, corrections=step.corrections,
                           residual=step.residual)
        if site.state is RUNNING and site.sent == site.ctrl:
            site.forwarded()

    def _held(self, target: tuple[float, ...]) -> tuple[float, ...] | None:
        """The command the controller holds for ``target`` when the last trial had this same
        target and the site is still where that trial's correction left it (a repeated trial:
        a Newton iteration, a re-sent step); None: move to the target first."""
        last, site = self.last, self.site
        if last is None or last.target != target or not last.iterations \
                or site.state is not RUNNING:
            return None
        command = last.iterations[-1].command
        return command if site.sent == command else None

    def sample(self, committed: int) -> CorrectionSample | None:
        """The last trial's correction when it is committed step ``committed``'s."""
        last = self.last
        if last is None or self.last_step != committed:
            return None
        return CorrectionSample(last.corrections, last.residual, last.verdict.outcome)

    def status(self) -> dict[str, object]:
        """``ctl status``'s ``correction``: the last trial and the counts so far."""
        last = self.last
        return {
            "corrections": None if last is None else last.corrections,
            "residual": None if last is None else last.residual,
            "outcome": None if last is None else last.verdict.outcome,
            "trials": self.trials, "most": self.most, "warnings": self.warnings,
            "unconverged": self.unconverged,
            "max_iterations": self.settings.max_iterations,
        }
