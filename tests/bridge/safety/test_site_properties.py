"""Property test of a real site (in-process specimen, driven like the connection drives it):
whatever the integrator sends and whatever the operator does, every command that reaches the
controller is within the limits, and nothing reaches it outside RUNNING."""

from __future__ import annotations

import math
from typing import Any

from hypothesis import given, settings
from hypothesis import strategies as st

from fresco_bridge.config import parse_config
from fresco_bridge.controls.base import InlineController
from fresco_bridge.eager import Suspended, start_eager
from fresco_bridge.sites import SiteError, SiteState
from fresco_bridge.sites.experimental import ExperimentalSite
from fresco_bridge.sites.experimental_kind import site_controller as make_controller
from protocol import Signals, SignalSizes

SIZES = SignalSizes(disp=0, vel=0, accel=0, force=1, time=0)
LO, HI, INC = -3.0, 3.0, 0.5


def _site(policy: str) -> tuple[ExperimentalSite, list[tuple[int, float]]]:
    text = f"""
[[sites]]
name = "p"
port = 0
[sites.controller]
model = "bilinear"
params = {{ k0 = 10.0, fy = 8.0, alpha = 0.1 }}
[[sites.limits]]
disp_min = {LO}
disp_max = {HI}
disp_increment = {INC}
force_max = 9.0
policy = "{policy}"
"""
    cfg = parse_config(text).sites[0]
    controller = make_controller(cfg)
    sent: list[tuple[int, float]] = []  # (session, command)
    assert isinstance(controller, InlineController), "set_ctrl_now is what is spied"
    original = controller.set_ctrl_now
    site = ExperimentalSite(cfg, controller, None, controller_timeout=1.0)

    def spy(disp: tuple[float, ...]) -> None:
        assert site.state is SiteState.RUNNING, f"command {disp} forwarded in {site.state}"
        sent.append((site.session, disp[0]))
        original(disp)

    controller.set_ctrl_now = spy  # type: ignore[method-assign]
    return site, sent


def _run(coro: Any) -> Any:
    r = start_eager(coro)
    assert not isinstance(r, Suspended), "no pause in this test: nothing may wait"
    return r


action = st.one_of(
    st.tuples(st.just("trial"), st.floats(min_value=-6.0, max_value=6.0)),
    st.tuples(st.just("trial"), st.sampled_from([math.nan, math.inf])),
    st.tuples(st.just("commit"), st.just(0.0)),
    st.tuples(st.just("abort"), st.just(0.0)),
    st.tuples(st.just("resume"), st.just(0.0)),
    st.tuples(st.just("reconnect"), st.just(0.0)),
)


@settings(max_examples=150, deadline=None)
@given(policy=st.sampled_from(["reject", "clamp"]), actions=st.lists(action, max_size=40))
def test_nothing_outside_the_limits_or_outside_running_reaches_the_controller(
    policy: str, actions: list[tuple[str, float]]
) -> None:
    site, sent = _site(policy)
    site.open_session("prop")
    t = 0.0
    for kind, value in actions:
        try:
            if kind == "trial":
                t += 0.01
                zero = (0.0,)
                _run(site.set_trial(Signals(disp=(value,), vel=zero, accel=zero, time=(t,))))
                _run(site.out_signals(SIZES))
            elif kind == "commit":
                _run(site.commit())
            elif kind == "abort":
                site.operator_abort("test")
            elif kind == "resume" and site.state is SiteState.FAULT and not site.peer:
                site.operator_resume("test")
            elif kind == "reconnect":
                site.close_session("test reconnect")
                if site.state is not SiteState.FAULT:
                    site.open_session("prop")
        except SiteError:
            assert site.state is SiteState.FAULT  # only an aborted site ends the session
            site.close_session("aborted", error=True)
        assert site.state in (SiteState.RUNNING, SiteState.HOLD, SiteState.FAULT,
                              SiteState.IDLE)
    previous, session = 0.0, 0
    for s, cmd in sent:
        if s != session:  # the specimen is reset to zero for every session
            previous, session = 0.0, s
        assert LO <= cmd <= HI
        assert abs(cmd - previous) <= INC + 1e-12
        previous = cmd
