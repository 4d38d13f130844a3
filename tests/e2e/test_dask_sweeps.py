"""The one sweep executor: order, failures named, local pool and a real Dask LocalCluster."""

from __future__ import annotations

import io
import os
import re

import pytest

from fresco_bridge.progress import ProgressBar
from fresco_bridge.sweeps import SweepError, run_sweep


def square(x: int) -> int:
    return x * x


def fail_on_three(x: int) -> int:
    if x == 3:
        raise ValueError("three is not allowed")
    return x


def blas_threads(_: int) -> list[int]:
    import numpy  # noqa: F401  (its OpenBLAS must be limited too)
    from threadpoolctl import threadpool_info

    return sorted({pool["num_threads"] for pool in threadpool_info()})


def test_serial_and_pool_give_results_in_item_order() -> None:
    items = list(range(12))
    assert run_sweep(square, items, workers=1) == [x * x for x in items]
    assert run_sweep(square, items, workers=2) == [x * x for x in items]
    assert run_sweep(square, []) == []


def test_a_failing_task_names_its_item_in_every_executor() -> None:
    for workers in (1, 2):
        with pytest.raises(SweepError, match=r"task 4 failed: ValueError: three") as info:
            run_sweep(fail_on_three, [0, 1, 2, 3, 4], workers=workers)
        assert info.value.index == 3


def test_pool_workers_run_one_blas_thread_and_the_parent_env_is_restored() -> None:
    before = os.environ.get("OPENBLAS_NUM_THREADS")
    assert run_sweep(blas_threads, [0, 1], workers=2) == [[1], [1]]
    assert os.environ.get("OPENBLAS_NUM_THREADS") == before


def test_progress_is_reported_per_task() -> None:
    seen: list[tuple[int, int]] = []
    run_sweep(square, [1, 2, 3], workers=2, progress=lambda d, t: seen.append((d, t)))
    assert [d for d, _ in seen] == [1, 2, 3] and {t for _, t in seen} == {3}


def test_each_result_is_handed_over_as_it_finishes_in_every_executor() -> None:
    for workers in (1, 2):
        seen: dict[int, int] = {}
        out = run_sweep(square, [1, 2, 3, 4], workers=workers, on_result=seen.__setitem__)
        assert seen == {0: 1, 1: 4, 2: 9, 3: 16} and out == [1, 4, 9, 16]
    kept: list[int] = []
    with pytest.raises(SweepError, match="task 4 failed"):  # what finished before is kept
        run_sweep(fail_on_three, [0, 1, 2, 3], workers=1, on_result=lambda i, r: kept.append(r))
    assert kept == [0, 1, 2]


def test_bad_workers_and_unreachable_scheduler_are_clear_errors() -> None:
    with pytest.raises(SweepError, match="workers must be >= 1"):
        run_sweep(square, [1], workers=0)
    with pytest.raises(
        SweepError, match=r"cannot reach the Dask scheduler at tcp://127\.0\.0\.1:9"
    ):
        run_sweep(square, [1], scheduler="tcp://127.0.0.1:9", connect_timeout=2.0)


def test_a_real_dask_local_cluster_runs_the_sweep_in_order() -> None:
    from distributed import LocalCluster

    with LocalCluster(
        n_workers=2, threads_per_worker=1, processes=True, dashboard_address=None
    ) as cluster:
        address = cluster.scheduler_address
        seen: dict[int, int] = {}
        assert run_sweep(square, list(range(8)), scheduler=address,
                         on_result=seen.__setitem__) == [x * x for x in range(8)]
        assert seen == {x: x * x for x in range(8)}
        with pytest.raises(SweepError, match="task 4 failed"):
            run_sweep(fail_on_three, [0, 1, 2, 3], scheduler=address, task_timeout=60)


def test_progress_bar_is_quiet_off_a_terminal() -> None:
    out = io.StringIO()
    bar = ProgressBar("fit", 20, stream=out)
    for i in range(1, 21):
        bar(i)
    lines = out.getvalue().splitlines()  # no bar off a terminal: one line at the end
    assert len(lines) == 1 and re.fullmatch(r"fit: 20/20 done in \d+\.\d s", lines[0]), lines
    silent = io.StringIO()
    ProgressBar("x", 3, stream=silent, enabled=False)(3)
    assert silent.getvalue() == ""
