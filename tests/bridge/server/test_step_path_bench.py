"""The in-process step-path benchmark drives a real Bridge through whole steps (a smoke test:
it must keep working as the pump and the site change; the timing itself is not asserted)."""

from __future__ import annotations

import asyncio

import pytest

from benchmarks.bench_step_path import run


@pytest.mark.parametrize(("dofs", "limits"), [(1, False), (1, True), (64, True)])
def test_step_path_bench_runs_whole_steps(dofs: int, limits: bool) -> None:
    per_step = asyncio.run(asyncio.wait_for(run(dofs, 20, True, limits, 1, None), 60.0))
    assert len(per_step) == 1 and per_step[0] > 0.0
