"""The eager path (an in-process controller called synchronously, a request answered inside
``data_received``) and the full asynchronous path (the same specimen behind a controller that
suspends, every call under its deadline, requests finished in tasks) are one behaviour: byte for
byte the same replies and the same run record, through limits that act, a HOLD and NaN answers.
"""

from __future__ import annotations

import asyncio
import math
import struct
from pathlib import Path
from typing import Any

import pytest

from fresco_bridge.config import parse_config
from fresco_bridge.controls.base import Controller, Daq, InlineController
from fresco_bridge.controls.sim import SimController
from fresco_bridge.eager import start_eager
from fresco_bridge.record import RunRecord, read_record
from fresco_bridge.server.connection import SessionPump, SiteListener
from fresco_bridge.sites.access import Allowlist
from fresco_bridge.sites.experimental import ExperimentalSite
from protocol import SizeID

DOFS = 2
SID = SizeID.for_generic_client(DOFS, 16)
VEC = struct.Struct(f"<{SID.data_size}d")
WAIT = 5.0  # s: deadline of every wait in this test


class Suspending(Controller):
    """The same specimen behind a controller that suspends at every call (as a network
    controller does): the site takes its asynchronous path."""

    def __init__(self, inner: InlineController) -> None:
        self.inner = inner
        self.n_actuators = inner.n_actuators
        self.calls = 0

    async def _io(self) -> None:
        self.calls += 1
        await asyncio.sleep(0)

    async def set_ctrl(self, disp: tuple[float, ...]) -> None:
        await self._io()
        self.inner.set_ctrl_now(disp)

    async def get_daq(self) -> Daq:
        await self._io()
        return self.inner.get_daq_now()

    async def commit(self) -> None:
        await self._io()
        self.inner.commit_now()

    async def tangent_stiffness(self) -> tuple[float, ...]:
        await self._io()
        return self.inner.tangent_stiffness_now()

    async def initial_stiffness(self) -> tuple[float, ...]:
        await self._io()
        return self.inner.initial_stiffness_now()


def config(policy: str) -> str:
    limits = "".join(f"""
[[sites.limits]]
actuator = {a}
disp_min = -2.0
disp_max = 2.0
disp_increment = 0.75
force_max = 150.0
policy = "{policy}"
""" for a in (1, 2))
    return f"""
[[sites]]
name = "spec"
port = 0
dofs = {DOFS}
[sites.controller]
model = "bilinear"
params = {{ k0 = 100.0, fy = 20.0, alpha = 0.02 }}
{limits}"""


def request(code: int) -> bytes:
    return VEC.pack(float(code), *([0.0] * (SID.data_size - 1)))


def trial(d: tuple[float, float], t: float) -> bytes:
    values = [3.0, *d, 0.0, 0.0, 0.0, 0.0, t]
    return VEC.pack(*values, *([0.0] * (SID.data_size - len(values))))


def messages() -> list[bytes]:
    """Newton steps (a repeated trial, tangent and damping requests), a step the limits act
    on (too large an increment), and a non-finite trial (HOLD; NaN answers from then on)."""
    out = [SID.encode(), request(12), request(15)]
    path = [(0.1 * math.sin(0.3 * i), -0.05 * i) for i in range(1, 9)]
    path[4] = (path[3][0] + 1.5, path[4][1])  # past disp_increment: reject / clamp
    for i, d in enumerate(path):
        t = 0.01 * (i + 1)
        for dd in ((d[0] * 0.9, d[1] * 0.9), d, d):
            out += [trial(dd, t), request(10), request(14), request(13), request(14)]
        out += [request(5)]
    out += [trial((math.nan, 0.0), 0.2), request(10), request(13), request(5), request(99)]
    return out


async def run(tmp: Path, policy: str, suspending: bool) -> tuple[list[bytes], list[Any], int]:
    cfg = parse_config(config(policy)).sites[0]
    inner = SimController.from_params(DOFS, "bilinear", {"k0": 100.0, "fy": 20.0, "alpha": 0.02})
    controller: Controller = Suspending(inner) if suspending else inner
    record = RunRecord(tmp)
    site = ExperimentalSite(cfg, controller, record, controller_timeout=WAIT)
    listener = SiteListener(site, Allowlist(["127.0.0.1"]), 65536, 60.0)
    replies: list[bytes] = []
    pump = SessionPump(listener, "test:1", replies.append, lambda: None, lambda _on: None,
                       transport="tcp")
    loop = asyncio.get_running_loop()
    for data in messages():
        pump.feed(data)
        deadline = loop.time() + WAIT
        while pump.busy:  # the asynchronous path: the request finishes in a task
            assert loop.time() < deadline, "a request did not finish"
            await asyncio.sleep(0)
    assert pump.closed  # DIE
    record.close()
    lines = [{k: v for k, v in line.items() if k != "t"} for line in read_record(tmp)]
    return replies, lines, getattr(controller, "calls", 0)


@pytest.mark.parametrize("policy", ["reject", "clamp"])
def test_eager_and_async_paths_answer_and_record_the_same(tmp_path: Path, policy: str) -> None:
    async def both() -> tuple[Any, Any]:
        (tmp_path / "eager").mkdir()
        (tmp_path / "async").mkdir()
        return (await run(tmp_path / "eager", policy, False),
                await run(tmp_path / "async", policy, True))

    (eager_replies, eager_lines, _), (async_replies, async_lines, calls) = asyncio.run(both())
    assert calls > 20  # the second run really took the asynchronous path
    assert len(eager_replies) == len(async_replies) > 50
    assert eager_replies == async_replies
    assert eager_lines == async_lines
    events = [line.get("event") for line in eager_lines]
    assert "limit" in events and "hold" in events and "integrator-stop" in events
    commits = [line["kind"] for line in eager_lines].count("commit")
    assert commits == (4 if policy == "reject" else 8), commits
    last = struct.unpack_from("<2d", eager_replies[-1])  # the tangent after the HOLD
    assert all(math.isnan(v) for v in last)


def test_the_eager_path_runs_without_a_coroutine_per_request() -> None:
    """An in-process specimen answers inside ``feed``: no request is left to a task."""
    async def go() -> int:
        cfg = parse_config(config("reject")).sites[0]
        site = ExperimentalSite(cfg, SimController.from_params(
            DOFS, "bilinear", {"k0": 100.0, "fy": 20.0, "alpha": 0.02}), None,
            controller_timeout=WAIT)
        replies: list[bytes] = []
        pump = SessionPump(SiteListener(site, Allowlist(["127.0.0.1"]), 65536, 60.0), "t:1",
                           replies.append, lambda: None, lambda _on: None, transport="tcp")
        for data in messages()[:-5]:
            pump.feed(data)
            assert not pump.busy
        assert site.set_trial_eager(site.trial) is None  # done at once: no coroutine
        # NaN here (the site holds): compared by value, not by float identity (the compiled
        # step path makes a new NaN object where the pure one may share one)
        assert list(map(repr, start_eager(site.tangent()))) == list(map(repr, site.tangent_eager()))
        return len(replies)

    assert asyncio.run(go()) > 50
