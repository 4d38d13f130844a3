"""An updatable site in a real bridge driven over the element protocol (no OpenSees): its
status, its metrics (the updater's step time) and its telemetry (``predicted_force``)."""

from __future__ import annotations

import math
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from fresco_bridge.integrator.link import GenericClientLink
from fresco_bridge.site_output import CommittedStep
from fresco_bridge.telemetry.taps import SiteTaps
from protocol import Action
from tests.bridge.telemetry.test_metrics_bridge import scrape
from tests.support.bridge import RunningBridge
from tests.support.twins import learners_of

TOML = '''
[telemetry]
metrics_port = 0
[[sites]]
name = "damper"
port = 0
[sites.controller]
model = "bilinear"
params = { k0 = 20.0, fy = 5.0, alpha = 0.05 }
[[sites]]
name = "twin1"
port = 0
kind = "updatable"
learns_from = "damper"
updater = "online_ukf"
'''


def test_a_served_twin_learns_reports_and_times_its_updates(tmp_path: Path) -> None:
    pytest.importorskip("filterpy")
    steps = 40
    with RunningBridge(TOML, tmp_path) as bridge, \
            GenericClientLink("127.0.0.1", bridge.ports["damper"], 1) as source, \
            GenericClientLink("127.0.0.1", bridge.ports["twin1"], 1) as twin:
        forces = []
        for i in range(1, steps + 1):
            d = 1.5 * math.sin(i / 4.0)
            source.set_trial((d,), time=0.01 * i)
            source.force()
            twin.set_trial((0.8 * d,), time=0.01 * i)
            forces.append(twin.force()[0])
            source.commit()
            twin.commit()
        twin.request(Action.GET_DISP)  # answered after the last commit: the site has it
        status = bridge.call(lambda: bridge.bridge.sites["twin1"].status())
        assert bridge.bridge.metrics_server is not None
        values = scrape(bridge.bridge.metrics_server.port)
    assert all(math.isfinite(f) for f in forces)
    assert status["kind"] == "updatable" and status["source"] == "damper"
    assert status["updater"] == "online_ukf" and status["causality"] == "previous-step"
    assert status["learner"] == "live" and status["steps_trained"] == steps - 1
    assert status["source_step"] == steps and status["step"] == steps
    # one update time per source step learned (the twin's steps 2..40 learn steps 1..39)
    assert values[("fresco_updater_step_seconds_count", ())] == steps - 1


class Published:
    def __init__(self) -> None:
        self.steps: list[Any] = []

    def publish_step(self, sample: Any) -> None:
        self.steps.append(sample)


@pytest.mark.parametrize("predicted", [False, True])
def test_an_updatable_sites_step_is_published_with_its_predicted_force(predicted: bool) -> None:
    mqtt = Published()
    taps = SiteTaps(mqtt, None, None, predicted=predicted)  # type: ignore[arg-type]
    taps.step_committed(CommittedStep("twin1", 1, 3, 0.03, (0.2,), (0.2,), (0.2,), (4.5,),
                                      "RUNNING"))
    assert mqtt.steps[0].predicted_force == (4.5 if predicted else None)


def test_a_client_asking_the_twin_before_the_sources_trial_falls_back_not_deadlocks(
        tmp_path: Path) -> None:
    """Same-step with a client that asks each element's force right after its own trial, twin
    first: the twin's first trial waits out its deadline for the source's, then the session
    goes on previous-step (said in an event), equal to the in-process previous-step replay."""
    pytest.importorskip("filterpy")
    from fresco_bridge.runs import load_run
    from fresco_bridge.updating.histories import read_history
    from fresco_bridge.updating.registry import make_updater
    from fresco_bridge.updating.replay import replay

    toml = TOML.replace("[telemetry]\nmetrics_port = 0\n", "") + (
        'causality = "same-step"\nlearner_deadline = 0.2\n')
    steps = 20
    with RunningBridge(toml, tmp_path) as bridge, \
            GenericClientLink("127.0.0.1", bridge.ports["damper"], 1) as source, \
            GenericClientLink("127.0.0.1", bridge.ports["twin1"], 1) as twin:
        for i in range(1, steps + 1):
            d = 1.5 * math.sin(i / 4.0)
            twin.set_trial((0.8 * d,), time=0.01 * i)
            twin.force()
            source.set_trial((d,), time=0.01 * i)
            source.force()
            twin.commit()
            source.commit()
        twin.request(Action.GET_DISP)
        source.request(Action.GET_DISP)
        status = bridge.call(lambda: bridge.bridge.sites["twin1"].status())
        run_dir = bridge.run_dir
    assert status["causality"] == "same-step (fell back to previous-step)"
    fallbacks = [e for e in load_run(run_dir).events if e["event"] == "same-step-fallback"]
    assert len(fallbacks) == 1 and fallbacks[0]["step"] == 1
    src, tw = read_history(run_dir, site="damper"), read_history(run_dir, site="twin1")
    assert tw.force is not None and tw.disp.size == steps
    expected = replay(make_updater("online_ukf"), src.disp, src.force, tw.disp,
                      lag=True).force_pred
    assert float(np.max(np.abs(tw.force - expected))) / float(np.max(np.abs(expected))) < 1e-9


def test_two_twins_of_one_source_share_a_learner_each_with_its_own_state(
        tmp_path: Path) -> None:
    """One learner (one worker) for both; each twin its own updater and history: twin1 the
    UKF at 0.8 d, twin2 a fixed law at 0.5 d, each equal to its own in-process replay."""
    pytest.importorskip("filterpy")
    from fresco_bridge.updating.histories import read_history
    from fresco_bridge.updating.registry import make_updater
    from fresco_bridge.updating.replay import replay

    toml = TOML.replace("[telemetry]\nmetrics_port = 0\n", "") + (
        '[[sites]]\nname = "twin2"\nport = 0\nkind = "updatable"\nlearns_from = "damper"\n'
        'updater = "none"\n[sites.updater_options]\nmodel = "elastic"\nparams = { k = 7.0 }\n')
    steps = 25
    with RunningBridge(toml, tmp_path) as bridge:
        assert list(learners_of(bridge)) == ["damper"]
        links = [GenericClientLink("127.0.0.1", bridge.ports[s], 1).connect()
                 for s in ("damper", "twin1", "twin2")]
        for i in range(1, steps + 1):
            d = 1.5 * math.sin(i / 4.0)
            for link, scale in zip(links, (1.0, 0.8, 0.5), strict=True):
                link.set_trial((scale * d,), time=0.01 * i)
                link.force()
            for link in links:
                link.commit()
        for link in links:
            link.request(Action.GET_DISP)
            link.close()
        run_dir = bridge.run_dir
    src = read_history(run_dir, site="damper")
    for site, name, options in (("twin1", "online_ukf", {}),
                                ("twin2", "none", {"model": "elastic", "params": {"k": 7.0}})):
        tw = read_history(run_dir, site=site)
        assert tw.force is not None and tw.disp.size == steps
        expected = replay(make_updater(name, **options), src.disp, src.force, tw.disp,
                          lag=True).force_pred
        assert float(np.max(np.abs(tw.force - expected))) < 1e-9 * float(
            np.max(np.abs(expected))), site
