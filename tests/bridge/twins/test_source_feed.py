"""The source's published trials and commits as a same-step twin awaits them: no polling, a
deadline, the committed measurement when the source's commit came first (explicit schemes'
race), the true reason when same-step is impossible (an implicit scheme's iterations)."""

from __future__ import annotations

import asyncio
from dataclasses import dataclass

import pytest

from fresco_bridge.controls.base import Daq
from fresco_bridge.site_output import CommittedStep, SiteNotice
from fresco_bridge.telemetry.schema import SiteStatus
from fresco_bridge.twins.source import SameStepImpossible, SourceFeed


@dataclass
class Trial:
    session: int
    step: int
    time: float
    ctrl: tuple[float, ...]
    current: bool = True
    reads: int = 0

    async def read(self) -> Daq | None:
        self.reads += 1
        return Daq(self.ctrl, (10.0 * self.ctrl[0],)) if self.current else None


def commit(step: int, time: float, d: float, f: float) -> CommittedStep:
    return CommittedStep("damper", 1, step, time, (d,), (d,), (d,), (f,), "RUNNING")


def test_the_twin_waits_for_the_sources_trial_and_reads_its_measurement() -> None:
    async def main() -> None:
        feed = SourceFeed("damper")
        waiting = asyncio.ensure_future(feed.measurement(3, 0.03, 1.0))
        await asyncio.sleep(0.01)
        assert not waiting.done()  # no poll: it waits for the publication
        trial = Trial(1, 3, 0.03, (0.5,))
        feed.trial_forwarded(trial)
        assert await asyncio.wait_for(waiting, 1.0) == (0.5, 5.0, False)
        assert trial.reads == 1

    asyncio.run(main())


def test_a_source_committed_before_the_twins_request_gives_its_committed_measurement() -> None:
    async def main() -> None:
        feed = SourceFeed("damper")
        feed.trial_forwarded(Trial(1, 50, 0.5, (0.2,), current=False))
        feed.step_committed(commit(50, 0.5, 0.2, 2.1))
        assert await feed.measurement(50, 0.5, 1.0) == (0.2, 2.1, True)

    asyncio.run(main())


def test_no_trial_within_the_deadline_is_a_true_reason() -> None:
    async def main() -> None:
        feed = SourceFeed("damper")
        with pytest.raises(SameStepImpossible, match=r"did not reach its controller within "
                           r"0\.05 s of the twin's trial"):
            await feed.measurement(1, 0.01, 0.05)

    asyncio.run(main())


def test_several_distinct_trials_of_one_step_make_same_step_impossible() -> None:
    async def main() -> None:
        feed = SourceFeed("damper")
        feed.trial_forwarded(Trial(1, 1, 0.01, (0.1,)))
        feed.trial_forwarded(Trial(1, 1, 0.01, (0.1,)))  # the same command again: one trial
        assert feed.iterating is None
        feed.trial_forwarded(Trial(1, 1, 0.01, (0.12,)))
        assert feed.iterating == (1, 1)
        with pytest.raises(SameStepImpossible, match=r"several trials .*implicit"):
            await feed.measurement(1, 0.01, 1.0)
        feed.trial_forwarded(Trial(2, 1, 0.01, (0.1,)))  # a new session: its own scheme
        assert feed.iterating is None

    asyncio.run(main())


def test_a_source_that_stops_ends_the_wait_with_nothing_to_learn() -> None:
    async def main() -> None:
        feed = SourceFeed("damper")
        waiting = asyncio.ensure_future(feed.measurement(2, 0.02, 5.0))
        await asyncio.sleep(0.01)
        feed.site_event(SiteNotice("damper", 1, 1, 0.01, "hold", "x", {}),
                        SiteStatus(site="damper", state="HOLD", session=1, step=1, time=0.01,
                                   reason="x", holds=1))
        assert await asyncio.wait_for(waiting, 1.0) is None

    asyncio.run(main())


def test_a_trial_of_the_committed_command_is_neither_the_steps_trial_nor_an_iteration() -> None:
    """``CentralDifference`` and Newmark's predictor begin each step with the committed
    displacement again: the step's trial is the one that moves."""
    async def main() -> None:
        feed = SourceFeed("damper")
        feed.step_committed(commit(2, 0.02, 0.3, 3.0))
        waiting = asyncio.ensure_future(feed.measurement(3, 0.03, 1.0))
        feed.trial_forwarded(Trial(1, 3, 0.03, (0.3,)))  # the committed state again
        await asyncio.sleep(0.01)
        assert not waiting.done() and feed.iterating is None
        feed.trial_forwarded(Trial(1, 3, 0.03, (0.7,)))
        assert await asyncio.wait_for(waiting, 1.0) == (0.7, 7.0, False)
        assert feed.iterating is None

    asyncio.run(main())
