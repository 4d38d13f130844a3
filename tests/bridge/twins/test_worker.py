"""The learner's worker, in process: message handling, previous-step exactness whatever the
order of the source's commit and the twin's, one updater per twin."""

from __future__ import annotations

import math

import numpy as np
import pytest

from fresco_bridge.twins.worker import LearnerSpec, LearnerState, TwinSpec
from fresco_bridge.updating.registry import make_updater
from fresco_bridge.updating.replay import replay

UKF = {"k0": 20.0, "fy": 12.0, "alpha": 0.05}


def histories(n: int = 60) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    from sim_actuator.models import make_model

    law = make_model("bilinear", k0=25.0, fy=15.0, alpha=0.02)
    d = 2.0 * np.sin(np.arange(1, n + 1) / 5.0) * np.linspace(0.5, 1.5, n)
    f = np.empty(n)
    for i, x in enumerate(d):
        f[i] = law.set_trial(float(x))[0]
        law.commit()
    return d, f, 0.8 * d


def state(*twins: str) -> LearnerState:
    pytest.importorskip("filterpy")
    return LearnerState(LearnerSpec("src", tuple(TwinSpec(t, "online_ukf", dict(UKF))
                                                 for t in twins)))


@pytest.mark.parametrize("source_first", [True, False])
def test_previous_step_equals_the_in_process_replay(source_first: bool) -> None:
    sd, sf, td = histories()
    worker = state("twin")
    answers = []
    for i in range(sd.size):
        observe = ("observe", 1, i + 1, float(sd[i]), float(sf[i]))
        for k, d in enumerate((td[i] * 0.5, td[i])):  # Newton: the last trial is committed
            reply = worker.handle(("trial", 10 * i + k, "twin", float(d), (1, i)))
            assert reply is not None and reply[0] == "trial" and reply[4] == i  # through i-1
            assert reply[5] >= 0.0  # the update time of the step(s) just learned
        answers.append(reply[2])
        if source_first:  # the client commits the source's element before the twin's
            worker.handle(observe)
            worker.handle(("commit", "twin"))
        else:
            worker.handle(("commit", "twin"))
            worker.handle(observe)
    expected = replay(make_updater("online_ukf", **UKF), sd, sf, td, lag=True).force_pred
    assert np.array_equal(np.array(answers), expected)
    assert worker.handle(("sync", 7)) == ("sync", 7, sd.size - 1)


def test_each_twin_follows_the_learned_parameters() -> None:
    """A second twin of the same source learns too (its own updater, the same steps)."""
    sd, sf, td = histories(30)
    worker = state("a", "b")
    for i in range(sd.size):
        fa = worker.handle(("trial", 1, "a", float(td[i]), (1, i)))
        fb = worker.handle(("trial", 2, "b", float(td[i]), (1, i)))
        assert fa is not None and fb is not None and fa[2:5] == fb[2:5]
        worker.handle(("commit", "a"))
        worker.handle(("commit", "b"))
        worker.handle(("observe", 1, i + 1, float(sd[i]), float(sf[i])))
    fixed = make_updater("online_ukf", **UKF).twin.set_trial(float(td[-1]))[0]
    assert fa[2] != fixed  # the parameters moved: the twins answer from what they learned


def test_a_non_finite_observation_is_not_learned_and_a_bad_trial_is_an_error() -> None:
    worker = state("twin")
    worker.handle(("observe", 1, 1, math.nan, 3.0))
    worker.handle(("commit", "twin"))
    reply = worker.handle(("trial", 1, "twin", 0.5, (1, 1)))
    assert reply is not None and reply[0] == "trial" and reply[4] == 0
    assert worker.rejected == 1
    bad = worker.handle(("trial", 2, "twin", math.inf, (1, 1)))
    assert bad is not None and bad[0] == "error" and bad[1] == 2
    initial = worker.handle(("initial", 3, "twin"))
    assert initial == ("initial", 3, UKF["k0"])


def test_same_step_equals_the_in_process_replay_in_the_papers_order() -> None:
    sd, sf, td = histories()
    worker = state("twin")
    answers = []
    for i in range(sd.size):
        worker.handle(("observe", 1, i + 1, float(sd[i]), float(sf[i])))  # the source's trial
        reply = worker.handle(("trial", i, "twin", float(td[i]), (1, i + 1)))
        assert reply is not None and reply[4] == i + 1  # learned through this very step
        answers.append(reply[2])
        worker.handle(("commit", "twin"))
    expected = replay(make_updater("online_ukf", **UKF), sd, sf, td, lag=False).force_pred
    assert np.array_equal(np.array(answers), expected)


def test_learned_observations_are_dropped_and_learning_goes_on(
        monkeypatch: pytest.MonkeyPatch) -> None:
    from fresco_bridge.twins import worker as worker_module

    monkeypatch.setattr(worker_module, "TRIM", 16)
    sd, sf, td = histories(60)
    worker = state("twin")
    answers = []
    for i in range(sd.size):
        reply = worker.handle(("trial", i, "twin", float(td[i]), (1, i)))
        assert reply is not None
        answers.append(reply[2])
        worker.handle(("commit", "twin"))
        worker.handle(("observe", 1, i + 1, float(sd[i]), float(sf[i])))
    assert len(worker.observations) < 20
    expected = replay(make_updater("online_ukf", **UKF), sd, sf, td, lag=True).force_pred
    assert np.array_equal(np.array(answers), expected)


def _session(worker: LearnerState, session: int, sd: np.ndarray, sf: np.ndarray,
             td: np.ndarray | None) -> list[float]:
    """One session of the source (and of the twin, unless ``td`` is None), previous-step,
    the client committing the twin's element first."""
    answers = []
    for i in range(sd.size):
        if td is not None:
            reply = worker.handle(("trial", i, "twin", float(td[i]), (session, i)))
            assert reply is not None and reply[0] == "trial"
            answers.append(reply[2])
            worker.handle(("commit", "twin"))
        worker.handle(("observe", session, i + 1, float(sd[i]), float(sf[i])))
    return answers


def test_a_second_session_learns_exactly_what_one_long_session_would() -> None:
    """Steps restart at 1 in each session; keyed by (session, step), the second session's
    step k answers from all of the first and its own steps before k."""
    sd, sf, td = histories(80)
    worker = state("twin")
    answers = _session(worker, 1, sd[:40], sf[:40], td[:40])
    answers += _session(worker, 2, sd[40:], sf[40:], td[40:])
    expected = replay(make_updater("online_ukf", **UKF), sd, sf, td, lag=True).force_pred
    assert np.array_equal(np.array(answers), expected)


def test_a_source_only_session_is_learned_from_by_the_next_pair() -> None:
    """The stated rule: every step of an earlier source session precedes the twin's next
    trial, so a source-only session is learned at the pair's first step."""
    sd, sf, td = histories(80)
    worker = state("twin")
    _session(worker, 1, sd[:30], sf[:30], None)  # the source alone
    answers = _session(worker, 2, sd[30:], sf[30:], td[30:])
    updater = make_updater("online_ukf", **UKF)
    for d, f in zip(sd[:30], sf[:30], strict=True):
        updater.observe(float(d), float(f))
    expected = replay(updater, sd[30:], sf[30:], td[30:], lag=True).force_pred
    assert np.array_equal(np.array(answers), expected)


def _committed_only(sd: np.ndarray, sf: np.ndarray, td: np.ndarray,
                    through: list[int]) -> list[float]:
    """The twin's answers of an updater that learned the committed source steps
    ``1..through[i]`` before the twin's step ``i + 1``, and nothing else."""
    updater = make_updater("online_ukf", **UKF)
    learned, answers = 0, []
    for i, k in enumerate(through):
        while learned < k:
            updater.observe(float(sd[learned]), float(sf[learned]))
            learned += 1
        answers.append(updater.twin.set_trial(float(td[i]))[0])
        updater.twin.commit()
    return answers


@pytest.mark.parametrize("source_first", [True, False])
def test_a_tentative_trial_that_is_not_committed_is_never_trained_on(
        source_first: bool) -> None:
    """Newmark + Newton served same-step: the twin's first iteration learns the source's
    first trial tentatively; the second (another trial: the twin falls back to previous-step)
    unlearns it; from then on the learner has learned committed steps only, exactly."""
    sd, sf, td = histories(40)
    worker = state("twin")
    answers, through = [], []
    for i in range(sd.size):
        if i == 0:  # the first iteration: the source's first trial (0.5 of the way)
            reply = worker.handle(("trial", 1, "twin", 0.5 * float(td[0]), (1, 1),
                                   (0.5 * float(sd[0]), 0.5 * float(sf[0]))))
            assert reply is not None and reply[4] == 1 and reply[7] is True
        reply = worker.handle(("trial", 2, "twin", float(td[i]), (1, i)))  # previous-step
        assert reply is not None and reply[4] == i and reply[7] is False
        answers.append(reply[2])
        through.append(i)
        observe = ("observe", 1, i + 1, float(sd[i]), float(sf[i]))
        for msg in (observe, ("commit", "twin")) if source_first else (("commit", "twin"),
                                                                        observe):
            worker.handle(msg)
    assert np.array_equal(np.array(answers), _committed_only(sd, sf, td, through))


def test_a_tentative_trial_committed_differently_is_replaced_by_the_commit() -> None:
    """The twin's answer used the source's trial of step k (the client visits the twin's
    element first); the source then commits another measurement of step k: the updater goes
    back to the committed steps, so it ends holding exactly what learning the committed
    steps alone gives."""
    sd, sf, td = histories(40)
    worker = state("twin")
    for i in range(sd.size):
        trial = (float(sd[i]), float(sf[i])) if i % 3 else (float(sd[i]) + 0.1,
                                                              float(sf[i]) - 0.2)
        reply = worker.handle(("trial", i, "twin", float(td[i]), (1, i + 1), trial))
        assert reply is not None and reply[4] == i + 1 and reply[7] is True
        worker.handle(("commit", "twin"))
        worker.handle(("observe", 1, i + 1, float(sd[i]), float(sf[i])))
    worker.handle(("learn", 0, (1, sd.size)))  # the last commit, learned in the background
    while worker.learn_in_background():
        pass
    committed = make_updater("online_ukf", **UKF)
    for d, f in zip(sd, sf, strict=True):
        committed.observe(float(d), float(f))
    learned = worker.twins["twin"].updater
    assert learned.parameters == committed.parameters  # type: ignore[attr-defined]
    assert np.array_equal(learned.covariance, committed.covariance)  # type: ignore


def test_the_rollback_point_is_bounded_and_the_log_still_trimmed(
        monkeypatch: pytest.MonkeyPatch) -> None:
    """Explicit same-step for many steps: a new rollback point every REBASE steps (the
    re-learning bounded), the learned observations still dropped; the answers those of the
    paper's order."""
    from fresco_bridge.twins import worker as worker_module

    monkeypatch.setattr(worker_module, "TRIM", 16)
    monkeypatch.setattr(worker_module, "REBASE", 8)
    sd, sf, td = histories(60)
    worker = state("twin")
    answers = []
    for i in range(sd.size):
        reply = worker.handle(("trial", i, "twin", float(td[i]), (1, i + 1),
                               (float(sd[i]), float(sf[i]))))
        assert reply is not None
        answers.append(reply[2])
        worker.handle(("commit", "twin"))
        worker.handle(("observe", 1, i + 1, float(sd[i]), float(sf[i])))
        assert worker.twins["twin"].since_base <= 8
    assert len(worker.observations) < 30
    expected = replay(make_updater("online_ukf", **UKF), sd, sf, td, lag=False).force_pred
    assert np.array_equal(np.array(answers), expected)


def test_a_copy_that_sees_no_more_commits_unlearns_its_tentative_step() -> None:
    """The learner's frozen copy starts from a snapshot taken while a same-step trial was
    learned tentatively: ``committed_only`` returns it to the committed steps."""
    sd, sf, td = histories(10)
    worker, reference = state("twin"), state("twin")
    for i in range(5):
        for w in (worker, reference):
            w.handle(("observe", 1, i + 1, float(sd[i]), float(sf[i])))
            w.handle(("trial", i, "twin", float(td[i]), (1, i + 1)))
            w.handle(("commit", "twin"))
    reply = worker.handle(("trial", 9, "twin", float(td[5]), (1, 6),
                           (float(sd[5]), float(sf[5]))))
    assert reply is not None and reply[7] is True and reply[4] == 6
    worker.committed_only()
    got = worker.handle(("trial", 10, "twin", float(td[5]), (1, 6)))
    expected = reference.handle(("trial", 10, "twin", float(td[5]), (1, 6)))
    assert got is not None and expected is not None and got[2:5] == expected[2:5]
