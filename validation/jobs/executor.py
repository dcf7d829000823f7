"""The executor: independent jobs run in worker processes, results collected as they finish.

Every command that runs many (scene, engine spec[, dt]) jobs (``run``, ``sweep``,
``stability``) goes through ``run_jobs``: submit every job, receive each result as it
finishes (for the progress bar), and return the results in submission order, so the output
does not depend on which worker finished first. A backend is anything with the
``Executor`` interface (``submit`` returning a future, ``shutdown``); the local backends are
in ``BACKENDS`` and a distributed one can be added there without touching the jobs.

Ctrl-C: workers ignore SIGINT (the main process owns the terminal); the main process stops
every worker and raises ``Interrupted``, which the command turns into one line and exit 130.
"""

from __future__ import annotations

import multiprocessing
import os
import signal
from collections.abc import Callable, Iterable, Iterator
from concurrent.futures import Executor, Future, ProcessPoolExecutor, as_completed
from typing import Any

WORKER_PRELOAD = [
    "validation.jobs.run",
    "validation.jobs.sweep",
    "validation.jobs.stability_search",
]
"""Modules the fork server imports once, so each worker starts with them loaded."""


class Interrupted(Exception):  # noqa: N818 (a user action, not an error)
    """The user pressed Ctrl-C; every worker has been stopped."""


class SerialExecutor(Executor):
    """Runs each job in this process when it is submitted (``--jobs 1``): no pickling, and a
    debugger or profiler sees the whole run."""

    def submit(self, fn: Callable, /, *args: Any, **kwargs: Any) -> Future:
        future: Future = Future()
        try:
            future.set_result(fn(*args, **kwargs))
        except BaseException as error:  # delivered through the future, as a pool would
            if isinstance(error, KeyboardInterrupt):
                raise
            future.set_exception(error)
        return future


def _ignore_interrupt() -> None:
    signal.signal(signal.SIGINT, signal.SIG_IGN)


def process_pool(workers: int) -> Executor:
    """Worker processes forked from a clean fork server (no threads of the main process are
    inherited), each ignoring Ctrl-C."""
    context = multiprocessing.get_context("forkserver")
    context.set_forkserver_preload(WORKER_PRELOAD)
    return ProcessPoolExecutor(
        max_workers=workers, mp_context=context, initializer=_ignore_interrupt
    )


BACKENDS: dict[str, Callable[[int], Executor]] = {
    "serial": lambda workers: SerialExecutor(),
    "processes": process_pool,
}
"""Backend name -> a factory taking the number of workers."""


def default_jobs() -> int:
    """The machine's cores (the default of ``--jobs``)."""
    return os.cpu_count() or 1


def executor_for(jobs: int) -> Executor:
    """Serial for one job at a time, else local worker processes."""
    return BACKENDS["serial" if jobs <= 1 else "processes"](jobs)


def _completed(futures: dict[Future, int]) -> Iterator[tuple[int, Any]]:
    for future in as_completed(futures):
        yield futures[future], future.result()


def run_jobs(
    fn: Callable[[Any], Any],
    jobs: Iterable[Any],
    workers: int,
    on_result: Callable[[int, Any], None] | None = None,
) -> list[Any]:
    """``fn(job)`` for every job; ``on_result(index, result)`` as each finishes; the results in
    job order. Raises ``Interrupted`` on Ctrl-C after stopping every worker."""
    jobs = list(jobs)
    executor = executor_for(min(workers, len(jobs)) if jobs else 1)
    results: list[Any] = [None] * len(jobs)
    try:
        futures = {executor.submit(fn, job): index for index, job in enumerate(jobs)}
        for index, result in _completed(futures):
            results[index] = result
            if on_result is not None:
                on_result(index, result)
    except KeyboardInterrupt:
        _stop(executor)
        raise Interrupted from None
    except BaseException:
        _stop(executor)
        raise
    executor.shutdown(wait=True)
    return results


def _stop(executor: Executor) -> None:
    """Cancel what has not started and end the workers now."""
    processes = getattr(executor, "_processes", None) or {}
    for process in list(processes.values()):
        process.terminate()
    executor.shutdown(wait=False, cancel_futures=True)
