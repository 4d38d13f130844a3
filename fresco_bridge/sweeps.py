"""One executor for independent sweep tasks: study cases, diagnosis records, seeds x noise.

A sweep maps a picklable top-level function over a list of items and returns the results in the
items' order. Where it runs is the caller's choice, never the task's:

* ``workers=1``: in this process, one after the other (deterministic; for tests and debugging);
* default: a local process pool (``forkserver``: no inherited threads or event loops), one BLAS
  thread per worker so that N workers on N cores do not oversubscribe them;
* ``scheduler="tcp://host:8786"``: a Dask cluster (``dask.distributed``). Its workers must be
  able to import ``fresco_bridge`` (install the same version there).

A task that raises ends the sweep with a :class:`SweepError` naming the item; results are never
silently dropped. Every wait has a deadline (``connect_timeout`` for a scheduler, ``task_timeout``
per sweep when given).
"""

from __future__ import annotations

import concurrent.futures as cf
import multiprocessing
import os
import time
from collections.abc import Callable, Sequence
from typing import Any, TypeVar

__all__ = ["SweepError", "run_sweep"]

T = TypeVar("T")
R = TypeVar("R")

Progress = Callable[[int, int], None]
"""Called as ``progress(done, total)`` after each finished task (in the caller's process)."""

OnResult = Callable[[int, Any], None]
"""Called as ``on_result(index, result)`` as each task finishes, in completion order (in the
caller's process): a long sweep can keep what is done (a resumable log) before it ends."""

_ONE_THREAD = ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS")


class SweepError(RuntimeError):
    """A sweep could not run, or one of its tasks failed (``index`` names the item)."""

    def __init__(self, message: str, index: int | None = None) -> None:
        super().__init__(message)
        self.index = index


def run_sweep(
    fn: Callable[[T], R],
    items: Sequence[T],
    *,
    workers: int | None = None,
    scheduler: str | None = None,
    connect_timeout: float = 30.0,
    task_timeout: float | None = None,
    progress: Progress | None = None,
    on_result: OnResult | None = None,
) -> list[R]:
    """``[fn(item) for item in items]``, run in parallel; results in the items' order (and
    each one to ``on_result`` as it finishes)."""
    if workers is not None and workers < 1:
        raise SweepError(f"workers must be >= 1 (got {workers})")
    if not items:
        return []
    if scheduler is not None:
        return _run_dask(fn, items, scheduler, connect_timeout, task_timeout, progress,
                         on_result)
    n = min(workers or os.cpu_count() or 1, len(items))
    if n == 1:
        return _run_serial(fn, items, progress, on_result)
    return _run_pool(fn, items, n, task_timeout, progress, on_result)


def _failed(index: int, exc: BaseException) -> SweepError:
    error = SweepError(f"task {index + 1} failed: {type(exc).__name__}: {exc}", index)
    error.__cause__ = exc
    return error


def _run_serial(fn: Callable[[T], R], items: Sequence[T], progress: Progress | None,
                on_result: OnResult | None) -> list[R]:
    results: list[R] = []
    for i, item in enumerate(items):
        try:
            results.append(fn(item))
        except Exception as exc:
            raise _failed(i, exc) from exc
        if on_result is not None:
            on_result(i, results[i])
        if progress is not None:
            progress(i + 1, len(items))
    return results


_limits: Any = None


def _one_blas_thread() -> None:
    """Pool initializer: one BLAS/OpenMP thread per worker, for loaded and later libraries."""
    global _limits
    os.environ.update(dict.fromkeys(_ONE_THREAD, "1"))
    from threadpoolctl import threadpool_limits  # type: ignore[import-untyped]

    _limits = threadpool_limits(1)


def _run_pool(
    fn: Callable[[T], R],
    items: Sequence[T],
    n: int,
    task_timeout: float | None,
    progress: Progress | None,
    on_result: OnResult | None,
) -> list[R]:
    results: list[Any] = [None] * len(items)
    deadline = None if task_timeout is None else time.monotonic() + task_timeout
    context = multiprocessing.get_context("forkserver")
    pool = cf.ProcessPoolExecutor(max_workers=n, mp_context=context, initializer=_one_blas_thread)
    try:
        futures = {pool.submit(fn, item): i for i, item in enumerate(items)}
        done = 0
        remaining = None if deadline is None else max(0.0, deadline - time.monotonic())
        try:
            for future in cf.as_completed(futures, timeout=remaining):
                i = futures[future]
                try:
                    results[i] = future.result()
                except Exception as exc:
                    raise _failed(i, exc) from exc
                if on_result is not None:
                    on_result(i, results[i])
                done += 1
                if progress is not None:
                    progress(done, len(items))
        except cf.TimeoutError as exc:
            raise SweepError(f"sweep not finished within {task_timeout:g} s") from exc
    except BaseException:
        processes = list((getattr(pool, "_processes", None) or {}).values())
        pool.shutdown(wait=False, cancel_futures=True)
        for process in processes:
            process.terminate()
        raise
    pool.shutdown(wait=True)
    return results


def _run_dask(
    fn: Callable[[T], R],
    items: Sequence[T],
    scheduler: str,
    connect_timeout: float,
    task_timeout: float | None,
    progress: Progress | None,
    on_result: OnResult | None,
) -> list[R]:
    try:
        from distributed import Client, as_completed  # untyped: used through Any below
    except ImportError as exc:  # pragma: no cover - dask is a dependency
        raise SweepError("--scheduler needs dask.distributed (pip install distributed)") from exc
    try:
        client: Any = Client(  # type: ignore[no-untyped-call]
            scheduler, timeout=connect_timeout, set_as_default=False
        )
    except (OSError, TimeoutError) as exc:
        raise SweepError(
            f"cannot reach the Dask scheduler at {scheduler} within {connect_timeout:g} s: {exc}"
        ) from exc
    results: list[Any] = [None] * len(items)
    try:
        futures = client.map(fn, list(items), pure=False)
        index = {future.key: i for i, future in enumerate(futures)}
        done = 0
        try:
            with client.as_current():
                finishing: Any = as_completed(  # type: ignore[no-untyped-call]
                    futures, timeout=task_timeout
                )
                for future in finishing:
                    i = index[future.key]
                    try:
                        results[i] = future.result()
                    except Exception as exc:
                        raise _failed(i, exc) from exc
                    if on_result is not None:
                        on_result(i, results[i])
                    done += 1
                    if progress is not None:
                        progress(done, len(items))
        except TimeoutError as exc:
            raise SweepError(f"sweep not finished within {task_timeout:g} s") from exc
        finally:
            client.cancel(futures)
    finally:
        client.close(timeout=connect_timeout)
    return results
