"""The local Dask cluster of ``--scheduler local``, run as a child process in a session of its own.

``python -m validation.jobs.local_cluster WORKERS`` starts a ``distributed.LocalCluster`` of
``WORKERS`` worker processes of one thread each, prints its scheduler's address on one line
of stdout, and runs until its stdin closes (the physval process that started it ended, even
by SIGKILL), then closes the cluster.

Why a child in its own session: Ctrl-C in a terminal sends SIGINT to every process of the
terminal's foreground process group. A LocalCluster started inside the physval process puts
its worker processes in that group, so one Ctrl-C also reached every Dask worker, which
printed Dask's tracebacks ("Nanny failed to start" while starting, a ``KeyboardInterrupt``
from its event loop while running) and could hang the way out. In a new session no
terminal signal reaches the cluster: the physval process alone handles Ctrl-C, and stops the
cluster itself (``dask_backend.LocalClusterProcess.stop``).
"""

from __future__ import annotations

import logging
import sys

from validation.jobs.dask_backend import quiet_dask_logs
from validation.jobs.executor import WORKER_PRELOAD

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


def serve(workers: int) -> None:
    """Start the cluster (each worker imports the job modules, ``executor.WORKER_PRELOAD``,
    as it starts), print its address, hold it until stdin
    closes, close it."""
    import dask
    from distributed import LocalCluster

    quiet_dask_logs()
    with dask.config.set(LOCAL_SCHEDULER):
        cluster = LocalCluster(
            n_workers=max(1, workers),
            threads_per_worker=1,
            processes=True,
            dashboard_address=None,
            silence_logs=logging.CRITICAL,
            preload=WORKER_PRELOAD,  # imported as each worker starts
        )
    try:
        print(cluster.scheduler_address, flush=True)
        sys.stdin.read()  # returns at EOF: the physval process closed the pipe or ended
    finally:
        cluster.close()


if __name__ == "__main__":
    serve(int(sys.argv[1]))
