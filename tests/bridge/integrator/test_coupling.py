"""The one coupling loop: story elements (models, twins, bridge sites) under explicit Newmark."""

from __future__ import annotations

from collections.abc import Callable

import numpy as np
import pytest

from fresco_bridge.daemon import BridgeThread
from fresco_bridge.integrator import (
    DEMO_DAMPER,
    DEMO_DT,
    DEMO_ZETA,
    Placement,
    StoryCoupling,
    coupled_integrator,
    demo_frame_integrator,
    demo_integrator,
    kanai_tajimi,
    paper_two_story_frame,
    run_coupled,
)
from fresco_bridge.integrator.link import GenericClientLink, SiteElement
from sim_actuator.models import Bilinear, Elastic

DAMPER = {"k0": 8.0, "fy": 12.0, "alpha": 0.05}
MOTION = kanai_tajimi(3.0, duration=3.0, dt=DEMO_DT, seed=4)


class Recorder:
    """A model wrapper that logs every call, to check the order and count of trials/commits."""

    def __init__(self, name: str, model: Bilinear | Elastic, log: list[str]) -> None:
        self.name, self.model, self.log = name, model, log

    @property
    def initial_tangent(self) -> float:
        return self.model.initial_tangent

    def set_trial(self, d: float) -> tuple[float, float]:
        self.log.append(f"trial {self.name}")
        return self.model.set_trial(d)

    def commit(self) -> None:
        self.log.append(f"commit {self.name}")
        self.model.commit()


def test_a_model_in_story_1_is_the_demo_integrator_with_a_callable_bit_for_bit() -> None:
    reference_model = Bilinear(**DAMPER)

    def force(step: int, t: float, drift: np.ndarray) -> list[float]:
        f, _ = reference_model.set_trial(float(drift[0]))
        reference_model.commit()
        return [f]

    expected = demo_integrator(force, MOTION).run()
    coupling = StoryCoupling({"damper": Placement(0, Bilinear(**DAMPER))})
    got = run_coupled(demo_frame_integrator(coupling, MOTION), coupling)
    assert np.array_equal(got.displacement, expected.displacement)
    assert np.array_equal(got.experimental_force, expected.experimental_force)
    assert np.array_equal(coupling.force("damper"), expected.experimental_force[:, 0])
    assert np.array_equal(coupling.drift("damper"), expected.experimental_drift[:, 0])


def test_elements_sharing_a_story_add_up_and_each_is_tried_once_then_committed_in_order() -> None:
    log: list[str] = []
    tested = Recorder("tested", Bilinear(**DAMPER), log)
    twin = Recorder("twin", Bilinear(**DAMPER), log)
    coupling = StoryCoupling({"tested": Placement(0, tested), "twin": Placement(0, twin)})
    assert coupling.stories == (0,)
    assert list(coupling.story_stiffness(2)) == [16.0, 0.0]  # both k0 in story 1
    integrator = demo_frame_integrator(coupling, MOTION)
    response = run_coupled(integrator, coupling, steps=50)
    assert integrator.current_step == 50
    assert log[:4] == ["trial tested", "trial twin", "commit tested", "commit twin"]
    assert log == log[:4] * 51
    total = coupling.force("tested") + coupling.force("twin")
    assert np.array_equal(response.experimental_force[:, 0], total)
    assert np.array_equal(coupling.force("tested"), coupling.force("twin"))  # identical loading


def test_elements_in_two_stories_get_their_own_drift() -> None:
    frame = paper_two_story_frame()
    coupling = StoryCoupling({"twin": Placement(1, Elastic(k=3.0)),
                              "tested": Placement(0, Bilinear(**DAMPER), stiffness=7.0)})
    assert coupling.stories == (0, 1)
    assert list(coupling.story_stiffness(2)) == [7.0, 3.0]  # explicit estimate, initial_tangent
    integrator = coupled_integrator(frame, coupling, MOTION, dt=DEMO_DT, zeta=DEMO_ZETA)
    response = run_coupled(integrator, coupling)
    assert np.array_equal(coupling.drift("tested"), response.drift[:, 0])
    assert np.array_equal(coupling.drift("twin"), response.drift[:, 1])
    assert np.allclose(coupling.force("twin"), 3.0 * response.drift[:, 1], rtol=0, atol=1e-12)
    assert np.array_equal(response.experimental_force[:, 1], coupling.force("twin"))


def test_bad_couplings_are_refused_with_the_element_named() -> None:
    with pytest.raises(ValueError, match="at least one element"):
        StoryCoupling({})
    with pytest.raises(TypeError, match="'gauge' has no set_trial"):
        StoryCoupling({"gauge": Placement(0, object())})  # type: ignore[arg-type]
    with pytest.raises(ValueError, match=r"'x': story must be >= 0"):
        StoryCoupling({"x": Placement(-1, Elastic(k=1.0))})
    far = StoryCoupling({"roof": Placement(2, Elastic(k=1.0))})
    with pytest.raises(ValueError, match="'roof' is in story 3 of a 2-story frame"):
        demo_frame_integrator(far, MOTION)
    coupling = StoryCoupling({"d": Placement(0, Elastic(k=1.0))})
    integrator = demo_frame_integrator(coupling, MOTION)
    with pytest.raises(ValueError, match=r"outside 0\.\.300"):
        run_coupled(integrator, coupling, steps=301)


@pytest.mark.parametrize(("dofs", "setup"), [(1, "NoTransformation"), (2, "OneActuator")])
def test_a_bridge_site_is_a_story_element_equal_to_the_model_in_process(
    run_bridge: Callable[[str], BridgeThread], dofs: int, setup: str
) -> None:
    params = ", ".join(f"{k} = {v!r}" for k, v in DAMPER.items())
    bridge = run_bridge(f'[[sites]]\nname = "damper"\nport = 0\ndofs = {dofs}\nsetup = "{setup}"\n'
                        f'[sites.controller]\nmodel = "bilinear"\nparams = {{ {params} }}\n')
    link = GenericClientLink("127.0.0.1", bridge.ports["damper"], dofs, timeout=10.0)
    over_bridge = StoryCoupling(
        {"damper": Placement(0, SiteElement(link, stiffness=float(DEMO_DAMPER["k0"])))})
    with link:
        response = run_coupled(demo_frame_integrator(over_bridge, MOTION), over_bridge)
    in_process = StoryCoupling({"damper": Placement(0, Bilinear(**DAMPER))})
    expected = run_coupled(demo_frame_integrator(in_process, MOTION), in_process)
    assert np.array_equal(response.displacement, expected.displacement)
    assert np.array_equal(over_bridge.force("damper"), in_process.force("damper"))


def test_a_site_element_needs_one_or_two_dofs() -> None:
    with pytest.raises(ValueError, match="1 or 2 basic DOFs, the link has 3"):
        SiteElement(GenericClientLink("127.0.0.1", 1, 3))
