"""The in-process step-path benchmark still drives a real Bridge through whole steps as the pump
and the site change (a smoke run of ``python -m benchmarks.bench_step_path --quick``, a few
seconds; it checks every step's replies itself; the timing is not asserted)."""

from __future__ import annotations

from tests.support.benchmark import run_benchmark


def test_the_step_path_bench_runs_whole_steps_at_64_dofs_with_limits() -> None:
    printed = run_benchmark("bench_step_path", "--quick", "--dofs", "64", "--limits",
                            deadline=120.0)
    assert "step path, 64 DOF, record on, limits on" in printed
