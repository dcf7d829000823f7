"""Jobs in parallel: the same files as a serial run, in the same order; Ctrl-C stops cleanly."""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import time

import pandas as pd
import pytest

from validation.cli import BUNDLED_SCENARIOS, main
from validation.jobs.executor import Interrupted, run_jobs
from validation.jobs.terminal import message_lines

FOUR_SCENES = [
    BUNDLED_SCENARIOS / "formulas" / "oblique_impact_spin.yaml",
    BUNDLED_SCENARIOS / "formulas" / "head_on_ratio_1.yaml",
    BUNDLED_SCENARIOS / "contact" / "box_drop_edge.yaml",
    BUNDLED_SCENARIOS / "formulas" / "projectile.yaml",
]
"""Four quick library scenes: impacts with spin, a head-on pair, a box edge, free flight."""

TIMING_COLUMNS = ("wall_time_s",)
"""Columns that measure the machine, not the physics: the only ones allowed to differ."""


def _run(folder, jobs: int) -> int:
    return main(
        [
            "run",
            *map(str, FOUR_SCENES),
            "--engines",
            "mini, mujoco, pybullet",
            "--out",
            str(folder),
            "--jobs",
            str(jobs),
        ]
    )


def test_two_jobs_give_the_files_of_one_job(tmp_path):
    serial, parallel = tmp_path / "serial", tmp_path / "parallel"
    assert _run(serial, 1) == _run(parallel, 2)
    for name in ("results.csv", "impacts.csv", "series.csv"):
        one = pd.read_csv(serial / name).drop(columns=list(TIMING_COLUMNS), errors="ignore")
        two = pd.read_csv(parallel / name).drop(columns=list(TIMING_COLUMNS), errors="ignore")
        assert len(one) > 0, f"{name} is empty"
        pd.testing.assert_frame_equal(one, two, check_exact=True, obj=name)


def _square(x: int) -> int:
    return x * x


def test_results_come_back_in_job_order_whatever_finishes_first():
    finished: list[int] = []
    results = run_jobs(_square, list(range(12)), 2, lambda index, _: finished.append(index))
    assert results == [x * x for x in range(12)]
    assert sorted(finished) == list(range(12))


def _interrupt(_: int) -> None:
    raise KeyboardInterrupt


def test_ctrl_c_in_serial_mode_raises_interrupted():
    with pytest.raises(Interrupted):
        run_jobs(_interrupt, [1, 2], 1)


PREVIOUS_REPORT = "scenario,engine,metric\nprevious,run,kept\n"
PREVIOUS_PROVENANCE = '{"command": "physval run", "git_commit": "c0ffee", "created": "2025"}'
"""A previous run's record at ``--out``: an interrupted run must leave it as it was."""

INTERRUPT_AFTER_S = 8.0
"""s: planning the library takes about a second; by then the workers are running jobs."""


def test_ctrl_c_stops_the_run_with_one_line_and_exit_130(tmp_path):
    """Ctrl-C (SIGINT to the whole process group: the run, its fork server and its workers)
    on a parallel run: exit 130, one line, no traceback, the previous report untouched, the
    finished jobs kept in the run's journal."""
    out = tmp_path / "out"
    out.mkdir()
    (out / "results.csv").write_text(PREVIOUS_REPORT)
    (out / "provenance.json").write_text(PREVIOUS_PROVENANCE)  # a run folder: replaceable
    command = [sys.executable, "-m", "validation.cli", "run", str(BUNDLED_SCENARIOS)]
    process = subprocess.Popen(
        [*command, "--jobs", "2", "--out", str(out)],
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
        cwd=tmp_path,
        start_new_session=True,  # its own process group, as a terminal's foreground job
    )
    time.sleep(INTERRUPT_AFTER_S)
    os.killpg(process.pid, signal.SIGINT)  # what Ctrl-C does: every process of the group
    try:
        _, stderr = process.communicate(timeout=60)
    except subprocess.TimeoutExpired:
        process.kill()
        raise
    lines = message_lines(stderr)
    assert process.returncode == 130, (process.returncode, stderr[-2000:])
    assert "Traceback" not in stderr, stderr[-2000:]
    assert len(lines) == 1 and "interrupted" in lines[0], lines
    assert (out / "results.csv").read_text() == PREVIOUS_REPORT
    assert sorted(p.name for p in out.iterdir()) == ["provenance.json", "results.csv"]
    leftovers = sorted(p.name for p in tmp_path.iterdir() if p.name != "out")
    # the lock file, and the run's staging folder with its journal for ``--resume``
    assert leftovers[1] == ".out.lock" and len(leftovers) == 2, leftovers
    assert (tmp_path / leftovers[0] / "journal" / "header.json").is_file(), leftovers


class _InterruptedImport:
    """A meta-path finder whose import of ``validation.cli`` is interrupted: what a Ctrl-C
    in the second Python spends importing NumPy, MuJoCo and the harness does."""

    def find_spec(self, name, path=None, target=None):
        if name == "validation.cli":
            raise KeyboardInterrupt
        return None


def test_ctrl_c_while_the_command_is_still_importing_is_the_same_one_line(monkeypatch, capsys):
    """The ``physval`` entry point (``validation.entry``) imports the harness inside the
    Ctrl-C handling: one line and exit 130 however early the Ctrl-C comes, no traceback."""
    from validation.contract import EXIT_INTERRUPTED, INTERRUPTED_MESSAGE
    from validation.entry import main as entry

    monkeypatch.delitem(sys.modules, "validation.cli")
    monkeypatch.setattr(sys, "meta_path", [_InterruptedImport(), *sys.meta_path])
    assert entry() == EXIT_INTERRUPTED
    assert capsys.readouterr().err == INTERRUPTED_MESSAGE + "\n"


def test_the_longest_jobs_are_handed_out_first_and_results_keep_job_order():
    """With a cost, a pool is given the most expensive jobs first (a long job started last
    runs alone while the other worker waits); every result still lands at its job's index.
    One worker keeps job order: it gains nothing from another."""
    from validation.jobs.executor import submission_order

    cost = {0: 1.0, 1: 5.0, 2: 2.0, 3: 5.0, 4: 0.5}.__getitem__
    assert submission_order(list(range(5)), cost) == [1, 3, 2, 0, 4]  # ties in job order
    assert submission_order(list(range(5)), None) == [0, 1, 2, 3, 4]
    finished: list[int] = []
    results = run_jobs(_square, list(range(5)), 2, lambda i, _: finished.append(i), cost=cost)
    assert results == [x * x for x in range(5)]
    assert sorted(finished) == list(range(5))


def test_a_pool_receives_the_jobs_longest_first(monkeypatch):
    """What the pool is handed, in order: ``run_jobs`` with a cost submits by it."""
    from validation.jobs import executor

    handed: list[list[int]] = []

    class Recording(executor.IsolatedPool):
        def results(self, fn, jobs, order, limit):
            handed.append([jobs[index] for index in order])
            return super().results(fn, jobs, order, limit)

    monkeypatch.setitem(
        executor.BACKENDS, "processes", lambda workers, scheduler: Recording(workers)
    )
    results = run_jobs(_square, [3, 9, 1, 7], 2, cost=float)
    assert handed == [[9, 7, 3, 1]]
    assert results == [9, 81, 1, 49]
