"""Catch-up (``twins/catchup.py``), in process: a trial learns at most its cap of a backlog and
answers from the model as learned so far, saying exactly how far; the rest is learned between
the twin's steps, never between a trial and its commit; and replaying the trials with the
source step each was learned through rebuilds the very same answers (what a new worker and
``--resume`` do)."""

from __future__ import annotations

import random
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from fresco_bridge.twins.catchup import CatchUpEvents
from fresco_bridge.twins.worker import LearnerSpec, LearnerState, Message, TwinSpec
from tests.bridge.twins.test_worker import UKF, histories

CAP = 8


def state() -> LearnerState:
    pytest.importorskip("filterpy")
    return LearnerState(LearnerSpec("src", (TwinSpec("twin", "online_ukf", dict(UKF)),)))


def test_a_trial_behind_a_backlog_learns_its_cap_and_says_how_far() -> None:
    sd, sf, _ = histories(100)
    worker = state()
    for i in range(60):  # a source-only session: 60 steps, none learned yet
        worker.handle(("observe", 1, i + 1, float(sd[i]), float(sf[i])))
    reply = worker.handle(("trial", 1, "twin", 0.3, (2, 0), None, (CAP, 60.0)))
    assert reply is not None and reply[0] == "trial"
    assert reply[8] == (1, CAP) and reply[9] == 60 - CAP  # learned through, still behind
    assert not worker.learn_in_background() and reply[8] == worker.twins["twin"].learned
    assert worker.twins["twin"].learned == (1, CAP)  # nothing learned between trial and commit
    worker.handle(("commit", "twin"))
    assert worker.learn_in_background()  # one step, more left
    assert worker.twins["twin"].learned == (1, CAP + 1)
    reply = worker.handle(("trial", 2, "twin", 0.4, (2, 0)))  # uncapped (a replay): all of it
    assert reply is not None and reply[8] == (1, 60) and reply[9] == 0
    worker.handle(("commit", "twin"))
    assert not worker.learn_in_background()  # caught up: nothing asked is left


def test_a_trial_past_its_time_budget_still_learns_two_steps() -> None:
    """A spent budget (a loaded host) stops the trial's learning after two steps: the
    backlog still shrinks while the twin learns one new step per step."""
    sd, sf, _ = histories(20)
    worker = state()
    for i in range(20):
        worker.handle(("observe", 1, i + 1, float(sd[i]), float(sf[i])))
    reply = worker.handle(("trial", 1, "twin", 0.3, (2, 0), None, (CAP, 0.0)))
    assert reply is not None and reply[8] == (1, 2) and reply[9] == 18


def test_background_learning_stops_at_what_the_twin_may_learn() -> None:
    """Previous-step: after the twin's trial of step k (through k - 1) the source's step k
    may already be in the worker; it is learned by the next trial, not in the background."""
    sd, sf, _ = histories(10)
    worker = state()
    worker.handle(("observe", 1, 1, float(sd[0]), float(sf[0])))
    worker.handle(("trial", 1, "twin", 0.1, (1, 0), None, (CAP, 60.0)))
    worker.handle(("observe", 1, 2, float(sd[1]), float(sf[1])))
    worker.handle(("commit", "twin"))
    assert not worker.learn_in_background()
    assert worker.twins["twin"].learned == (0, 0)
    worker.handle(("learn", 0, (1, 2)))  # no twin in a session: everything so far
    assert worker.learn_in_background() and not worker.learn_in_background()
    assert worker.twins["twin"].learned == (1, 2)


def test_a_replay_of_the_learned_through_steps_gives_the_same_answers() -> None:
    """A live worker behind a backlog, background steps at random between the twin's steps;
    a fresh worker fed the same messages with each trial's learned-through step (what the
    learner logs and the record's update lines say) answers exactly the same."""
    sd, sf, td = histories(200)
    live, rng = state(), random.Random(3)
    replayed: list[Message] = []
    for i in range(120):  # the backlog: a source-only session
        replayed.append(("observe", 1, i + 1, float(sd[i]), float(sf[i])))
        live.handle(replayed[-1])
    answers = []
    for k in range(1, 81):  # the pair: source session 2, twin step k, previous-step
        for _ in range(rng.randrange(4)):
            live.learn_in_background()
        reply = live.handle(("trial", k, "twin", float(td[k]), (2, k - 1), None, (CAP, 60.0)))
        assert reply is not None
        answers.append(reply[2])
        assert reply[8] <= (2, k - 1)  # never past what its causality allows
        replayed += [("trial", 0, "twin", float(td[k]), reply[8]), ("commit", "twin")]
        live.handle(("commit", "twin"))
        replayed.append(("observe", 2, k, float(sd[119 + k]), float(sf[119 + k])))
        live.handle(replayed[-1])
    assert live.twins["twin"].learned == (2, 79)  # caught up within the pair
    fresh, again = state(), []
    for msg in replayed:
        reply = fresh.handle(msg)
        if reply is not None:
            again.append(reply[2])
    assert np.array_equal(np.array(again), np.array(answers))


@pytest.mark.parametrize("seed", [3, 11])
def test_same_step_behind_a_backlog_learns_no_tentative_step_and_replays_the_same(
        seed: int) -> None:
    """Same-step behind a backlog: a trial the cap stops short learns no tentative step
    (answers from committed steps only, says how far); once caught up, the source's trial is
    learned tentatively. Some commits differ from the trial (a rollback, met by a trial or by
    background learning between steps): a fresh worker fed each trial with what it learned
    through (its trial measurement only if it used it) answers exactly the same."""
    sd, sf, td = histories(200)
    live, rng = state(), random.Random(seed)
    replayed: list[Message] = []
    for i in range(100):  # the backlog: a source-only session
        replayed.append(("observe", 1, i + 1, float(sd[i]), float(sf[i])))
        live.handle(replayed[-1])
    answers, tentative = [], []
    for k in range(1, 61):  # the pair: source session 2, twin step k, same-step
        for _ in range(rng.randrange(3)):
            live.learn_in_background()
        d, f = float(sd[99 + k]), float(sf[99 + k])
        measured = (d, f) if rng.random() < 0.7 else (d + 0.05, f - 0.1)
        reply = live.handle(("trial", k, "twin", float(td[k]), (2, k), measured,
                             (CAP, 60.0)))
        assert reply is not None and reply[0] == "trial"
        answers.append(reply[2])
        tentative.append(reply[7])
        assert not reply[7] or reply[9] == 0  # tentative only with nothing committed left
        assert reply[8] == ((2, k) if reply[7] else live.twins["twin"].learned)
        replayed += [("trial", 0, "twin", float(td[k]), reply[8],
                      measured if reply[7] else None), ("commit", "twin")]
        live.handle(("commit", "twin"))
        replayed.append(("observe", 2, k, d, f))
        live.handle(replayed[-1])
    assert not tentative[0] and tentative[-1]  # behind at first, same-step once caught up
    fresh, again = state(), []
    for msg in replayed:
        reply = fresh.handle(msg)
        if reply is not None:
            again.append(reply[2])
    assert np.array_equal(np.array(again), np.array(answers))


def test_the_twin_says_when_it_falls_behind_and_when_it_caught_up() -> None:
    events: list[tuple[str, dict[str, object]]] = []
    catch_up = CatchUpEvents("src", lambda kind, reason, **extra: events.append((kind, extra)))
    catch_up.answered("twin", 1, 500, (1, 32))
    catch_up.answered("twin", 2, 460, (1, 72))
    catch_up.answered("twin", 3, 0, (2, 2))
    catch_up.answered("twin", 4, 0, (2, 3))
    assert events == [("learner-behind", {"twin": "twin", "behind": 500, "upto": [1, 32]}),
                      ("learner-caught-up", {"twin": "twin", "upto": [2, 2]})]


def test_a_resume_replays_each_trial_as_far_as_its_update_line_says(tmp_path: Path) -> None:
    """The record's ``upto`` (a twin answering behind its source) is what the resumed learner
    replays that trial with; without it, the twin's causality (previous-step: k - 1)."""
    from fresco_bridge.twins.build import RecordedHistory
    from fresco_bridge.twins.learner import Learner

    spec = LearnerSpec("damper", (TwinSpec("twin1", "none", {}),))
    learner = Learner("damper", spec, deadline=2.0)
    history = RecordedHistory({"damper": learner}, tmp_path, [])
    lines: list[dict[str, Any]] = [
        {"kind": "event", "site": "damper", "session": 1, "event": "session-open"}]
    for step in (1, 2, 3):
        lines += [{"kind": "trial", "site": "damper", "session": 1, "ctrl": [0.1 * step]},
                  {"kind": "daq", "site": "damper", "session": 1, "disp": [0.1 * step],
                   "force": [float(step)]},
                  {"kind": "commit", "site": "damper", "session": 1, "step": step}]
    for step, upto in ((1, [1, 2]), (2, None)):
        lines += [{"kind": "trial", "site": "twin1", "session": 1, "ctrl": [0.5 * step]},
                  {"kind": "daq", "site": "twin1", "session": 1, "disp": [0.5 * step],
                   "force": [0.0]},
                  {"kind": "commit", "site": "twin1", "session": 1, "step": step},
                  {"kind": "update", "site": "twin1", "session": 1, "step": step,
                   "through": 2, **({} if upto is None else {"upto": upto})}]
    for line in lines:
        history.line(line)
    history.end()
    trials = [m for m in learner.log if m[0] == "trial"]
    assert trials == [("trial", 0, "twin1", 0.5, (1, 2)), ("trial", 0, "twin1", 1.0, (1, 1))]
