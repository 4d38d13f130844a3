"""Words that mislead no more: a session's close line counts the session's own steps (after a
resume too), and HOLD lines are limited per (site, cause), not per site."""

from __future__ import annotations

import asyncio
import io
import logging

import pytest

from fresco_bridge.config import parse_config
from fresco_bridge.logs import RateLimitFilter
from fresco_bridge.sites import SiteState
from fresco_bridge.sites.experimental import ExperimentalSite
from protocol import Signals
from tests.bridge.sites.test_guard import Scripted

CFG = parse_config('[[sites]]\nname = "s"\nport = 0\n[[sites.limits]]\ndisp_min = -1.0\n'
                   'disp_max = 1.0\n').sites[0]


def _trial(d: float, t: float) -> Signals:
    return Signals(disp=(d,), vel=(0.0,), accel=(0.0,), time=(t,))


def _steps(site: ExperimentalSite, n: int) -> None:
    async def run() -> None:
        for i in range(n):
            await site.set_trial(_trial(0.01 * (i + 1), 0.1 * (i + 1)))
            await site.commit()

    asyncio.run(run())


def test_the_close_line_counts_the_sessions_steps_after_a_resume(
        caplog: pytest.LogCaptureFixture) -> None:
    site = ExperimentalSite(CFG, Scripted([]), None, controller_timeout=1.0)
    site.resume_from(session=1, step=70000, time=7000.0)  # a run resumed after a kill -9
    with caplog.at_level(logging.INFO, logger="fresco_bridge"):
        site.open_session("127.0.0.1:9")
        _steps(site, 3)
        site.close_session("the client said goodbye")
        site.open_session("127.0.0.1:10")
        _steps(site, 2)
        site.close_session("the client said goodbye")
    closes = [r.getMessage() for r in caplog.records if "closed after" in r.getMessage()]
    assert closes == [
        "site s: session 2 closed after 3 step(s) (steps 70001-70003 of the resumed run): the "
        "client said goodbye",
        "site s: session 3 closed after 2 step(s): the client said goodbye"]


def test_a_second_hold_cause_within_the_interval_is_logged() -> None:
    """One site, two HOLD causes within 10 s (a limit, then a lost controller): two lines; the
    same cause again: dropped and counted."""
    out = io.StringIO()
    handler = logging.StreamHandler(out)
    handler.addFilter(RateLimitFilter(10.0))
    logger = logging.getLogger("fresco_bridge")
    logger.addHandler(handler)
    try:
        for d in (1.5, 1.75):  # the limit: twice, two values
            site = ExperimentalSite(CFG, Scripted([]), None, controller_timeout=1.0)
            site.open_session("127.0.0.1:9")
            asyncio.run(site.set_trial(_trial(d, 0.1)))
            assert site.state is SiteState.HOLD
        from fresco_bridge.controls.base import ControllerLinkError

        site = ExperimentalSite(CFG, Scripted([ControllerLinkError("link lost")]), None,
                                controller_timeout=1.0)
        site.open_session("127.0.0.1:9")

        async def lost() -> None:
            await site.set_trial(_trial(0.5, 0.1))
            await site.commit()

        asyncio.run(lost())
        assert site.state is SiteState.HOLD
    finally:
        logger.removeHandler(handler)
    holds = [line for line in out.getvalue().splitlines() if ": HOLD at step" in line]
    assert len(holds) == 2, holds
    assert "limit exceeded" in holds[0] and "link lost" in holds[1]
