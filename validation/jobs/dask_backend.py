"""The Dask distributed backend of the executor (``--scheduler ADDRESS|local``).

``dask_executor(workers, scheduler)`` connects a ``distributed.Client`` to the scheduler at
``scheduler`` (``tcp://host:8786``: an existing cluster whose workers have physval
installed) or, for ``local``, starts a ``distributed.LocalCluster`` of ``workers`` worker
processes of one thread each (the engines hold the GIL: threads would not run in parallel),
and returns it as a ``concurrent.futures.Executor`` for ``executor.run_jobs``.

Each job is one Dask task, submitted with ``pure=False`` (a job is never deduplicated or
cached: two equal jobs are two runs) and ``retries=RETRIES``. What Dask does when a job
fails:

- the job raised on its worker: Dask runs it again ``RETRIES`` more times (``retries=``);
- its worker died (killed, out of memory): the scheduler gives the job to another worker
  until ``allowed-failures`` workers have died running it, then fails it with
  ``KilledWorker``. A local cluster is started with ``LOCAL_ALLOWED_FAILURES`` (the job is
  run twice in all); an existing cluster uses its scheduler's
  ``distributed.scheduler.allowed-failures`` (Dask's default 3).

A job that still failed reaches ``run_jobs`` as an exception, and the command records it as
an ``error`` row (its ``lost`` function, with Dask's reason); the run goes on. Dask's own log
lines are silenced in this process and in a local cluster's workers (the reason is in the
row): the run prints its progress and summary, not the cluster's chatter. A finished job's
result lives on its worker until this process fetches it; a worker lost before that makes
Dask run the job again, which is not counted as a failure.
"""

from __future__ import annotations

import logging
from concurrent.futures import Executor, Future
from typing import Any


class BackendError(Exception):
    """The backend cannot be used (Dask missing, a scheduler that does not answer): one line
    for the user, exit 2, before any job has run."""


RETRIES = 1
"""Dask ``retries=``: a job that raised is run once more before it counts as failed."""

LOCAL_ALLOWED_FAILURES = 1
"""A local cluster's ``allowed-failures``: a job whose worker died is given to another
worker once; a second death fails it (``KilledWorker``)."""

LOCAL_SCHEDULER = {
    "distributed.scheduler.allowed-failures": LOCAL_ALLOWED_FAILURES,
    "distributed.scheduler.worker-saturation": 1.0,
}
"""A local cluster's scheduler settings. ``worker-saturation`` 1.0: a worker of one thread
holds only the job it runs (Dask's default 1.1 assigns it a second one ahead), so a worker
that dies counts a death against that job alone, never against an innocent job queued
behind it."""

CONNECT_TIMEOUT_S = 30
"""How long to wait for the scheduler at ``--scheduler ADDRESS`` to answer."""

MISSING = (
    '--scheduler needs Dask: pip install -e ".[distributed]" (dask[distributed]); '
    "without --scheduler the jobs run in local processes"
)
"""The one line printed (exit 2) when ``--scheduler`` is given and Dask is not installed."""


def distributed_missing() -> str:
    """``MISSING`` when ``distributed`` cannot be imported, else empty."""
    try:
        import distributed  # noqa: F401
    except ImportError:
        return MISSING
    return ""


class DaskExecutor(Executor):
    """Jobs as Dask tasks on ``client``'s cluster; ``cluster`` (a LocalCluster this backend
    started) is closed with it."""

    loses_workers = True
    """A worker may die mid-job: ``run_jobs`` asks the command for the job's error result."""

    def __init__(self, client: Any, cluster: Any = None):
        self._client = client
        self._cluster = cluster
        self._executor = client.get_executor(retries=RETRIES, pure=False)

    def submit(self, fn, /, *args: Any, **kwargs: Any) -> Future:
        return self._executor.submit(fn, *args, **kwargs)

    def shutdown(self, wait: bool = True, *, cancel_futures: bool = False) -> None:
        """Close the client (and the cluster it started); with ``cancel_futures``, the
        unfinished jobs are cancelled first."""
        try:
            self._executor.shutdown(wait=wait and not cancel_futures)
        finally:
            self._client.close()
            if self._cluster is not None:
                self._cluster.close()


def _quiet() -> None:
    """Dask's log lines off in this process: what a lost job says is in its error row."""
    for name in ("distributed", "dask"):
        logging.getLogger(name).setLevel(logging.CRITICAL)


def dask_executor(workers: int, scheduler: str) -> DaskExecutor:
    """A ``DaskExecutor`` on the cluster at ``scheduler``, or a new local one of ``workers``
    processes for ``local``. Raises ``BackendError`` when Dask is missing or the scheduler
    does not answer."""
    if distributed_missing():
        raise BackendError(MISSING)
    import dask
    from distributed import Client, LocalCluster

    _quiet()
    if scheduler == "local":
        with dask.config.set({"distributed.scheduler.allowed-failures": LOCAL_ALLOWED_FAILURES}):
            cluster = LocalCluster(
                n_workers=max(1, workers),
                threads_per_worker=1,
                processes=True,
                dashboard_address=None,
                silence_logs=logging.CRITICAL,
            )
        return DaskExecutor(Client(cluster), cluster)
    try:
        client = Client(scheduler, timeout=CONNECT_TIMEOUT_S)
    except (OSError, TimeoutError, ValueError) as error:
        raise BackendError(
            f"--scheduler {scheduler}: no Dask scheduler answered ({type(error).__name__}: "
            f"{str(error).splitlines()[0] if str(error) else ''}); start one with "
            "`dask scheduler` and workers with `dask worker ADDRESS`"
        ) from None
    return DaskExecutor(client)
