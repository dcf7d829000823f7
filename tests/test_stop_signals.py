"""Every signal a CI runner or a terminal sends is a clean stop, as Ctrl-C is.

SIGTERM (a cancelled or timed-out CI job, ``timeout``, systemd) and SIGHUP (a closed terminal)
gave exit 143 / 129 with no message and left a ``--jobs 2`` run's workers running for over a
minute. Now each stops every worker, keeps the finished jobs in the run's journal, prints one
line and exits 128 + the signal's number, whether the signal reaches the run's main process
alone or its whole process group.
"""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

from validation.cli import BUNDLED_SCENARIOS
from validation.jobs.terminal import message_lines

SCENES = [
    BUNDLED_SCENARIOS / "formulas" / "projectile.yaml",
    BUNDLED_SCENARIOS / "rotation" / "torque_free_symmetric_top.yaml",
    BUNDLED_SCENARIOS / "contact" / "box_drop_flat.yaml",
    BUNDLED_SCENARIOS / "rotation" / "dzhanibekov_box.yaml",
]
"""Enough jobs that the run is still busy when its first job has been journaled."""

STARTED_S = 300
"""s to wait for the first journaled job (a few seconds on an idle machine)."""

WORKERS_GONE_S = 10
"""s for every process the run started to have ended once it exited: the run ends them
before it exits (a terminated worker ends at once); this only bounds how long the machine
takes to notice. Before, the workers ran on for over a minute."""


def _processes() -> dict[int, tuple[int, str]]:
    """pid -> (parent pid, state letter; Z for a zombie) of every process of the machine."""
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
    processes = _processes()
    found, frontier = set(), {root}
    while frontier:
        frontier = {pid for pid, (parent, _) in processes.items() if parent in frontier} - found
        found |= frontier
    return found


def _alive(pids: set[int]) -> set[int]:
    processes = _processes()
    return {pid for pid in pids if pid in processes and processes[pid][1] != "Z"}


def _wait_for(condition, timeout: float, what: str):
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        found = condition()
        if found:
            return found
        time.sleep(0.05)
    raise AssertionError(f"timed out after {timeout} s waiting for {what}")


@pytest.mark.parametrize("target", ["process", "group"])
@pytest.mark.parametrize("signum", [signal.SIGTERM, signal.SIGHUP], ids=["SIGTERM", "SIGHUP"])
def test_a_stop_signal_stops_every_worker_with_one_line(tmp_path, signum, target):
    out = tmp_path / "run"
    command = [sys.executable, "-m", "validation.cli", "run", *map(str, SCENES)]
    command += ["--engines", "mini", "--out", str(out), "--jobs", "2"]
    command += ["--baseline", "none", "--history", "none"]
    run = subprocess.Popen(
        command,
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
        cwd=tmp_path,
        start_new_session=True,  # its own process group, as a CI runner's job
    )
    try:
        journaled = _wait_for(
            lambda: list(tmp_path.glob(".run-staging-*/journal/job-*")), STARTED_S, "a job"
        )
        started = _descendants(run.pid)
        if target == "group":
            os.killpg(run.pid, signum)
        else:
            os.kill(run.pid, signum)
        _, stderr = run.communicate(timeout=120)
    finally:
        if run.poll() is None:
            run.kill()
    lines = message_lines(stderr)
    name = signal.Signals(signum).name
    assert run.returncode == 128 + signum, (run.returncode, stderr[-3000:])
    assert "Traceback" not in stderr, stderr[-3000:]
    assert len(lines) == 1 and lines[0].startswith(f"stopped by {name}"), lines
    assert "--resume" in lines[0], lines
    _wait_for(lambda: not _alive(started), WORKERS_GONE_S, "the run's workers to end")
    assert not out.exists(), "nothing is published by a stopped run"
    assert all(path.exists() for path in journaled), "the finished jobs stay in the journal"


IMPORT_RECORDER = """
import subprocess, sys
started = []
class Recording(subprocess.Popen):
    def __init__(self, args, *rest, **kwargs):
        started.append(args)
        super().__init__(args, *rest, **kwargs)
subprocess.Popen = Recording
import validation.engines.mujoco.adapter
import validation.engines.pybullet.adapter
print(len(started))
"""
"""Counts the processes importing the engine adapters starts."""


def test_importing_the_engines_starts_no_other_process(tmp_path):
    """Every process of a run's group gets a Ctrl-C: one the engines' imports start on the
    side (GLFW, loaded by ``import mujoco``, ran a second Python to read its version) printed
    a BrokenPipeError traceback after the run's one line when the signal came at that moment."""
    environment = {key: value for key, value in os.environ.items() if key != "MUJOCO_GL"}
    found = subprocess.run(
        [sys.executable, "-c", IMPORT_RECORDER],
        capture_output=True,
        text=True,
        cwd=tmp_path,
        env=environment,
        check=True,
    )
    assert found.stdout.strip() == "0", (found.stdout, found.stderr[-2000:])
