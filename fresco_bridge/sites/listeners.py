"""Who takes what leaves a site: its committed steps and events (the values:
``site_output.py``), to a list of listeners.

A site holds an ordered list of listeners (``Site.add_listener``): the run record's writer
(``record/site.py``), the telemetry taps with the online monitors (``telemetry/taps.py``), and
whatever else needs a site's committed steps (an updater learning from a tested element).
Each gets every committed step (``step_committed``), every event (``site_event``) and/or every
trial that reached the controller (``trial_forwarded``, with its measurement to read), in the
order they were added, on the bridge's loop: a listener must not block (a bounded-queue
append, a buffered line, a counter).
"""

from __future__ import annotations

from collections.abc import Callable
from typing import TYPE_CHECKING, Protocol, runtime_checkable

from ..site_output import CommittedStep, SiteNotice

if TYPE_CHECKING:
    from ..controls.base import Daq
from ..telemetry.schema import SiteStatus

__all__ = ["EventListener", "ForwardedTrial", "Listeners", "StepListener",
           "StepValuesListener", "TrialListener"]


@runtime_checkable
class StepListener(Protocol):
    def step_committed(self, step: CommittedStep) -> None: ...


class StepValuesListener(Protocol):
    """A step listener that also takes a committed step as the values it needs (the run
    record's writer, the monitor batch): when every step listener of a site has
    ``step_values``, the site calls it instead of ``step_committed`` and builds no
    ``CommittedStep`` (once a step, on the step loop)."""

    def step_committed(self, step: CommittedStep) -> None: ...

    def step_values(self, session: int, step: int, time: float, ctrl: tuple[float, ...],
                    daq_disp: tuple[float, ...]) -> None:
        """The same as ``step_committed`` of ``CommittedStep(site, session, step, time, …,
        ctrl, daq_disp, …)``."""
        ...


@runtime_checkable
class EventListener(Protocol):
    def site_event(self, notice: SiteNotice, status: SiteStatus) -> None:
        """``status``: the site's status right after the event (telemetry retains it)."""
        ...


class ForwardedTrial(Protocol):
    """A trial that reached the site's controller, and the one measurement of it (read once,
    shared with the site's own force request): what a site publishes to its trial listeners,
    so that nothing else ever reaches into the site for it."""

    session: int
    step: int
    """The step being tried (the last committed + 1)."""
    time: float
    """The trial's pseudo-time."""
    ctrl: tuple[float, ...]
    """The command that went to the controller."""

    async def read(self) -> Daq | None:
        """This trial's measurement; None once it is not the site's current trial any more
        (committed, superseded) or the site stopped forwarding (HOLD, FAULT)."""
        ...


@runtime_checkable
class TrialListener(Protocol):
    def trial_forwarded(self, trial: ForwardedTrial) -> None:
        """A trial reached the controller (every trial: an implicit scheme's iterations too)."""
        ...


StepValues = Callable[[int, int, float, tuple[float, ...], tuple[float, ...]], None]


class Listeners:
    """A site's listeners, by what they take, in the order they were added (composed into
    every site: what leaves a site goes through here)."""

    def __init__(self) -> None:
        self.steps: list[StepListener] = []
        self.step_values: tuple[StepValues, ...] | None = None
        """Every step listener's ``step_values``, when they all have one (no
        ``CommittedStep`` to build per commit)."""
        self.events: list[EventListener] = []
        self.trials: list[TrialListener] = []

    def add(self, listener: object) -> None:
        """Committed steps, events and/or forwarded trials go to ``listener`` from now on,
        after those added before it."""
        if isinstance(listener, StepListener):
            self.steps.append(listener)
            lean = [getattr(x, "step_values", None) for x in self.steps]
            self.step_values = None if None in lean else tuple(lean)  # type: ignore[arg-type]
        if isinstance(listener, EventListener):
            self.events.append(listener)
        if isinstance(listener, TrialListener):
            self.trials.append(listener)

    def event(self, notice: SiteNotice, status: SiteStatus) -> None:
        for listener in self.events:
            listener.site_event(notice, status)

    def trial(self, trial: ForwardedTrial) -> None:
        for listener in self.trials:
            listener.trial_forwarded(trial)
