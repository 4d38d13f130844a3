"""Committed steps and events leave a site through its list of listeners: the record's writer
first, then whatever was added (telemetry taps, an updater), in order, with the same values."""

from __future__ import annotations

import asyncio
from pathlib import Path
from typing import Any

from fresco_bridge.config import parse_config
from fresco_bridge.eager import Suspended, start_eager
from fresco_bridge.record import RunRecord, read_record
from fresco_bridge.site_output import CommittedStep, SiteNotice
from fresco_bridge.sites.experimental import ExperimentalSite
from fresco_bridge.sites.experimental_kind import site_controller as make_controller
from fresco_bridge.telemetry.schema import SiteStatus
from protocol import Signals, SignalSizes

SITE = """
[[sites]]
name = "spring"
port = 0
[sites.controller]
model = "elastic"
params = { k = 4.0 }
[[sites.limits]]
disp_max = 1.0
"""
SIZES = SignalSizes(disp=0, vel=0, accel=0, force=1, time=0)


def _run(coro: Any) -> Any:
    r = start_eager(coro)
    assert not isinstance(r, Suspended)
    return r


class Collector:
    """A step and event listener that keeps everything it gets, in arrival order."""

    def __init__(self, log: list[str]) -> None:
        self.steps: list[CommittedStep] = []
        self.events: list[tuple[SiteNotice, SiteStatus]] = []
        self.log = log

    def step_committed(self, step: CommittedStep) -> None:
        self.steps.append(step)
        self.log.append(f"step {step.step}")

    def site_event(self, notice: SiteNotice, status: SiteStatus) -> None:
        self.events.append((notice, status))
        self.log.append(f"event {notice.kind}")


class StepsOnly:
    def __init__(self) -> None:
        self.seen: list[int] = []

    def step_committed(self, step: CommittedStep) -> None:
        self.seen.append(step.step)


def _step(site: ExperimentalSite, d: float, t: float) -> None:
    zero = (0.0,)
    _run(site.set_trial(Signals(disp=(d,), vel=zero, accel=zero, time=(t,))))
    _run(site.out_signals(SIZES))
    _run(site.commit())


def test_listeners_get_every_committed_step_and_event_in_order(tmp_path: Path) -> None:
    cfg = parse_config(SITE).sites[0]
    record = RunRecord.create(tmp_path, "listeners", SITE, {}, fsync="off")
    site = ExperimentalSite(cfg, make_controller(cfg), record, controller_timeout=1.0)
    log: list[str] = []
    first, steps_only = Collector(log), StepsOnly()
    site.add_listener(first)
    site.add_listener(steps_only)
    site.open_session("127.0.0.1:1")
    for i in range(1, 4):
        _step(site, 0.1 * i, 0.01 * i)
    _run(site.set_trial(Signals(disp=(2.0,), vel=(0.0,), accel=(0.0,), time=(0.04,))))
    record.close()

    assert [s.step for s in first.steps] == [1, 2, 3] == steps_only.seen
    last = first.steps[-1]
    assert last == CommittedStep("spring", 1, 3, 0.03, (0.30000000000000004,),
                                 (0.30000000000000004,), (0.30000000000000004,),
                                 (1.2000000000000002,), "RUNNING")
    kinds = [notice.kind for notice, _ in first.events]
    assert kinds == ["session-open", "limit", "hold"]
    hold, status = first.events[-1]
    assert hold.step == 3 and status.state == "HOLD" and status.holds == 1
    assert log.index("event session-open") < log.index("step 1") < log.index("event hold")
    # the record's writer is the first listener: its lines are the same steps and events
    lines = list(read_record(record.directory))
    assert [r["step"] for r in lines if r["kind"] == "commit"] == [1, 2, 3]
    assert [r["event"] for r in lines if r["kind"] == "event"] == kinds


def test_a_site_without_record_or_listeners_still_steps() -> None:
    cfg = parse_config(SITE).sites[0]
    site = ExperimentalSite(cfg, make_controller(cfg), None, controller_timeout=1.0)
    assert site.recorder is None
    site.open_session("127.0.0.1:1")
    _step(site, 0.5, 0.01)
    assert site.step == 1 and site.daq.force == (2.0,)
    asyncio.run(asyncio.sleep(0))  # nothing was scheduled on a loop


class Values:
    """A step listener that also takes a committed step as values (``StepValuesListener``)."""

    def __init__(self) -> None:
        self.seen: list[tuple[Any, ...]] = []

    def step_committed(self, step: CommittedStep) -> None:
        self.seen.append(("step", step.session, step.step, step.time, step.ctrl, step.daq_disp))

    def step_values(self, session: int, step: int, time: float, ctrl: tuple[float, ...],
                    daq_disp: tuple[float, ...]) -> None:
        self.seen.append(("values", session, step, time, ctrl, daq_disp))


def test_listeners_that_all_take_values_get_no_committed_step(tmp_path: Path) -> None:
    cfg = parse_config(SITE).sites[0]
    lean, full = Values(), Values()
    for values, extra in ((lean, None), (full, StepsOnly())):
        record = RunRecord.create(tmp_path / str(extra is None), "values", SITE, {}, fsync="off")
        site = ExperimentalSite(cfg, make_controller(cfg), record, controller_timeout=1.0)
        site.add_listener(values)
        if extra is not None:  # a listener that needs the CommittedStep: every one gets it
            site.add_listener(extra)
            assert site.listeners.step_values is None
        else:
            assert site.listeners.step_values is not None  # the record's writer takes values too
        site.open_session("127.0.0.1:1")
        for i in range(1, 4):
            _step(site, 0.1 * i, 0.01 * i)
        record.close()
        steps = [(r["step"], r["time"]) for r in read_record(record.directory)
                 if r["kind"] == "commit"]
        assert steps == [(1, 0.01), (2, 0.02), (3, 0.03)]
    assert [s[0] for s in lean.seen] == ["values"] * 3
    assert [s[0] for s in full.seen] == ["step"] * 3
    assert [s[1:] for s in lean.seen] == [s[1:] for s in full.seen]
    assert lean.seen[-1][1:] == (1, 3, 0.03, (0.30000000000000004,), (0.30000000000000004,))
