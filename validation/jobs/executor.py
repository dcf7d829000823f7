"""The executor: independent jobs run in worker processes, results collected as they finish.

Every command that runs many (scene, engine spec[, dt]) jobs (``run``, ``sweep``,
``stability``) goes through ``run_jobs``: submit every job, receive each result as it
finishes (for the progress bar), and return the results in submission order, so the output
does not depend on which worker finished first. A backend is anything with the
``Executor`` interface (``submit`` returning a future, ``shutdown``); the local backends are
in ``BACKENDS``, with ``dask`` (``validation.jobs.dask_backend``: a Dask cluster, chosen by
``--scheduler ADDRESS|local``) beside them; the jobs do not know which one runs them.

A job whose worker was lost (a distributed backend only: Dask retries it first) is given to
the command's ``lost(job, message)``, which returns the result the command records for it
(an ``error`` row), so the run completes.

Ctrl-C, SIGTERM, SIGHUP (``validation.signals``): workers ignore them (the main process owns
the terminal and the run); the main process stops every worker and raises ``Interrupted``
with the signal, which the command turns into one line and exit 128 + the signal's number.
"""

from __future__ import annotations

import multiprocessing
import os
from collections.abc import Callable, Iterable, Iterator
from concurrent.futures import Executor, Future, ProcessPoolExecutor, as_completed
from contextlib import nullcontext
from multiprocessing import forkserver, resource_tracker
from typing import Any

from validation.jobs.dask_backend import (  # BackendError: the commands catch it from here
    BackendError,  # noqa: F401
    dask_executor,
)
from validation.signals import (  # Interrupted: the commands catch it from here
    Interrupted,
    deferred,
    ignore_in_worker,
    ignored_while_starting_helpers,
    signal_number,
)

WORKER_PRELOAD = [
    "validation.jobs.run",
    "validation.jobs.sweep",
    "validation.jobs.stability_search",
]
"""Modules the fork server imports once, so each worker starts with them loaded."""


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


def process_pool(workers: int) -> Executor:
    """Worker processes forked from a clean fork server (no threads of the main process are
    inherited), each ignoring the stop signals (``signals.ignore_in_worker``)."""
    context = multiprocessing.get_context("forkserver")
    context.set_forkserver_preload(WORKER_PRELOAD)
    with ignored_while_starting_helpers():  # they outlive a stop signal to the group
        resource_tracker.ensure_running()
        forkserver.ensure_running()
    return ProcessPoolExecutor(
        max_workers=workers, mp_context=context, initializer=ignore_in_worker
    )


BACKENDS: dict[str, Callable[[int, str | None], Executor]] = {
    "serial": lambda workers, scheduler: SerialExecutor(),
    "processes": lambda workers, scheduler: process_pool(workers),
    "dask": lambda workers, scheduler: dask_executor(workers, scheduler or "local"),
}
"""Backend name -> a factory taking the number of workers and the scheduler (``--scheduler``:
an address, ``local``, or None for the local backends). ``dask`` imports Dask only when it is
used: it is an optional extra."""


def default_jobs() -> int:
    """The machine's cores (the default of ``--jobs``)."""
    return os.cpu_count() or 1


def executor_for(jobs: int, scheduler: str | None = None) -> Executor:
    """A Dask cluster when a scheduler is given; else serial for one job at a time, else
    local worker processes."""
    if scheduler is not None:
        return BACKENDS["dask"](jobs, scheduler)
    return BACKENDS["serial" if jobs <= 1 else "processes"](jobs, None)


def _completed(
    executor: Executor, futures: dict[Future, int], jobs: list[Any], lost: Lost | None
) -> Iterator[tuple[int, Any]]:
    """(index, result) as each job finishes; on a backend that can lose workers
    (``loses_workers``), a job that failed even after its retries is ``lost(job, message)``."""
    for future in as_completed(futures):
        index = futures[future]
        try:
            result = future.result()
        except Exception as error:
            if lost is None or not getattr(executor, "loses_workers", False):
                raise
            result = lost(jobs[index], failure_message(error))
        yield index, result


def failure_message(error: BaseException) -> str:
    """The message of a job's ``error`` row when its worker was lost or it raised twice."""
    text = str(error).strip().splitlines()
    detail = f"{type(error).__name__}: {text[0]}" if text else type(error).__name__
    return f"the job failed on the Dask cluster after its retries ({detail})"


Lost = Callable[[Any, str], Any]
"""``lost(job, message)``: the result a command records for a job the cluster lost."""


def run_jobs(
    fn: Callable[[Any], Any],
    jobs: Iterable[Any],
    workers: int,
    on_result: Callable[[int, Any], None] | None = None,
    scheduler: str | None = None,
    lost: Lost | None = None,
    cost: Callable[[Any], float] | None = None,
) -> list[Any]:
    """``fn(job)`` for every job; ``on_result(index, result)`` as each finishes (in this
    process, whatever the backend); the results in job order. ``scheduler``: run on a Dask
    cluster (an address, or ``local``) instead of local processes; ``lost``: the result of a
    job the cluster failed twice (module docstring); ``cost``: a job's expected cost, to
    start the longest first (``submission_order``). Raises ``Interrupted`` on Ctrl-C after
    stopping every worker, ``BackendError`` when the cluster cannot be used."""
    jobs = list(jobs)
    if not jobs:
        return []
    workers = min(workers, len(jobs))
    executor = executor_for(workers, scheduler)
    results: list[Any] = [None] * len(jobs)
    parallel = scheduler is not None or workers > 1
    try:
        # a pool spawns its workers while jobs are submitted: a stop comes after they exist
        # (the serial backend runs each job inside submit: it must stay interruptible)
        with deferred() if parallel else nullcontext():
            futures = {
                executor.submit(fn, jobs[index]): index
                for index in submission_order(jobs, cost if parallel else None)
            }
        for index, result in _completed(executor, futures, jobs, lost):
            results[index] = result
            if on_result is not None:
                on_result(index, result)
    except KeyboardInterrupt as stop:  # Ctrl-C, or SIGTERM / SIGHUP (signals.Stopped)
        _stop(executor)
        raise Interrupted(signal_number(stop)) from None
    except BaseException:
        _stop(executor)
        raise
    executor.shutdown(wait=True)
    return results


def submission_order(jobs: list[Any], cost: Callable[[Any], float] | None) -> list[int]:
    """The job indices in the order they are handed to the workers: the longest expected
    first (longest-processing-time-first: a long job started last would run alone at the
    end while the other workers wait), equal costs in job order; job order without ``cost``
    (one worker gains nothing from it). Only the order of the work changes: every result
    still goes to its job's index."""
    indices = list(range(len(jobs)))
    if cost is None:
        return indices
    return sorted(indices, key=lambda index: -cost(jobs[index]))


def _stop(executor: Executor) -> None:
    """Cancel what has not started and end the workers now (SIGKILL: they ignore the stop
    signals, and hold nothing to save: results are journaled by this process)."""
    processes = getattr(executor, "_processes", None) or {}
    for process in list(processes.values()):
        process.kill()
    executor.shutdown(wait=False, cancel_futures=True)
