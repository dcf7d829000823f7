"""The executor: independent jobs, each in an isolated worker process, results collected as
they finish.

Every command that runs many (scene, engine spec[, dt]) jobs (``run``, ``sweep``,
``stability``) goes through ``run_jobs``: hand every job to a worker, receive each result as
it finishes (for the progress bar), and return the results in submission order, so the output
does not depend on which worker finished first. Locally (``--jobs N``, one included) the jobs
run in ``IsolatedPool``'s worker processes; with ``--scheduler ADDRESS|local`` on a Dask
cluster (``validation.jobs.dask_backend``); the jobs do not know which one runs them.

Nothing an engine does in a job can take the run down. A job whose process dies (a
segfault, ``os.abort()``, an out-of-memory kill, ``os._exit``), whose code calls
``sys.exit``, or which runs past its time limit (``--job-timeout``, ``time_limit``) is given
to the command's ``lost(job, status, message)``, which returns the result the command
records for it: status ``crashed`` (the signal or exit code in the message) or ``timed_out``.
Its worker is replaced and every other job goes on. On a Dask cluster a job the cluster
failed even after its retries (``KilledWorker``) is ``crashed`` the same way.

Ctrl-C, SIGTERM, SIGHUP (``validation.signals``): workers ignore them (the main process owns
the terminal and the run); the main process stops every worker and raises ``Interrupted``
with the signal, which the command turns into one line and exit 128 + the signal's number.
A worker also ends when the main process ends, even by SIGKILL (``_die_with``).
"""

from __future__ import annotations

import ctypes
import multiprocessing
import os
import select
import signal
import threading
import time
from collections import deque
from collections.abc import Callable, Iterable, Iterator
from concurrent.futures import Executor, as_completed
from contextlib import closing
from dataclasses import dataclass
from functools import partial
from multiprocessing.connection import Connection, wait
from typing import Any

from validation.jobs.dask_backend import (  # BackendError: the commands catch it from here
    BackendError,  # noqa: F401
    dask_executor,
)
from validation.signals import (  # Interrupted: the commands catch it from here
    Interrupted,
    deferred,
    ignore_in_worker,
    signal_number,
)

WORKER_PRELOAD = [
    "validation.jobs.run",
    "validation.jobs.sweep",
    "validation.jobs.stability_search",
]
"""Modules a local Dask cluster's workers import as they start (``local_cluster``)."""

PR_SET_PDEATHSIG = 1
"""prctl(2)'s option: the signal the calling process gets when its parent ends (Linux)."""

JOB_TIMEOUT_FACTOR = 20.0
"""The default time limit of a job is this many times its expected seconds
(``SECONDS_PER_COST`` x its cost): generous, since 5 commands may share 2 cores, and a hung
job costs only its limit."""

SECONDS_PER_COST = 2e-3
"""s per unit of ``plan.expected_cost`` (about one step of one body), an upper bound measured
on the library (``physval run --jobs 2`` on 2 cores shared with other work): the slowest per
unit was box_stack in mini, 1.9e-3 s (4.5 s for 2400); simbenchmark_666_pile took 1.0e-4 to
1.7e-4 s per unit in every engine."""

JOB_TIMEOUT_FLOOR_S = 120.0
"""s, the shortest default time limit: a job's imports (an engine's package: pydrake takes
~5 s cold) and a loaded machine's slow start are not a hang."""

WATCH_INTERVAL_S = 0.5
"""s, how often a worker without ``os.pidfd_open`` checks that the main process lives."""


@dataclass(frozen=True)
class JobFailed:
    """A job that gave no result: ``status`` ``crashed`` (its process died or exited) or
    ``timed_out`` (it ran past its time limit), and the sentence saying so."""

    status: str
    message: str


Lost = Callable[[Any, str, str], Any]
"""``lost(job, status, message)``: the result a command records for a job that gave none
(``JobFailed``: ``crashed`` or ``timed_out``)."""


BACKENDS: dict[str, Callable[[int, str | None], Any]] = {
    "processes": lambda workers, scheduler: IsolatedPool(workers),
    "dask": lambda workers, scheduler: dask_executor(workers, scheduler or "local"),
}
"""Backend name -> a factory taking the number of workers and the scheduler (``--scheduler``:
an address or ``local``): local isolated processes (``IsolatedPool``, whatever ``--jobs``),
or a Dask cluster as a ``concurrent.futures.Executor``. ``dask`` imports Dask only when it
is used: it is an optional extra."""


def default_jobs() -> int:
    """The machine's cores (the default of ``--jobs``)."""
    return os.cpu_count() or 1


def time_limit(
    job_timeout: float | None, cost: Callable[[Any], float] | None
) -> Callable[[Any], float | None]:
    """A job's time limit in s (None: none): ``--job-timeout`` when given (0 turns it off),
    else ``JOB_TIMEOUT_FACTOR`` x its expected seconds (``cost`` x ``SECONDS_PER_COST``), at
    least ``JOB_TIMEOUT_FLOOR_S``."""
    if job_timeout == 0:
        return lambda job: None
    if job_timeout is not None:
        return lambda job: float(job_timeout)
    if cost is None:
        return lambda job: JOB_TIMEOUT_FLOOR_S
    return lambda job: max(JOB_TIMEOUT_FLOOR_S, JOB_TIMEOUT_FACTOR * SECONDS_PER_COST * cost(job))


def run_jobs(
    fn: Callable[[Any], Any],
    jobs: Iterable[Any],
    workers: int,
    on_result: Callable[[int, Any], None] | None = None,
    scheduler: str | None = None,
    lost: Lost | None = None,
    cost: Callable[[Any], float] | None = None,
    job_timeout: float | None = None,
) -> list[Any]:
    """``fn(job)`` for every job; ``on_result(index, result)`` as each finishes (in this
    process, whatever the backend); the results in job order. ``scheduler``: run on a Dask
    cluster (an address, or ``local``) instead of local processes; ``lost``: the result of a
    job that crashed or timed out (module docstring; without it, ``JobFailed`` is the
    result); ``cost``: a job's expected cost, to start the longest first
    (``submission_order``) and to derive its time limit; ``job_timeout``: ``--job-timeout``
    (``time_limit``). Raises ``Interrupted`` on Ctrl-C after stopping every worker,
    ``BackendError`` when the cluster cannot be used."""
    jobs = list(jobs)
    if not jobs:
        return []
    workers = min(workers, len(jobs))
    order = submission_order(jobs, cost if workers > 1 or scheduler is not None else None)
    limit = time_limit(job_timeout, cost)
    results: list[Any] = [None] * len(jobs)
    try:
        if scheduler is None:
            finished = BACKENDS["processes"](workers, None).results(fn, jobs, order, limit)
        else:
            executor = BACKENDS["dask"](workers, scheduler)
            finished = _on_cluster(executor, fn, jobs, order, limit)
        with closing(finished):  # whatever ends the loop, every worker is stopped now
            for index, result in finished:
                if isinstance(result, JobFailed) and lost is not None:
                    result = lost(jobs[index], result.status, result.message)
                results[index] = result
                if on_result is not None:
                    on_result(index, result)
    except KeyboardInterrupt as stop:  # Ctrl-C, or SIGTERM / SIGHUP (signals.Stopped)
        raise Interrupted(signal_number(stop)) from None
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


def _on_cluster(
    executor: Executor,
    fn: Callable[[Any], Any],
    jobs: list[Any],
    order: list[int],
    limit: Callable[[Any], float | None],
) -> Iterator[tuple[int, Any]]:
    """(index, result) of each job as it finishes on the Dask cluster (``executor``), each in
    a process of its own on its worker (``isolated_call``: the same ``crashed`` and
    ``timed_out`` as locally); a job the cluster failed even after its retries (its worker
    died: ``KilledWorker``) is ``JobFailed`` (``crashed``, with Dask's reason)."""
    try:
        with deferred():  # a stop comes after every job is handed over
            futures = {
                executor.submit(partial(isolated_call, fn, limit(jobs[index])), jobs[index]): index
                for index in order
            }
        for future in as_completed(futures):
            try:
                result = future.result()
            except Exception as error:
                result = JobFailed("crashed", failure_message(error))
            yield futures[future], result
    except BaseException:
        executor.shutdown(wait=False, cancel_futures=True)
        raise
    executor.shutdown(wait=True)


def failure_message(error: BaseException) -> str:
    """The message of a job's ``crashed`` row when the cluster lost its worker or it raised
    twice."""
    text = str(error).strip().splitlines()
    detail = f"{type(error).__name__}: {text[0]}" if text else type(error).__name__
    return f"the job failed on the Dask cluster after its retries ({detail})"


def isolated_call(fn: Callable[[Any], Any], limit: float | None, job: Any) -> Any:
    """``fn(job)`` in a worker process of a pool of one, forked from this one (a Dask
    worker's task): its result, or ``JobFailed`` when it crashed or ran past ``limit`` s. A
    Dask worker is a daemonic process, which ``multiprocessing`` forbids children (they
    would outlive it): this one dies with it (``_die_with``), so the rule is lifted while it
    starts."""
    config = multiprocessing.current_process()._config
    daemon = config.pop("daemon", None)
    try:
        ((_, result),) = IsolatedPool(1).results(fn, [job], [0], lambda _: limit)
    finally:
        if daemon is not None:
            config["daemon"] = daemon
    return result


class IsolatedPool:
    """``workers`` worker processes forked from this process (each starts with what it has
    imported and set: the job modules, the environment, a test's patches, as the jobs saw
    when ``--jobs 1`` ran them in this process), each running one job at a time, sent over
    its own pipe. A worker that dies, or whose job runs past its time limit (it is killed),
    is replaced: that job is ``JobFailed``, no other job notices."""

    def __init__(self, workers: int):
        self._size = max(1, workers)
        self._context = multiprocessing.get_context("fork")

    def results(
        self,
        fn: Callable[[Any], Any],
        jobs: list[Any],
        order: list[int],
        limit: Callable[[Any], float | None],
    ) -> Iterator[tuple[int, Any]]:
        """(index, result or ``JobFailed``) of each job as it finishes, handed out in
        ``order``; a job that raised re-raises here (a harness bug, not an engine's: the
        engines' exceptions are rows already), after every worker is stopped."""
        waiting = deque(order)
        workers: list[_Worker] = []
        try:
            with deferred():  # a worker started but not yet known could not be stopped; a
                # worker inherits the handler that holds a stop until it ignores them
                workers = [_Worker(self._context) for _ in range(min(self._size, len(order)))]
            while waiting or any(w.index is not None for w in workers):
                for worker in workers:
                    if worker.index is None and waiting:
                        index = waiting.popleft()
                        worker.give(fn, index, jobs[index], limit(jobs[index]))
                for position, (index, result) in _finished(workers):
                    if isinstance(result, JobFailed):
                        workers[position].stop()
                        with deferred():
                            workers[position] = _Worker(self._context)
                    yield index, result
        finally:
            for worker in workers:
                worker.stop()


def _finished(workers: list[_Worker]) -> list[tuple[int, tuple[int, Any]]]:
    """Wait until a busy worker answers, dies or passes its deadline; (worker position,
    (job index, result)) of each that did."""
    busy = [w for w in workers if w.index is not None]
    deadlines = [w.deadline for w in busy if w.deadline is not None]
    timeout = max(0.0, min(deadlines) - time.monotonic()) if deadlines else None
    ready = set(wait([w.conn for w in busy] + [w.process.sentinel for w in busy], timeout))
    found = []
    for position, worker in enumerate(workers):
        if worker.index is None:
            continue
        if worker.conn in ready or worker.process.sentinel in ready:
            found.append((position, (worker.index, worker.answer())))
        elif worker.deadline is not None and time.monotonic() >= worker.deadline:
            found.append((position, (worker.index, worker.timed_out())))
        else:
            continue
        worker.index = None
    return found


class _Worker:
    """One worker process and the pipe its jobs and results go through."""

    def __init__(self, context: Any):
        self.conn, theirs = context.Pipe()
        self.process = context.Process(target=_serve, args=(theirs, os.getpid()), daemon=True)
        self.process.start()
        theirs.close()
        self.index: int | None = None
        self.deadline: float | None = None
        self.limit: float | None = None

    def give(self, fn: Callable[[Any], Any], index: int, job: Any, limit: float | None) -> None:
        self.conn.send((fn, job))
        self.index, self.limit = index, limit
        self.deadline = None if limit is None else time.monotonic() + limit

    def answer(self) -> Any:
        """The job's result, or ``JobFailed`` when the process died; re-raises a job's
        exception (``_outcome``)."""
        try:
            kind, value = self.conn.recv()
        except (EOFError, OSError):
            self.process.join()
            return JobFailed("crashed", died_message(self.process.exitcode))
        if kind == "raised":
            raise value
        if kind == "interrupted":
            raise KeyboardInterrupt
        return value

    def timed_out(self) -> JobFailed:
        self.stop()
        return JobFailed(
            "timed_out",
            f"the job ran past its time limit of {self.limit:g} s (--job-timeout) and was stopped",
        )

    def stop(self) -> None:
        """SIGKILL (a worker ignores the stop signals and holds nothing to save: results
        are journaled by the main process)."""
        if self.process.exitcode is None:
            self.process.kill()
        self.process.join()
        self.conn.close()


def died_message(exitcode: int | None) -> str:
    """What a ``crashed`` row says of a process that ended with ``exitcode`` (negative: the
    signal that killed it)."""
    if exitcode is not None and exitcode < 0:
        name = signal.Signals(-exitcode).name
        why = CRASH_SIGNALS.get(name, signal.strsignal(-exitcode) or "")
        return f"the job's process was killed by {name} ({why})"
    return f"the job's process exited with code {exitcode} before it finished"


CRASH_SIGNALS = {
    "SIGSEGV": "a segmentation fault in the engine",
    "SIGABRT": "the engine aborted",
    "SIGKILL": "killed from outside: out of memory, or by another process",
    "SIGBUS": "a bus error in the engine",
    "SIGFPE": "a floating-point exception in the engine",
}
"""What a signal that killed a job's process most likely means, for its ``crashed`` row."""


def _serve(conn: Connection, main_pid: int) -> None:
    """A worker: run each job the pipe brings, send back its outcome, until the pipe closes."""
    ignore_in_worker()
    _die_with(main_pid)
    while True:
        try:
            fn, job = conn.recv()
        except EOFError:
            return
        outcome = _outcome(fn, job)
        try:
            conn.send(outcome)
        except Exception as error:  # an unpicklable result or exception: the harness's bug
            conn.send(("raised", RuntimeError(f"the job's result could not be sent: {error!r}")))


def _outcome(fn: Callable[[Any], Any], job: Any) -> tuple[str, Any]:
    """``("done", result)``, ``("raised", exception)``, ``("interrupted", None)``, or
    ``("done", JobFailed)`` when the job called ``sys.exit`` (it exited: ``crashed``)."""
    try:
        return "done", fn(job)
    except SystemExit as exited:
        return "done", JobFailed(
            "crashed", f"the job called sys.exit({exited.code!r}): it tried to end its process"
        )
    except KeyboardInterrupt:
        return "interrupted", None
    except Exception as error:
        return "raised", error


def _die_with(main_pid: int) -> None:
    """End this worker (SIGKILL) as soon as the main process ends, even by SIGKILL: the
    kernel's parent-death signal (``prctl(PR_SET_PDEATHSIG, SIGKILL)``, Linux), else a thread
    waiting on a pidfd of the main process (or looking every ``WATCH_INTERVAL_S``); a main
    process already gone when the worker starts ends it at once."""
    try:
        libc = ctypes.CDLL(None, use_errno=True)
        if libc.prctl(PR_SET_PDEATHSIG, signal.SIGKILL, 0, 0, 0) == 0:
            if os.getppid() != main_pid:  # it ended before the signal was asked for
                os.kill(os.getpid(), signal.SIGKILL)
            return
    except (OSError, AttributeError):  # no prctl here: the watching thread
        pass

    def watch() -> None:
        try:
            pidfd = os.pidfd_open(main_pid)
        except ProcessLookupError:
            pidfd = None
        except (AttributeError, OSError):  # no pidfd (not Linux): look every so often
            while _alive(main_pid):
                time.sleep(WATCH_INTERVAL_S)
            pidfd = None
        if pidfd is not None:
            select.select([pidfd], [], [])
        os.kill(os.getpid(), signal.SIGKILL)

    threading.Thread(target=watch, name="die-with-main", daemon=True).start()


def _alive(pid: int) -> bool:
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    return True
