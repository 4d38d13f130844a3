"""The twin controller over a fake learner, and the learner's source listener: a non-finite
source measurement is never sent for training."""

from __future__ import annotations

import asyncio
import math

import pytest

from fresco_bridge.controls.base import ControllerError, Daq
from fresco_bridge.site_output import CommittedStep
from fresco_bridge.twins.controller import TwinController
from fresco_bridge.twins.learner import Learner, LearnerError
from fresco_bridge.twins.worker import LearnerSpec, TwinSpec


class FakeLearner:
    source = "damper"

    def __init__(self) -> None:
        self.lost = False
        self.commits: list[str] = []

    async def trial(self, twin: str, d: float, *, step: int, same_step: bool = False,
                    measured: tuple[float, float] | None = None
                    ) -> tuple[float, float, int, float, float | None, tuple[int, int] | None]:
        if self.lost:
            raise LearnerError("learner of damper is lost")
        return 10.0 * d, 10.0, 7, 0.001, None, None

    def commit(self, twin: str) -> None:
        if self.lost:
            raise LearnerError("learner of damper is lost")
        self.commits.append(twin)

    async def initial(self, twin: str) -> float:
        return 12.0

    def status(self, twin: str, *, active: bool = True) -> dict[str, object]:
        return {"learner": "live", "steps_trained": 7}


def controller(learner: FakeLearner) -> TwinController:
    return TwinController(learner, "twin1", updater="online_ukf",  # type: ignore[arg-type]
                          causality="previous-step")


def test_the_twin_answers_its_learner_and_a_lost_learner_is_a_controller_error() -> None:
    async def run() -> None:
        learner = FakeLearner()
        ctrl = controller(learner)
        assert await ctrl.initial_stiffness() == (12.0,)
        assert await ctrl.tangent_stiffness() == (12.0,)  # no trial yet: the initial one
        await ctrl.set_ctrl((0.5,))
        assert await ctrl.get_daq() == Daq((0.5,), (5.0,))
        assert await ctrl.tangent_stiffness() == (10.0,)
        await ctrl.commit()
        assert learner.commits == ["twin1"] and ctrl.trained_through == 7
        assert ctrl.status_fields() == {"kind": "updatable", "source": "damper",
                                        "updater": "online_ukf", "causality": "previous-step",
                                        "learner": "live", "steps_trained": 7}
        learner.lost = True
        with pytest.raises(ControllerError, match="twin twin1: learner of damper is lost"):
            await ctrl.set_ctrl((0.6,))
        with pytest.raises(ControllerError):
            await ctrl.commit()

    asyncio.run(run())


def step(n: int, d: float, f: float) -> CommittedStep:
    return CommittedStep("damper", 1, n, 0.01 * n, (d,), (d,), (d,), (f,), "RUNNING")


def test_non_finite_source_data_is_never_sent_for_training() -> None:
    learner = Learner("damper", LearnerSpec("damper", (TwinSpec("t", "none", {}),)), deadline=1.0)
    events: list[tuple[str, str, dict[str, object]]] = []
    learner.add_event_sink(lambda kind, reason, extra: events.append((kind, reason, extra)))
    learner.step_committed(step(1, 0.5, 2.0))
    learner.step_committed(step(2, 0.6, math.nan))
    learner.step_committed(step(3, math.inf, 1.0))
    learner.step_committed(step(4, 0.7, 2.5))
    assert learner.log == [("observe", 1, 1, 0.5, 2.0), ("observe", 1, 4, 0.7, 2.5)]
    assert learner.not_trained == 2 and learner.source_step == 4
    assert [(k, x["source_step"]) for k, _, x in events] == [("not-trained", 2),
                                                             ("not-trained", 3)]
    assert learner.status("t")["not_trained"] == 2


def test_ctl_status_says_what_the_twin_is() -> None:
    from fresco_bridge.ctl import format_answer

    site = {"site": "twin1", "kind": "updatable", "state": "RUNNING", "reason": "",
            "session": 1, "peer": None, "step": 12, "time": 0.12, "ctrl": [0.1],
            "target": [0.1], "daq_disp": [0.1], "daq_force": [1.0], "holds": 0,
            "limit_events": {}, "limits": [], "pending": None,
            **controller(FakeLearner()).status_fields(), "learner_reason": None,
            "source_step": 12, "not_trained": 0, "learner_losses": 0}
    text = format_answer({"sites": [site]})
    assert ("updatable: learns from damper  updater online_ukf  causality previous-step  "
            "learner live  trained through source step 7 (source at 12)") in text


def test_status_says_behind_only_while_the_twin_runs_and_frozen_says_the_snapshots_step() -> None:
    spec = LearnerSpec("damper", (TwinSpec("t", "none", {}, on_loss="freeze"),))
    learner = Learner("damper", spec, deadline=1.0)
    learner.state, learner.source_step, learner.trained_through = "live", 775, 0
    assert learner.status("t", active=True)["learner"] == "behind 774"
    assert learner.status("t", active=False)["learner"] == "live"  # the run has ended
    from fresco_bridge.twins.worker import LearnerState

    local = LearnerState(spec)
    local.twins["t"].trained_through = 700
    learner.state, learner._local, learner.trained_through = "lost", local, 724
    status = learner.status("t")
    assert status["learner"] == "frozen" and status["steps_trained"] == 700


@pytest.mark.parametrize("source_first", [False, True])
def test_a_committed_answer_that_used_a_trial_the_source_committed_otherwise_is_said(
        source_first: bool) -> None:
    """A same-step answer used the source's trial measurement of step 3 and the twin
    committed it; the source's commit of step 3 differs (a later trial came after the twin's
    answer): one ``same-step-mismatch`` event, whichever commit came first. An equal commit
    (steps 4) says nothing; the source's steps always go to the log as committed."""
    learner = Learner("damper", LearnerSpec("damper", (TwinSpec("t", "none", {}),)),
                      deadline=1.0)
    learner.state = "live"
    events: list[tuple[str, str, dict[str, object]]] = []
    learner.add_event_sink(lambda kind, reason, extra: events.append((kind, reason, extra)))
    for n, used, committed in ((3, (0.5, 2.0), (0.6, 2.1)), (4, (0.7, 2.5), (0.7, 2.5))):
        learner._last_trial["t"] = (0.1, (1, n), used)
        learner._tentative["t"] = True
        if source_first:
            learner.step_committed(step(n, *committed))
            learner.commit("t")
        else:
            learner.commit("t")
            learner.step_committed(step(n, *committed))
    assert [(k, x["source_step"]) for k, _, x in events] == [("same-step-mismatch", 3)]
    assert "trial of step 3" in events[0][1]
    assert [m for m in learner.log if m[0] == "observe"] == [
        ("observe", 1, 3, 0.6, 2.1), ("observe", 1, 4, 0.7, 2.5)]
    assert not learner._used
