"""Conformance with the real OpenSeesPy genericClient: the bridge must be invisible.

Every scenario runs OpenSees twice in real processes: once with genericClient elements served
by the bridge, once with the equivalent pure-OpenSees elements (zeroLength + Steel01/Elastic),
and the displacement histories must agree to 1e-9 relative.
"""

from __future__ import annotations

from pathlib import Path

import pytest

from fresco_bridge.record.export import committed_steps
from tests.support.bridge import RunningBridge, run_opensees
from tests.support.opensees_frame import BILINEAR, frame_config, frame_params, rel_diff, site

pytestmark = pytest.mark.opensees

@pytest.mark.parametrize(
    "variant",
    [
        {},
        {"rayleigh": [0.6, 0.002, 0.0, 0.0]},
        {"rayleigh": [0.6, 0.002, 0.0, 0.0], "no_rayleigh": True},
        {"eigen_first": True},
        {"rebuild": True},
        {"algorithm": ["Linear"], "nsteps": 100},
        {"data_size": 1},
    ],
    ids=["newton", "rayleigh", "noRayleigh", "eigen-first", "wipe-rebuild", "linear", "datasize1"],
)
def test_two_story_bilinear_matches_pure_opensees(
    tmp_path: Path, variant: dict[str, object]
) -> None:
    ref = run_opensees("frame2", **frame_params(ports=None, **variant))["runs"]
    with RunningBridge(frame_config(), tmp_path) as bridge:
        ports = [bridge.ports["story1"], bridge.ports["story2"]]
        got = run_opensees("frame2", **frame_params(ports=ports, **variant))["runs"]
        run_dir = bridge.run_dir
    assert len(got) == len(ref)
    for g, r in zip(got, ref, strict=True):
        peak_drift = max(abs(x) for x in r["u2"])
        assert peak_drift > 3 * BILINEAR["fy"] / BILINEAR["k0"], "story 1 must yield"
        assert rel_diff(g["u2"], r["u2"]) <= 1e-9
        assert rel_diff(g["u3"], r["u3"]) <= 1e-9
        if r["eigen"] is not None:
            assert g["eigen"] == pytest.approx(r["eigen"], rel=1e-12)
    # The run record holds every committed step of every session, with its measurement.
    steps = committed_steps(run_dir)
    n_sessions = 2 if variant.get("rebuild") else 1
    nsteps = int(variant.get("nsteps", 300))  # type: ignore[call-overload]
    s1 = [s for s in steps if s.site == "story1"]
    assert len(s1) == n_sessions * nsteps
    first = [s for s in s1 if s.session == s1[0].session]
    drift = [b - a for a, b in zip([0.0] * nsteps, got[0]["u2"], strict=True)]
    assert [s.cmd_disp[0] for s in first] == pytest.approx(drift, rel=1e-12, abs=1e-15)


def test_two_story_over_udp(tmp_path: Path) -> None:
    ref = run_opensees("frame2", **frame_params(ports=None, nsteps=150))["runs"][0]
    with RunningBridge(frame_config("udp"), tmp_path) as bridge:
        ports = [bridge.ports["story1"], bridge.ports["story2"]]
        got = run_opensees("frame2", **frame_params(ports=ports, nsteps=150, udp=True))["runs"][0]
    assert rel_diff(got["u2"], ref["u2"]) <= 1e-9
    assert rel_diff(got["u3"], ref["u3"]) <= 1e-9


@pytest.mark.parametrize(
    ("data_size", "udp"), [(None, False), (1, False), (256, False), (1150, False), (1150, True)]
)
def test_static_1dof_data_sizes(tmp_path: Path, data_size: int | None, udp: bool) -> None:
    cfg = '[bridge]\nrun_name = "static"\n' + site(
        "spring", 0, dofs=1, setup="NoTransformation", model="elastic", params={"k": 100.0},
        transport="udp" if udp else "tcp",
    )
    with RunningBridge(cfg, tmp_path) as bridge:
        res = run_opensees("static_1dof", port=bridge.ports["spring"], load=30.0, nsteps=3,
                           data_size=data_size, udp=udp)
    assert res["u"] == pytest.approx([0.1, 0.2, 0.3], rel=1e-12)
    assert res["force"] == pytest.approx([10.0, 20.0, 30.0], rel=1e-12)


def test_static_1dof_bilinear_matches_steel01(tmp_path: Path) -> None:
    params = {"k0": 100.0, "fy": 20.0, "alpha": 0.02}
    cfg = '[bridge]\nrun_name = "static"\n' + site(
        "spring", 0, dofs=1, setup="NoTransformation", model="bilinear", params=params)
    ref = run_opensees("static_1dof", port=None, load=30.0, nsteps=6,
                       material=["Steel01", 1, 20.0, 100.0, 0.02])
    with RunningBridge(cfg, tmp_path) as bridge:
        got = run_opensees("static_1dof", port=bridge.ports["spring"], load=30.0, nsteps=6)
    assert rel_diff(got["u"], ref["u"]) <= 1e-9
    assert got["force"] == pytest.approx(ref["force"], rel=1e-9)
