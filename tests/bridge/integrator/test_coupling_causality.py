"""A twin that learns in the coupling loop: the same-step and previous-step causality contracts,
with the paper's UKF updater on a Bilinear tested damper."""

from __future__ import annotations

import numpy as np
import pytest

from fresco_bridge.integrator import (
    DEMO_DT,
    DEMO_ZETA,
    Causality,
    MeasuredElement,
    Placement,
    StoryCoupling,
    UpdatingTwin,
    coupled_integrator,
    kanai_tajimi,
    paper_two_story_frame,
    run_coupled,
)
from fresco_bridge.updating import make_updater
from fresco_bridge.updating.base import Updater
from sim_actuator.effects import Sensor
from sim_actuator.models import Bilinear, Elastic, HysteresisModel

DAMPER = {"k0": 8.0, "fy": 12.0, "alpha": 0.05}
MOTION = kanai_tajimi(3.0, duration=1.0, dt=DEMO_DT, seed=4)
SPIKE_STEP = 40


class LoggedTwin:
    """A twin model that logs its trials and commits into the updater's log."""

    def __init__(self, model: HysteresisModel, log: list[str]) -> None:
        self.model, self.log = model, log

    @property
    def initial_tangent(self) -> float:
        return self.model.initial_tangent

    def set_trial(self, d: float) -> tuple[float, float]:
        self.log.append("twin trial")
        return self.model.set_trial(d)

    def commit(self) -> None:
        self.log.append("twin commit")
        self.model.commit()


class LoggedUpdater:
    """The paper's UKF updater, its observations and its twin's calls logged in order."""

    def __init__(self, log: list[str]) -> None:
        self.inner: Updater = make_updater("online_ukf")
        self.name = "logged"
        self.log = log
        self._twin = LoggedTwin(self.inner.twin, log)

    def observe(self, d: float, force: float) -> None:
        self.log.append("observe")
        self.inner.observe(d, force)

    @property
    def twin(self) -> LoggedTwin:
        return self._twin

    @property
    def last_update_seconds(self) -> float:
        return self.inner.last_update_seconds


class LoggedSpecimen:
    """A Bilinear tested damper whose measurement at ``spike_step`` is off by ``spike`` kN."""

    def __init__(self, log: list[str], spike: float = 0.0) -> None:
        self.model, self.log, self.spike, self.step = Bilinear(**DAMPER), log, spike, 0

    @property
    def initial_tangent(self) -> float:
        return self.model.initial_tangent

    def set_trial(self, d: float) -> tuple[float, float]:
        self.log.append("tested trial")
        force, tangent = self.model.set_trial(d)
        return force + (self.spike if self.step == SPIKE_STEP else 0.0), tangent

    def commit(self) -> None:
        self.log.append("tested commit")
        self.model.commit()
        self.step += 1


def _run(causality: Causality, spike: float = 0.0, steps: int = 60
         ) -> tuple[list[str], StoryCoupling, UpdatingTwin]:
    log: list[str] = []
    twin = UpdatingTwin(LoggedUpdater(log), causality)  # type: ignore[arg-type]
    coupling = StoryCoupling({
        "tested": Placement(0, LoggedSpecimen(log, spike)),
        "twin": Placement(1, twin, stiffness=DAMPER["k0"], learns_from="tested"),
    })  # fmt: skip
    integrator = coupled_integrator(paper_two_story_frame(), coupling, MOTION, dt=DEMO_DT,
                                    zeta=DEMO_ZETA)  # fmt: skip
    run_coupled(integrator, coupling, steps=steps)
    return log, coupling, twin


@pytest.mark.parametrize(("causality", "step"), [
    ("same-step", ["tested trial", "twin trial", "observe", "twin trial", "tested commit",
                   "twin commit"]),
    ("previous-step", ["tested trial", "twin trial", "tested commit", "twin commit", "observe"]),
])  # fmt: skip
def test_each_causality_runs_its_documented_order_every_step(
    causality: Causality, step: list[str]
) -> None:
    log, _, twin = _run(causality, steps=5)
    assert log == step * 6  # step 0 and 5 more
    assert twin.causality == causality
    assert twin.ahead_force().shape == twin.update_seconds().shape == (6,)


def test_previous_step_twin_at_step_i_does_not_depend_on_the_measurement_at_step_i() -> None:
    """The tested damper's measurement at SPIKE_STEP is off by 5 kN in a second run: under
    previous-step the twin's forces through that step are unchanged and only later ones move;
    under same-step the twin's force at that very step moves."""
    _, clean, _ = _run("previous-step")
    _, spiked, twin = _run("previous-step", spike=5.0)
    k = SPIKE_STEP
    assert np.array_equal(spiked.drift("twin")[: k + 1], clean.drift("twin")[: k + 1])
    assert np.array_equal(spiked.force("twin")[: k + 1], clean.force("twin")[: k + 1])
    assert spiked.force("twin")[k + 1] != clean.force("twin")[k + 1]  # learned after the commit
    assert np.array_equal(twin.ahead_force(), spiked.force("twin"))  # its answer is the ahead

    _, clean, _ = _run("same-step")
    _, spiked, twin = _run("same-step", spike=5.0)
    assert np.array_equal(spiked.drift("twin")[: k + 1], clean.drift("twin")[: k + 1])
    assert np.array_equal(spiked.force("twin")[:k], clean.force("twin")[:k])
    assert spiked.force("twin")[k] != clean.force("twin")[k]
    assert twin.ahead_force()[k] != spiked.force("twin")[k]  # the probe came before step k


def test_a_measured_element_gives_the_load_cell_reading_of_the_models_force() -> None:
    noisy = MeasuredElement(Bilinear(**DAMPER), Sensor(noise_std=0.2, bias=0.5,
                                                       rng=np.random.default_rng(3)))  # fmt: skip
    model, draws = Bilinear(**DAMPER), np.random.default_rng(3)
    assert noisy.initial_tangent == DAMPER["k0"]
    for d in (0.5, 2.0, -1.0):
        force, tangent = noisy.set_trial(d)
        noisy.commit()
        true, true_tangent = model.set_trial(d)
        model.commit()
        assert force == true + 0.5 + 0.2 * float(draws.standard_normal())
        assert tangent == true_tangent


def test_bad_learning_placements_are_refused_with_the_elements_named() -> None:
    def twin(causality: Causality = "same-step") -> UpdatingTwin:
        return UpdatingTwin(make_updater("online_ukf"), causality)

    with pytest.raises(ValueError, match="'twin' learns from 'gauge', which is not another"):
        StoryCoupling({"twin": Placement(0, twin(), learns_from="gauge")})
    with pytest.raises(ValueError, match="'twin' learns from 'twin'"):
        StoryCoupling({"twin": Placement(0, twin(), learns_from="twin")})
    with pytest.raises(TypeError, match="'model' learns from 'tested' but has no measured"):
        StoryCoupling({"tested": Placement(0, Elastic(k=1.0)),
                       "model": Placement(0, Elastic(k=1.0), learns_from="tested")})
    with pytest.raises(ValueError, match="'twin' learns same-step from 'tested', which must come"):
        StoryCoupling({"twin": Placement(1, twin(), learns_from="tested"),
                       "tested": Placement(0, Elastic(k=1.0))})
    StoryCoupling({"twin": Placement(1, twin("previous-step"), learns_from="tested"),
                   "tested": Placement(0, Elastic(k=1.0))})  # any order: it waits for the commit
    with pytest.raises(ValueError, match="unknown causality 'late'; known: same-step, previous"):
        twin("late")  # type: ignore[arg-type]
