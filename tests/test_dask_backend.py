"""The Dask backend (``--scheduler``): the same files as the local executor; a worker killed
mid-run costs a retry or an error row, never the run; without Dask, one line and exit 2."""

from __future__ import annotations

import os
import shutil
import signal
import socket
import subprocess
import sys
import time
from concurrent.futures import Executor, Future
from pathlib import Path

import pandas as pd
import pytest

from validation.cli import BUNDLED_SCENARIOS, main
from validation.jobs.dask_backend import MISSING
from validation.jobs.executor import BACKENDS, run_jobs
from validation.jobs.journal import Journal
from validation.jobs.plan import plan_run
from validation.jobs.run import JOURNAL_SCHEMA, execute, job_ids
from validation.jobs.terminal import message_lines

distributed = pytest.importorskip("distributed")

FOUR_SCENES = [
    BUNDLED_SCENARIOS / "formulas" / "projectile.yaml",
    BUNDLED_SCENARIOS / "formulas" / "head_on_ratio_1.yaml",
    BUNDLED_SCENARIOS / "rotation" / "torque_free_symmetric_top.yaml",
    BUNDLED_SCENARIOS / "contact" / "box_drop_flat.yaml",
]
"""Free flight (with its declared sweep), a head-on pair, a spinning top, a box on a floor."""

TIMING_COLUMNS = ("wall_time_s", "steps_per_second", "real_time_factor")
"""Columns that measure the machine, not the physics: the only ones allowed to differ."""

NO_NIGHTLY = ["--baseline", "none", "--history", "none"]


def _same_files(one: Path, two: Path, names: tuple[str, ...]) -> None:
    for name in names:
        a = pd.read_csv(one / name).drop(columns=list(TIMING_COLUMNS), errors="ignore")
        b = pd.read_csv(two / name).drop(columns=list(TIMING_COLUMNS), errors="ignore")
        assert len(a) > 0, f"{name} is empty"
        pd.testing.assert_frame_equal(a, b, check_exact=True, obj=name)


def test_local_cluster_gives_the_files_of_the_local_executor(tmp_path):
    """``physval run`` and ``physval sweep`` on a LocalCluster: every number and every row
    order equal to ``--jobs 1`` (timings aside)."""
    scenes = list(map(str, FOUR_SCENES))
    run = ["run", *scenes, "--engines", "mini, mujoco", "--dt", "2e-3", "--sweeps", "on"]
    run += NO_NIGHTLY
    serial = main([*run, "--out", str(tmp_path / "serial"), "--jobs", "1"])
    dask = main([*run, "--out", str(tmp_path / "dask"), "--jobs", "2", "--scheduler", "local"])
    assert serial == dask  # the coarse --dt fails checks in both: exit 1, the same rows
    _same_files(
        tmp_path / "serial",
        tmp_path / "dask",
        ("results.csv", "series.csv", "impacts.csv", "sweep.csv"),
    )
    sweep = ["sweep", *scenes[:2], "--engines", "mini, mujoco", "--dt", "4e-3,2e-3"]
    assert main([*sweep, "--out", str(tmp_path / "sweep-serial"), "--jobs", "1"]) == 0
    assert (
        main([*sweep, "--out", str(tmp_path / "sweep-dask"), "--jobs", "2", "--scheduler", "local"])
        == 0
    )
    _same_files(tmp_path / "sweep-serial", tmp_path / "sweep-dask", ("sweep.csv",))


def _dies_on_three(x: int) -> int:
    """A job whose worker dies whenever it runs job 3 (an out-of-memory kill, say); each job
    takes a moment, as a real one does (the workers have reported the earlier jobs' results
    before a death)."""
    time.sleep(0.5)
    if x == 3:
        os._exit(1)
    return x * x


def test_a_job_that_ends_its_process_becomes_its_lost_result():
    """The job ends its process (on its Dask worker, a process of its own: the worker lives
    on): the job gets the command's ``lost`` result (a ``crashed`` row naming the exit code)
    and every other job its own."""
    finished: list[int] = []
    results = run_jobs(
        _dies_on_three,
        list(range(6)),
        2,
        lambda index, _: finished.append(index),
        scheduler="local",
        lost=lambda job, status, message: ("lost", job, status, message),
    )
    assert results[:3] == [0, 1, 4] and results[4:] == [16, 25]
    kind, job, status, message = results[3]
    assert (kind, job, status) == ("lost", 3, "crashed")
    assert "exited with code 1" in message, message
    assert sorted(finished) == list(range(6))


def _free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def _dask(*args: str, log: Path) -> subprocess.Popen:
    found = shutil.which("dask", path=str(Path(sys.executable).parent))
    command = [found] if found else [sys.executable, "-m", "dask"]
    return subprocess.Popen(
        [*command, *args], stdout=log.open("w"), stderr=subprocess.STDOUT, start_new_session=True
    )


def _wait_for(condition, timeout: float, what: str, step: float = 0.2):
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        found = condition()
        if found:
            return found
        time.sleep(step)
    raise AssertionError(f"timed out after {timeout} s waiting for {what}")


ALLOWED_FAILURES = {"retried": "3", "error_row": "0"}
"""The scheduler's ``allowed-failures``: Dask's default 3 (a job whose worker died is given
to another worker), or 0 (it fails at once: the run's error row)."""


@pytest.fixture(params=sorted(ALLOWED_FAILURES))
def cluster(tmp_path, request, monkeypatch):
    """A ``dask scheduler`` and two ``dask worker`` processes (no nanny: a killed worker
    stays dead) on localhost; yields (what a lost job becomes, address, {worker name:
    process})."""
    monkeypatch.setenv(
        "DASK_DISTRIBUTED__SCHEDULER__ALLOWED_FAILURES", ALLOWED_FAILURES[request.param]
    )
    monkeypatch.setenv("DASK_DISTRIBUTED__SCHEDULER__WORKER_SATURATION", "1.0")
    address = f"tcp://127.0.0.1:{_free_port()}"
    port = address.rsplit(":", 1)[1]
    processes = [
        _dask(
            "scheduler",
            "--host",
            "127.0.0.1",
            "--port",
            port,
            "--no-dashboard",
            log=tmp_path / "scheduler.log",
        )
    ]
    workers = {}
    try:
        for k in range(2):
            worker = _dask(
                "worker",
                address,
                "--nthreads",
                "1",
                "--no-nanny",
                "--no-dashboard",
                "--name",
                f"w{k}",
                log=tmp_path / f"worker{k}.log",
            )
            processes.append(worker)
            workers[f"w{k}"] = worker
        with distributed.Client(address, timeout=120) as client:
            client.wait_for_workers(2, timeout=120)
        yield request.param, address, workers
    finally:
        for process in processes:
            if process.poll() is None:
                process.kill()
            process.wait(timeout=60)


def test_a_worker_killed_mid_run_costs_a_retry_not_the_run(tmp_path, cluster):
    """``physval run --scheduler ADDRESS``; a worker is SIGKILLed while it runs a job: the run
    completes, every scene has its rows, nothing prints a traceback, and the lost job was
    run again on the other worker (no error row) or, when the scheduler allows no failure,
    is an error row saying so."""
    becomes, address, workers = cluster
    out = tmp_path / "run"
    command = [sys.executable, "-m", "validation.cli", "run", *map(str, FOUR_SCENES)]
    command += ["--engines", "mini", "--dt", "5e-4", "--out", str(out), *NO_NIGHTLY]
    run = subprocess.Popen(
        [*command, "--scheduler", address],
        stdout=subprocess.PIPE,
        stderr=subprocess.STDOUT,
        text=True,
    )
    try:
        with distributed.Client(address, timeout=120) as client:

            def busy_worker():
                processing = client.processing()
                info = client.scheduler_info(n_workers=-1)["workers"]
                for worker, keys in processing.items():
                    if keys and info.get(worker, {}).get("name") in workers:
                        return info[worker]["name"]
                return None

            victim = _wait_for(busy_worker, 300, "a worker running a job", step=0.05)
            os.kill(workers[victim].pid, signal.SIGKILL)
        output, _ = run.communicate(timeout=600)
    finally:
        if run.poll() is None:
            run.kill()
    assert workers[victim].wait(timeout=60) == -signal.SIGKILL
    assert run.returncode in (0, 1), output
    assert "Traceback" not in output, output
    rows = pd.read_csv(out / "results.csv")
    assert set(rows.scenario) == {Path(p).stem for p in FOUR_SCENES}, sorted(set(rows.scenario))
    lost = rows[rows.status == "crashed"]
    if becomes == "retried":
        assert lost.empty, lost[["scenario", "engine", "message"]]
    else:
        jobs = lost.groupby(["scenario", "engine"]).size()
        assert 1 <= len(jobs) <= 2, lost[["scenario", "engine", "metric", "message"]]
        assert all(m == "status" or m.startswith("sweep_") for m in lost.metric), lost.metric
        assert all(
            "failed on the Dask cluster after its retries (KilledWorker" in m for m in lost.message
        ), lost.message


@pytest.mark.parametrize("command", ["run", "sweep", "stability"])
def test_without_dask_scheduler_is_one_line_and_exit_2(tmp_path, monkeypatch, capsys, command):
    """``distributed`` not importable (as when the extra is not installed): ``--scheduler``
    prints one line naming the extra and exits 2 before any job; nothing is written."""
    monkeypatch.setitem(sys.modules, "distributed", None)  # import distributed -> ImportError
    out = tmp_path / "out"
    scene = str(FOUR_SCENES[1])
    code = main([command, scene, "--engines", "mini", "--out", str(out), "--scheduler", "local"])
    captured = capsys.readouterr()
    assert code == 2
    assert captured.err.strip() == MISSING
    assert '".[distributed]"' in captured.err
    assert captured.out == ""
    assert not out.exists()


def _processes() -> dict[int, tuple[int, str]]:
    """Every process of the machine: pid -> (parent pid, state letter; Z for a zombie)."""
    found = {}
    for entry in Path("/proc").iterdir():
        if entry.name.isdigit():
            try:
                fields = (entry / "stat").read_text().rsplit(")", 1)[1].split()
            except (OSError, IndexError):
                continue  # ended while being read
            found[int(entry.name)] = (int(fields[1]), fields[0])
    return found


def _descendants(root: int) -> set[int]:
    """The pids of every process started by ``root``, its children's children included."""
    processes = _processes()
    found, frontier = set(), {root}
    while frontier:
        frontier = {pid for pid, (parent, _) in processes.items() if parent in frontier} - found
        found |= frontier
    return found


def _alive(pids: set[int]) -> set[int]:
    """Those of ``pids`` still running (a zombie has ended: init reaps it soon)."""
    processes = _processes()
    return {pid for pid in pids if pid in processes and processes[pid][1] != "Z"}


CLUSTER_GONE_S = 30
"""s, for every process the run started to have ended after the run exited: the run ends
them before it exits; this only bounds how long the machine takes to notice."""

INTERRUPT_MOMENTS = {
    "starting": lambda run, out: _descendants(run.pid),
    "running": lambda run, out: list(out.parent.glob(".run-staging-*/journal/job-*.zip")),
}
"""When Ctrl-C comes: as soon as the run has started a process of the cluster (its
scheduler and workers are starting), or once it has committed a finished job to its
journal."""


@pytest.mark.parametrize("moment", sorted(INTERRUPT_MOMENTS))
def test_ctrl_c_with_a_local_cluster_is_one_line_and_leaves_no_dask_process(tmp_path, moment):
    """Ctrl-C (SIGINT to the run's whole process group, as a terminal sends it) while the
    local cluster starts or while it runs jobs: exit 130, the one interrupted line and no
    traceback, and no process of the cluster left. Before the cluster had a session of its
    own, the workers got the signal too and printed Dask's "Nanny failed to start" or an
    event loop's KeyboardInterrupt traceback."""
    out = tmp_path / "run"
    command = [sys.executable, "-m", "validation.cli", "run", *map(str, FOUR_SCENES)]
    command += ["--engines", "mini", "--dt", "5e-4", "--out", str(out), *NO_NIGHTLY]
    run = subprocess.Popen(
        [*command, "--scheduler", "local", "--jobs", "2"],
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
        start_new_session=True,  # its own process group, as a terminal's foreground job
    )
    try:
        _wait_for(lambda: INTERRUPT_MOMENTS[moment](run, out), 300, moment, step=0.02)
        started = _descendants(run.pid)
        os.killpg(run.pid, signal.SIGINT)
        _, stderr = run.communicate(timeout=120)
    finally:
        if run.poll() is None:
            run.kill()
    lines = message_lines(stderr)
    assert run.returncode == 130, (run.returncode, stderr[-3000:])
    assert "Traceback" not in stderr, stderr[-3000:]
    assert len(lines) == 1 and lines[0].startswith("interrupted"), lines
    _wait_for(lambda: not _alive(started), CLUSTER_GONE_S, "the cluster's processes to end")
    assert not out.exists()


class _LosesTheFirstJob(Executor):
    """A cluster that loses the first job submitted (``KilledWorker`` after its retries, as
    Dask reports it) and runs the others in this process."""

    def __init__(self):
        self.submitted = 0

    def submit(self, fn, /, *args, **kwargs) -> Future:
        future: Future = Future()
        self.submitted += 1
        if self.submitted == 1:
            future.set_exception(RuntimeError("KilledWorker: the worker died twice"))
        else:
            future.set_result(fn(*args, **kwargs))
        return future


def test_a_job_the_cluster_lost_is_an_error_row_and_runs_again_on_resume(tmp_path, monkeypatch):
    """A lost job gets its ``error`` row in the run, but is not committed to the journal:
    the cluster failed, not the job, so ``--resume`` (of a run killed later) runs it again
    and gets its real rows."""
    plan = plan_run([FOUR_SCENES[1]], "mini, mujoco", None, None)
    monkeypatch.setitem(BACKENDS, "dask", lambda workers, scheduler: _LosesTheFirstJob())
    journal = Journal.create(tmp_path / "journal", {"run": "test"}, JOURNAL_SCHEMA)
    first = execute(plan, 2, journal, scheduler="tcp://lossy:8786")
    lost = [run for run in first.runs if run.status == "crashed"]
    assert [run.engine for run in lost] == ["mini"], [(r.engine, r.status) for r in first.runs]
    assert "KilledWorker" in lost[0].message, lost[0].message
    committed = journal.finished(job_ids(plan))
    assert 0 not in committed and len(committed) == len(plan.jobs) + len(plan.sweeps) - 1, sorted(
        committed
    )
    resumed = execute(plan, 1, journal, committed)
    assert [run.status for run in resumed.runs] == ["ok", "ok"], [r.message for r in resumed.runs]
    assert sorted(journal.finished(job_ids(plan))) == sorted([0, *committed])


def test_a_local_cluster_that_cannot_start_is_one_line_and_exit_2(tmp_path, monkeypatch, capsys):
    """The local cluster's process ends before it gives an address (a broken Dask install,
    say): one line with its last words, exit 2, nothing written."""
    from validation.jobs import dask_backend

    broken = [sys.executable, "-c", "import sys; sys.exit('distributed is broken here')"]
    monkeypatch.setattr(dask_backend, "LOCAL_CLUSTER_COMMAND", broken)
    out = tmp_path / "out"
    run = ["run", str(FOUR_SCENES[1]), "--engines", "mini", "--out", str(out), *NO_NIGHTLY]
    code = main([*run, "--scheduler", "local", "--jobs", "2"])
    err = capsys.readouterr().err.strip().splitlines()
    assert code == 2, (code, err)
    assert err == [
        "--scheduler local: the local Dask cluster did not start (distributed is broken here)"
    ], err
    assert not out.exists()
