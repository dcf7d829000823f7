"""The Dask distributed backend of the executor (``--scheduler ADDRESS|local``).

``dask_executor(workers, scheduler)`` connects a ``distributed.Client`` to the scheduler at
``scheduler`` (``tcp://host:8786``: an existing cluster whose workers have physval
installed) or, for ``local``, starts a ``distributed.LocalCluster`` of ``workers`` worker
processes of one thread each (the engines hold the GIL: threads would not run in parallel),
and returns it as a ``concurrent.futures.Executor`` for ``executor.run_jobs``. The local
cluster runs in a child process in a session of its own (``validation.jobs.local_cluster``):
a terminal's Ctrl-C reaches this process alone, which then stops the cluster, so Dask's
processes print nothing and the way out cannot hang on them.

Each job is one Dask task, submitted with ``pure=False`` (a job is never deduplicated or
cached: two equal jobs are two runs) and ``retries=RETRIES``. What Dask does when a job
fails:

- the job raised on its worker: Dask runs it again ``RETRIES`` more times (``retries=``);
- its worker died (killed, out of memory): the scheduler gives the job to another worker
  until ``allowed-failures`` workers have died running it, then fails it with
  ``KilledWorker``. A local cluster is started with ``local_cluster.LOCAL_ALLOWED_FAILURES``
  (the job is run twice in all); an existing cluster uses its scheduler's
  ``distributed.scheduler.allowed-failures`` (Dask's default 3).

A job that still failed reaches ``run_jobs`` as an exception, and the command records it as
a ``crashed`` row (its ``lost`` function, with Dask's reason); the run goes on. (Each job
runs in a process of its own on its worker, ``executor.isolated_call``: a job that
segfaults, exits or hangs is its own ``crashed`` or ``timed_out`` result, and its worker
lives on.) Dask's own log
lines are silenced in this process and in a local cluster's workers (the reason is in the
row): the run prints its progress and summary, not the cluster's chatter. A finished job's
result lives on its worker until this process fetches it; a worker lost before that makes
Dask run the job again, which is not counted as a failure.
"""

from __future__ import annotations

import contextlib
import logging
import os
import select
import signal
import socket
import struct
import subprocess
import sys
import tempfile
import time
from concurrent.futures import Executor, Future
from typing import IO, Any
from urllib.parse import urlsplit


class BackendError(Exception):
    """The backend cannot be used (Dask missing, a scheduler that does not answer): one line
    for the user, exit 2, before any job has run."""


RETRIES = 1
"""Dask ``retries=``: a job that raised is run once more before it counts as failed."""

CONNECT_TIMEOUT_S = 30
"""How long to wait for the scheduler at ``--scheduler ADDRESS`` to answer, its handshake
included (Dask's ``distributed.comm.timeouts.connect``, 30 s by default)."""

MAX_HANDSHAKE_BYTES = 1 << 20
"""The largest first message a scheduler may announce (a real one's handshake is a few
hundred bytes): Dask allocates whatever a server announces, so a larger one is refused
before Dask reads it."""

HANDSHAKE_HEADER = struct.Struct("<Q")
"""The first 8 bytes a Dask comm sends: the length of its first message (``distributed.comm.tcp``)."""

LOCAL_CLUSTER_COMMAND = [sys.executable, "-m", "validation.jobs.local_cluster"]
"""The local cluster's process, given its number of workers (``local_cluster.serve``)."""

LOCAL_START_TIMEOUT_S = 120
"""s, how long a local cluster may take to print its address. Measured: 1.2 s for 2 workers
on this 2-core machine with both cores busy (load average 2); 120 s is a hung start, not a
slow one."""


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

    def __init__(self, client: Any, cluster: LocalClusterProcess | None = None):
        self._client = client
        self._cluster = cluster
        self._executor = client.get_executor(retries=RETRIES, pure=False)

    def submit(self, fn, /, *args: Any, **kwargs: Any) -> Future:
        return self._executor.submit(fn, *args, **kwargs)

    def shutdown(self, wait: bool = True, *, cancel_futures: bool = False) -> None:
        """Close the client and end the cluster it started; with ``cancel_futures`` (Ctrl-C, a
        failure), the unfinished jobs are cancelled first."""
        try:
            self._executor.shutdown(wait=wait and not cancel_futures)
            self._client.close()
        finally:
            if self._cluster is not None:
                self._cluster.stop()


class LocalClusterProcess:
    """``python -m validation.jobs.local_cluster WORKERS`` in a new session: its address,
    and ``stop``. Its stdin is a pipe from this process: when this process ends, even by
    SIGKILL, the pipe closes and the cluster closes itself."""

    def __init__(self, workers: int):
        self._log: IO[bytes] = tempfile.TemporaryFile()  # noqa: SIM115 (closed by stop)
        self._process = subprocess.Popen(
            [*LOCAL_CLUSTER_COMMAND, str(workers)],
            stdin=subprocess.PIPE,
            stdout=subprocess.PIPE,
            stderr=self._log,
            env={**os.environ, "PYTHONPATH": os.pathsep.join(p for p in sys.path if p)},
            start_new_session=True,
        )

    def address(self) -> str:
        """The scheduler's address once the cluster is up; ``BackendError`` if it ended or
        did not answer within ``LOCAL_START_TIMEOUT_S``."""
        assert self._process.stdout is not None
        ready, _, _ = select.select([self._process.stdout], [], [], LOCAL_START_TIMEOUT_S)
        line = self._process.stdout.readline().decode().strip() if ready else ""
        if not line.startswith("tcp://"):
            self._log.seek(0)
            said = [text for text in self._log.read().decode(errors="replace").splitlines() if text]
            self.stop()
            reason = said[-1] if said else f"no address within {LOCAL_START_TIMEOUT_S} s"
            raise BackendError(
                f"--scheduler local: the local Dask cluster did not start ({reason})"
            )
        return line

    def stop(self) -> None:
        """End the cluster now: SIGKILL to its process group (the scheduler and every
        worker). Called once this process has every result it wants (or none, on Ctrl-C), so
        nothing is lost; a graceful close measured 0.5-1.2 s more per run."""
        with contextlib.suppress(ProcessLookupError):  # anything left: workers included
            os.killpg(self._process.pid, signal.SIGKILL)
        self._process.wait()
        for pipe in (self._process.stdin, self._process.stdout, self._log):
            if pipe is not None:
                pipe.close()


def quiet_dask_logs() -> None:
    """Dask's log lines off in this process: what a lost job says is in its row."""
    for name in ("distributed", "dask"):
        logging.getLogger(name).setLevel(logging.CRITICAL)


def dask_config(settings: dict[str, object]) -> Any:
    import dask

    return dask.config.set(settings)


def check_handshake(scheduler: str) -> None:
    """For a ``tcp://`` address (or ``host:port``), that what answers there begins Dask's
    handshake within ``CONNECT_TIMEOUT_S`` (a scheduler speaks first: the length of its
    handshake message) and announces at most ``MAX_HANDSHAKE_BYTES``; ``TimeoutError`` or
    ``ValueError`` saying which otherwise (an HTTP server says nothing; a hostile one may
    announce a huge message, which Dask would allocate). Other schemes are left to Dask."""
    parts = urlsplit(scheduler if "://" in scheduler else f"tcp://{scheduler}")
    if parts.scheme != "tcp" or parts.hostname is None or parts.port is None:
        return
    deadline = time.monotonic() + CONNECT_TIMEOUT_S
    with socket.create_connection((parts.hostname, parts.port), CONNECT_TIMEOUT_S) as probe:
        header = b""
        while len(header) < HANDSHAKE_HEADER.size:
            probe.settimeout(max(0.01, deadline - time.monotonic()))
            try:
                chunk = probe.recv(HANDSHAKE_HEADER.size - len(header))
            except TimeoutError:
                raise TimeoutError(
                    f"no Dask handshake within {CONNECT_TIMEOUT_S} s: not a Dask scheduler"
                ) from None
            if not chunk:
                raise ValueError("the server closed the connection: not a Dask scheduler")
            header += chunk
    (size,) = HANDSHAKE_HEADER.unpack(header)
    if size > MAX_HANDSHAKE_BYTES:
        raise ValueError(
            f"the server announced a {size}-byte handshake (at most {MAX_HANDSHAKE_BYTES}): "
            "not a Dask scheduler"
        )


def dask_executor(workers: int, scheduler: str) -> DaskExecutor:
    """A ``DaskExecutor`` on the cluster at ``scheduler``, or a new local one of ``workers``
    processes for ``local``. Raises ``BackendError`` when Dask is missing or the scheduler
    does not answer."""
    if distributed_missing():
        raise BackendError(MISSING)
    from distributed import Client

    quiet_dask_logs()
    if scheduler == "local":
        cluster = LocalClusterProcess(workers)
        try:
            return DaskExecutor(Client(cluster.address(), timeout=CONNECT_TIMEOUT_S), cluster)
        except BaseException:  # Ctrl-C while it starts, a client that cannot connect
            cluster.stop()
            raise
    try:
        check_handshake(scheduler)
        with dask_config({"distributed.comm.timeouts.connect": f"{CONNECT_TIMEOUT_S}s"}):
            client = Client(scheduler, timeout=CONNECT_TIMEOUT_S)
    except (OSError, TimeoutError, ValueError) as error:
        raise BackendError(
            f"--scheduler {scheduler}: no Dask scheduler answered ({type(error).__name__}: "
            f"{str(error).splitlines()[0] if str(error) else ''}); start one with "
            "`dask scheduler` and workers with `dask worker ADDRESS`"
        ) from None
    return DaskExecutor(client)
