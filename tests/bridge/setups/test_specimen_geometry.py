"""The setup's platform as a coupled rig's specimen sees it (``Setup.specimen_geometry``): the
state behind some strokes and ∂s/∂q there, from the setup's own geometry — exact under
``nlGeom`` at large rotations, linear otherwise; scale factors do not change the physical
platform; setups without a platform have none."""

from __future__ import annotations

from typing import Any

import pytest

from fresco_bridge.setups import make_setup
from fresco_bridge.setups.kinds import parse_setup_table

COLUMN = {"kind": "ThreeActuators2d", "La1": 1000.0, "La2": 900.0, "La3": 800.0,
          "L1": 500.0, "L2": 400.0}


def _geometry(**extra: Any) -> Any:
    setup = make_setup(parse_setup_table({**COLUMN, **extra}), 3)
    geometry = setup.specimen_geometry()
    assert geometry is not None and geometry.n_actuators == 3
    return setup, geometry


@pytest.mark.parametrize("q", [(20.0, -15.0, 0.3), (-60.0, 40.0, -0.5), (0.0, 0.0, 0.0)])
def test_exact_geometry_gives_back_the_pose_of_its_own_strokes(q: tuple[float, ...]) -> None:
    setup, geometry = _geometry(nlGeom=True)
    strokes = setup.ctrl_disp(q)
    state, rows = geometry.state(strokes)
    assert state == pytest.approx(q, abs=1e-9)
    expected = setup.platform.jacobian(state)  # type: ignore[attr-defined]
    for row, want in zip(rows, expected, strict=True):
        assert row == pytest.approx(want, rel=1e-12, abs=1e-12)


def test_linear_geometry_is_the_setups_linear_map() -> None:
    setup, geometry = _geometry()
    q = (3.0, -2.0, 0.01)
    state, rows = geometry.state(setup.ctrl_disp(q))
    assert state == pytest.approx(q, rel=1e-12)
    assert rows == setup.t  # type: ignore[attr-defined]


def test_factors_keep_the_physical_platform_and_linear_setups_have_none() -> None:
    _, plain = _geometry(nlGeom=True)
    _, scaled = _geometry(nlGeom=True, trialDispFact=2.0, daqForceFact=0.5)
    strokes = (1.0, 2.0, -0.5)
    assert scaled.state(strokes) == plain.state(strokes)
    assert make_setup("NoTransformation", 3).specimen_geometry() is None
    assert make_setup("OneActuator", 1).specimen_geometry() is None
