"""The controller guard of a site, against a scripted controller (pure logic, no sockets):
deadline, HOLD on failure, recovery of a lost controller with the setpoint re-sent once."""

from __future__ import annotations

import asyncio
import math
from typing import Any

import pytest

from fresco_bridge.config import parse_config
from fresco_bridge.controls.base import Controller, ControllerError, ControllerLinkError, Daq
from fresco_bridge.site_output import SiteNotice
from fresco_bridge.sites import SiteState
from fresco_bridge.sites.experimental import ExperimentalSite
from fresco_bridge.telemetry.schema import SiteStatus
from protocol import Signals, SignalSizes

CFG = parse_config('[[sites]]\nname = "g"\nport = 0\n').sites[0]
SIZES = SignalSizes(disp=0, vel=0, accel=0, force=1, time=0)


class Scripted(Controller):
    """A network-like controller whose reads fail as scripted (``failures``: exceptions)."""

    inline = False
    n_actuators = 1

    def __init__(self, failures: list[Exception], hang: float = 0.0) -> None:
        self.failures = failures
        self.hang = hang
        self.sent: list[tuple[float, ...]] = []
        self.holds = 0
        self.position = 0.0

    async def set_ctrl(self, disp: tuple[float, ...]) -> None:
        self.sent.append(disp)
        self.position = disp[0]

    async def get_daq(self) -> Daq:
        if self.hang:
            await asyncio.sleep(self.hang)
        if self.failures:
            raise self.failures.pop(0)
        return Daq((self.position,), (10.0 * self.position,))

    async def commit(self) -> None:
        return None

    async def tangent_stiffness(self) -> tuple[float, ...]:
        return (10.0,)

    async def initial_stiffness(self) -> tuple[float, ...]:
        return (10.0,)

    async def hold(self) -> None:
        self.holds += 1


class Events:
    def __init__(self) -> None:
        self.kinds: list[str] = []

    def site_event(self, notice: SiteNotice, status: SiteStatus) -> None:
        self.kinds.append(notice.kind)


def _site(controller: Controller, recovery: float) -> tuple[ExperimentalSite, Events]:
    site = ExperimentalSite(CFG, controller, None, controller_timeout=0.2,
                            controller_recovery=recovery)
    events = Events()
    site.add_listener(events)
    site.open_session("127.0.0.1:9")
    return site, events


def _trial(d: float) -> Signals:
    return Signals(disp=(d,), vel=(0.0,), accel=(0.0,), time=(0.1,))


def test_a_lost_controller_that_comes_back_is_recovered_and_the_setpoint_resent_once() -> None:
    controller = Scripted([ControllerLinkError("link lost"), ControllerLinkError("refused")])
    site, events = _site(controller, recovery=5.0)

    async def step() -> Signals:
        await site.set_trial(_trial(0.3))
        return await site.out_signals(SIZES)

    out = asyncio.run(step())
    assert out.force == (3.0,)
    assert site.state is SiteState.RUNNING and site.guard.recovering_since is None
    assert controller.sent == [(0.3,), (0.3,)]  # the command, then re-sent once after the probe
    assert controller.holds == 1
    assert events.kinds[-3:] == ["hold", "recovering", "recovered"]
    assert site.holds == 1 and site.pending is None


def test_without_recovery_a_lost_controller_holds_and_the_integrator_is_told_to_stop() -> None:
    controller = Scripted([ControllerLinkError("link lost")])
    site, events = _site(controller, recovery=0.0)

    async def step() -> Signals:
        await site.set_trial(_trial(0.3))
        return await site.out_signals(SIZES)

    out = asyncio.run(step())
    assert math.isnan(out.force[0])
    assert site.state is SiteState.HOLD and "link lost" in site.reason
    assert events.kinds[-2:] == ["hold", "integrator-stop"]


@pytest.mark.parametrize("failure", [ControllerError("FAULT: stroke limit")])
def test_a_controller_fault_is_never_recovered(failure: Exception) -> None:
    controller = Scripted([failure])
    site, events = _site(controller, recovery=5.0)

    async def step() -> Signals:
        await site.set_trial(_trial(0.3))
        return await site.out_signals(SIZES)

    assert math.isnan(asyncio.run(step()).force[0])
    assert "recovering" not in events.kinds and site.state is SiteState.HOLD
    assert controller.sent == [(0.3,)]


def test_a_silent_controller_misses_the_deadline_and_holds() -> None:
    controller = Scripted([], hang=1.0)
    site, _ = _site(controller, recovery=0.0)

    async def step() -> Signals:
        await site.set_trial(_trial(0.3))
        return await site.out_signals(SIZES)

    assert math.isnan(asyncio.run(step()).force[0])
    assert "did not answer get_daq within 0.2 s" in site.reason


class Counting(Scripted):
    def __init__(self) -> None:
        super().__init__([], hang=0.02)
        self.reads = 0

    async def get_daq(self) -> Daq:
        self.reads += 1
        return await super().get_daq()


class Trials:
    """A trial listener: what the site publishes of each forwarded trial."""

    def __init__(self) -> None:
        self.trials: list[Any] = []

    def trial_forwarded(self, trial: Any) -> None:
        self.trials.append(trial)


def test_concurrent_reads_of_one_trial_share_one_controller_read() -> None:
    """A same-step twin (reading the published trial) and the source's own force request ask
    at once: one read, one measurement for both; a new trial reads again, and a trial that is
    not the site's current one any more reads nothing."""
    async def main() -> None:
        controller = Counting()
        site, _ = _site(controller, recovery=0.0)
        listener = Trials()
        site.add_listener(listener)
        await site.set_trial(_trial(0.5))
        (first_trial,) = listener.trials
        assert (first_trial.step, first_trial.ctrl) == (1, (0.5,))
        first, second = await asyncio.wait_for(
            asyncio.gather(first_trial.read(), site.out_signals(SIZES)), 5.0)
        assert first is not None and first.disp == (0.5,) and second.force == first.force
        assert controller.reads == 1
        await site.set_trial(_trial(0.7))
        assert await first_trial.read() is None  # superseded
        daq = await asyncio.wait_for(listener.trials[-1].read(), 5.0)
        assert daq is not None and daq.disp == (0.7,) and controller.reads == 2

    asyncio.run(main())


def test_a_waiting_reader_reads_again_when_the_shared_read_is_abandoned() -> None:
    async def main() -> None:
        controller = Counting()
        controller.hang = 0.1  # within the site's 0.2 s controller deadline
        site, _ = _site(controller, recovery=0.0)
        listener = Trials()
        site.add_listener(listener)
        await site.set_trial(_trial(0.5))
        (trial,) = listener.trials
        first = asyncio.ensure_future(trial.read())
        await asyncio.sleep(0.01)
        second = asyncio.ensure_future(trial.read())
        await asyncio.sleep(0.01)
        first.cancel()
        daq = await asyncio.wait_for(second, 5.0)
        assert daq is not None and daq.disp == (0.5,) and controller.reads == 2
        with pytest.raises(asyncio.CancelledError):
            await first

    asyncio.run(main())
