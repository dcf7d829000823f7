"""No engine can take a run down: every job runs in a worker process of its own pool.

A test engine (tests/fixtures/hostile_engine, a distribution put on PYTHONPATH: mini_engine
whose ``mode`` option makes one adapter call misbehave) segfaults, aborts, calls ``sys.exit``,
hangs in ``advance``, ``close`` or its import, or raises where physval used to print a
traceback. Each becomes its own row (``crashed``, ``timed_out``, ``error``) while the other
jobs keep theirs, the run is published and exits 1; ``--job-timeout`` bounds every job; the
workers end with the run even when it is SIGKILLed; a ``--scheduler`` that does not speak
Dask's protocol is one line.
"""

from __future__ import annotations

import csv
import os
import signal
import socket
import subprocess
import sys
import threading
import time
from pathlib import Path

import pytest

from validation.cli import BUNDLED_SCENARIOS
from validation.contract import BAD_STATUSES, STATUS_DESCRIPTIONS

ROOT = Path(__file__).resolve().parent.parent
HOSTILE = ROOT / "tests" / "fixtures" / "hostile_engine"
SCENE = BUNDLED_SCENARIOS / "formulas" / "projectile.yaml"
"""A short scene every engine of the test runs in well under a second."""

TEST_TIMEOUT_S = 1.5
"""s: ``--job-timeout`` of the tests: a calm job of ``SCENE`` takes well under it."""

COMMAND_LIMIT_S = 120
"""s: a command that takes longer has hung (each takes a few seconds)."""


def _physval(*args: str, cwd: Path) -> subprocess.CompletedProcess:
    return subprocess.run(
        [sys.executable, "-m", "validation.cli", *args],
        capture_output=True,
        text=True,
        cwd=cwd,
        timeout=COMMAND_LIMIT_S,
        env={**os.environ, "PYTHONPATH": os.pathsep.join([str(ROOT), str(HOSTILE)])},
    )


def _run(tmp_path: Path, engines: str, *more: str) -> tuple[subprocess.CompletedProcess, dict]:
    """``physval run SCENE --engines ENGINES``; (the process, engine -> its status row)."""
    out = tmp_path / "out"
    done = _physval(
        "run",
        str(SCENE),
        "--engines",
        engines,
        "--out",
        str(out),
        "--baseline",
        "none",
        "--history",
        "none",
        *more,
        cwd=tmp_path,
    )
    rows = {}
    if (out / "results.csv").is_file():
        with (out / "results.csv").open() as f:
            for row in csv.DictReader(f):
                if row["metric"].startswith("sweep_"):  # the scene's own sweep: not the run
                    continue
                if row["engine"] not in rows or row["status"] != "ok":
                    rows[row["engine"]] = row
    return done, rows


CRASHES = {
    "segfault": "killed by SIGSEGV",
    "abort": "killed by SIGABRT",
    "exit": "sys.exit(3)",
    "exit0": "sys.exit(0)",
    "hard_exit": "exited with code 7",
}
"""Mode -> what its ``crashed`` row's message says (the signal or the exit code)."""


@pytest.mark.parametrize("jobs", ["1", "2"])
def test_an_engine_that_leaves_its_process_is_its_crashed_row_and_the_run_is_published(
    tmp_path, jobs
):
    """Before: ``sys.exit(0)`` in ``advance`` made physval exit 0 with nothing published; a
    segfault ended the run (exit 139 with --jobs 1, a BrokenProcessPool traceback with 2)."""
    engines = ", ".join(["mini", *(f"hostile(mode={mode})" for mode in CRASHES)])
    done, rows = _run(tmp_path, engines, "--jobs", jobs)
    assert done.returncode == 1, (done.returncode, done.stderr[-3000:])
    assert "Traceback" not in done.stderr, done.stderr[-3000:]
    assert rows["mini"]["status"] == "ok", rows["mini"]
    for mode, said in CRASHES.items():
        row = rows[f"hostile(mode={mode})"]
        assert row["status"] == "crashed" and said in row["message"], row


def test_a_hang_in_advance_close_or_the_import_is_timed_out_and_the_others_run(tmp_path):
    """Before: a hung ``advance()`` or ``close()`` hung ``run`` for ever."""
    engines = "mini, hostile(mode=hang), hostile(mode=hang_close), slowimport"
    start = time.monotonic()
    done, rows = _run(tmp_path, engines, "--jobs", "2", "--job-timeout", str(TEST_TIMEOUT_S))
    assert done.returncode == 1, (done.returncode, done.stderr[-3000:])
    assert rows["mini"]["status"] == "ok", rows["mini"]
    for engine in ("hostile(mode=hang)", "hostile(mode=hang_close)", "slowimport"):
        assert rows[engine]["status"] == "timed_out", rows[engine]
        assert f"{TEST_TIMEOUT_S:g} s" in rows[engine]["message"], rows[engine]
    assert time.monotonic() - start < COMMAND_LIMIT_S / 2


ADAPTER_ERRORS = {
    "hostile(mode=raise_init)": "the adapter's constructor: RuntimeError",
    "hostile(mode=raise_close)": "close: RuntimeError: close broke on purpose",
    "hostile(mode=raise_str)": "UnprintableError (its message cannot be shown)",
    "hostile(mode=no_version)": "provenance().version: expected str; got NoneType",
}
"""Engine -> what its ``error`` row says: each was a traceback (provenance version None a
journal TypeError)."""


def test_an_adapter_that_raises_where_physval_did_not_expect_is_an_error_row(tmp_path):
    done, rows = _run(tmp_path, ", ".join(["mini", *ADAPTER_ERRORS]), "--jobs", "1")
    assert done.returncode == 1, (done.returncode, done.stderr[-3000:])
    assert "Traceback" not in done.stderr, done.stderr[-3000:]
    assert rows["mini"]["status"] == "ok"
    for engine, said in ADAPTER_ERRORS.items():
        assert rows[engine]["status"] == "error" and said in rows[engine]["message"], rows[engine]


@pytest.mark.parametrize(
    ("mode", "call"), [("check", "check_settings"), ("caps", "capabilities_for")]
)
def test_a_declaration_call_that_raises_is_one_line_and_exit_2(tmp_path, mode, call):
    """The declaration's own functions, called when the spec is read: a traceback before."""
    done, rows = _run(tmp_path, f"badchecks(mode={mode})")
    assert done.returncode == 2, (done.returncode, done.stderr)
    assert done.stderr.strip().splitlines() == [
        f"--engines: badchecks: the engine's {call} raised RuntimeError: {call} broke on purpose"
    ], done.stderr
    assert not rows


def test_sweep_and_stability_record_a_crash_and_a_hang(tmp_path):
    """The other commands that run jobs: a crash and a hang are their rows too."""
    out = tmp_path / "sweep"
    done = _physval(
        "sweep",
        str(SCENE),
        "--engines",
        "mini, hostile(mode=segfault), hostile(mode=hang)",
        "--dt",
        "1e-2,5e-3",
        "--out",
        str(out),
        "--job-timeout",
        str(TEST_TIMEOUT_S),
        cwd=tmp_path,
    )
    assert "Traceback" not in done.stderr, done.stderr[-3000:]
    with (out / "sweep.csv").open() as f:
        statuses = {(r["engine"], r["status"]) for r in csv.DictReader(f)}
    assert ("hostile(mode=segfault)", "crashed") in statuses, statuses
    assert ("hostile(mode=hang)", "timed_out") in statuses, statuses
    assert ("mini", "ok") in statuses, statuses
    stability = tmp_path / "stability.csv"
    done = _physval(
        "stability",
        str(SCENE),
        "--engines",
        "hostile(mode=abort)",
        "--out",
        str(stability),
        cwd=tmp_path,
    )
    assert "Traceback" not in done.stderr, done.stderr[-3000:]
    assert "crashed" in stability.read_text(), stability.read_text()


def test_conformance_of_a_hanging_engine_fails_the_checks_that_hang(tmp_path):
    """Before: a hung ``advance()`` hung ``conformance`` for ever."""
    only = ["--only", "declaration", "--only", "advance"]
    done = _physval(
        "conformance",
        "hostile(mode=hang)",
        *only,
        "--job-timeout",
        str(TEST_TIMEOUT_S),
        cwd=tmp_path,
    )
    assert done.returncode == 1, (done.returncode, done.stdout, done.stderr)
    assert "pass declaration" in done.stdout and "FAIL advance" in done.stdout, done.stdout
    assert "timed_out" in done.stdout, done.stdout


def _descendants(root: int) -> set[int]:
    parents = {}
    for entry in Path("/proc").iterdir():
        if entry.name.isdigit():
            try:
                parents[int(entry.name)] = int(
                    (entry / "stat").read_text().rsplit(")", 1)[1].split()[1]
                )
            except (OSError, IndexError):
                continue
    found, frontier = set(), {root}
    while frontier:
        frontier = {pid for pid, parent in parents.items() if parent in frontier} - found
        found |= frontier
    return found


def _alive(pids: set[int]) -> set[int]:
    alive = set()
    for pid in pids:
        try:
            state = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()[0]
        except (OSError, IndexError):
            continue
        if state != "Z":
            alive.add(pid)
    return alive


WORKERS_GONE_S = 10
"""s for the workers of a SIGKILLed run to have ended (the kernel signals them at once)."""


def test_the_workers_of_a_sigkilled_run_end_with_it(tmp_path):
    """Before: after SIGKILL of ``run --jobs 2`` the workers and the fork server lived on."""
    run = subprocess.Popen(
        [
            sys.executable,
            "-m",
            "validation.cli",
            "run",
            str(SCENE),
            "--engines",
            "hostile(mode=hang), hostile(mode=hang_close)",
            "--jobs",
            "2",
            "--job-timeout",
            "0",
            "--out",
            str(tmp_path / "out"),
        ],
        cwd=tmp_path,
        stdout=subprocess.DEVNULL,
        stderr=subprocess.DEVNULL,
        env={**os.environ, "PYTHONPATH": os.pathsep.join([str(ROOT), str(HOSTILE)])},
    )
    try:
        deadline = time.monotonic() + COMMAND_LIMIT_S
        while len(_descendants(run.pid)) < 2 and time.monotonic() < deadline:
            time.sleep(0.1)
        workers = _descendants(run.pid)
        assert len(workers) >= 2, workers
        time.sleep(1.0)  # the workers are in their jobs
        run.send_signal(signal.SIGKILL)
        run.wait()
        deadline = time.monotonic() + WORKERS_GONE_S
        while _alive(workers) and time.monotonic() < deadline:
            time.sleep(0.1)
        assert not _alive(workers), _alive(workers)
    finally:
        if run.poll() is None:
            run.kill()


def test_the_new_statuses_fail_a_run_and_are_described():
    from validation.nightly.cases import ERROR, OUTCOME_KINDS

    for status in ("crashed", "timed_out"):
        assert status in BAD_STATUSES and status in STATUS_DESCRIPTIONS
        assert OUTCOME_KINDS[status] == ERROR  # a JUnit error, a pytest item's error


def test_job_timeout_is_checked_and_its_default_documented(tmp_path):
    done = _physval("run", str(SCENE), "--job-timeout", "-1", cwd=tmp_path)
    assert done.returncode == 2 and "--job-timeout" in done.stderr, done.stderr
    shown = _physval("run", "--help", cwd=tmp_path).stdout
    assert "--job-timeout" in shown and "expected time" in shown, shown


def _serve_once(reply: bytes) -> tuple[str, threading.Thread]:
    """A TCP server on a free port that accepts one connection and sends ``reply`` (then
    waits, as an HTTP server waits for its request)."""
    server = socket.socket()
    server.bind(("127.0.0.1", 0))
    server.listen(1)

    def serve() -> None:
        with server:
            connection, _ = server.accept()
            with connection:
                connection.sendall(reply)
                time.sleep(3)

    thread = threading.Thread(target=serve, daemon=True)
    thread.start()
    return f"tcp://127.0.0.1:{server.getsockname()[1]}", thread


def test_a_scheduler_address_that_does_not_speak_dask_is_refused_without_allocating(
    monkeypatch,
):
    """A server that says nothing (HTTP waits for a request) is refused once Dask's
    connect timeout passes; one announcing a huge message is refused before Dask allocates
    it. Before: past 120 s, and an allocation of the announced size."""
    pytest.importorskip("distributed")
    from validation.jobs import dask_backend

    monkeypatch.setattr(dask_backend, "CONNECT_TIMEOUT_S", 1)
    silent, _ = _serve_once(b"")
    start = time.monotonic()
    with pytest.raises(dask_backend.BackendError, match="no Dask handshake within 1 s"):
        dask_backend.dask_executor(1, silent)
    assert time.monotonic() - start < 10
    huge, _ = _serve_once(dask_backend.HANDSHAKE_HEADER.pack(1 << 40))
    with pytest.raises(dask_backend.BackendError, match="1099511627776-byte handshake"):
        dask_backend.dask_executor(1, huge)


def test_pytest_physval_fails_the_items_whose_engine_crashed_or_hung_and_goes_on(tmp_path):
    """Before: a hung ``advance()`` hung ``pytest --physval`` for ever, a segfault ended it."""
    scene = SCENE.read_text().replace(
        'engines: [mini, mujoco, "mujoco(integrator=RK4)", pybullet, rapier, drake]',
        'engines: [mini, "hostile(mode=segfault)", "hostile(mode=hang)", "mujoco(integrator=RK4)"]',
    )
    assert "hostile(mode=hang)" in scene
    (tmp_path / "scenes").mkdir()
    (tmp_path / "scenes" / "projectile.yaml").write_text(scene)
    done = subprocess.run(
        [
            sys.executable,
            "-m",
            "pytest",
            "-p",
            "no:cacheprovider",
            "-rA",
            "--physval",
            "scenes",
            "-k",
            "mini or hostile",  # RK4 is there for the scene's checks that name it
            "--job-timeout",
            str(TEST_TIMEOUT_S),
        ],
        cwd=tmp_path,
        capture_output=True,
        text=True,
        timeout=COMMAND_LIMIT_S,
        env={
            **{k: v for k, v in os.environ.items() if not k.startswith("PYTEST_")},
            "PYTHONPATH": os.pathsep.join([str(ROOT), str(HOSTILE)]),
        },
    )
    shown = done.stdout + done.stderr
    assert done.returncode == 1, shown[-3000:]
    assert "PASSED scenes/projectile.yaml::mini" in shown, shown[-3000:]
    assert "FAILED scenes/projectile.yaml::hostile(mode=segfault)" in shown, shown[-3000:]
    assert "FAILED scenes/projectile.yaml::hostile(mode=hang)" in shown, shown[-3000:]
    assert "[crashed]" in shown and "[timed_out]" in shown, shown[-3000:]


def _misbehaves(x: int) -> int:
    """Job 1 hangs, job 2 segfaults, the others return their square."""
    if x == 1:
        time.sleep(3600)
    if x == 2:
        import ctypes

        ctypes.string_at(0)
    return x * x


def test_on_a_dask_cluster_a_hang_and_a_segfault_are_the_same_statuses():
    """``--scheduler local``: each job runs in a process of its own on its Dask worker, with
    the same time limit and the same statuses as locally."""
    pytest.importorskip("distributed")
    from validation.jobs.executor import run_jobs

    results = run_jobs(
        _misbehaves,
        [0, 1, 2, 3],
        2,
        scheduler="local",
        lost=lambda job, status, message: (status, message),
        job_timeout=TEST_TIMEOUT_S,
    )
    assert results[0] == 0 and results[3] == 9, results
    assert results[1][0] == "timed_out", results[1]
    assert results[2][0] == "crashed" and "SIGSEGV" in results[2][1], results[2]
