"""``physval run`` under kills and concurrency: the journal, ``--resume``, the output lock,
publishing and the checks of ``--out``. Real processes, killed
with SIGKILL, on small scenes."""

from __future__ import annotations

import os
import shutil
import signal
import stat
import subprocess
import sys
import time
from pathlib import Path

import pandas as pd
import pytest

from validation.cli import BUNDLED_SCENARIOS
from validation.jobs.output import history_name
from validation.jobs.terminal import message_lines

PROJECTILE = BUNDLED_SCENARIOS / "formulas" / "projectile.yaml"

SLOW_SCENE = """\
description: A free fall long enough (10,000 steps a job) for a kill to land between jobs.
dt: 1.0e-4
duration: 1.0
engines: [mini, "mini(gyroscopic=explicit)", "mini(gyroscopic=implicit)", mujoco]
bodies: [{name: ball, shape: {type: sphere, radius: 0.1}, mass: 1.0, velocity: [1, 0, 3]}]
checks: {position_error: 1.0e-3}
"""

WALL_TIME_COLUMNS = ["wall_time_s"]
"""results.csv columns that differ between two runs by nature (a job's own clock)."""

RELEASE_FILE = "release"
HELD = f"""
import pathlib, time
import validation.jobs.run as run
job = run.JOB_KINDS["run"]
def held(payload):
    deadline = time.monotonic() + 60
    while not pathlib.Path({RELEASE_FILE!r}).exists() and time.monotonic() < deadline:
        time.sleep(0.01)
    return job(payload)
run.JOB_KINDS["run"] = held
"""
"""Injected into the first of two concurrent runs: its jobs wait for the release file, so the
second run meets the lock however fast the engines are."""

RUN_TIMEOUT_S = 120
"""Loose bound for one small run in a subprocess on a shared 2-core machine."""


def physval(*arguments: str, cwd: Path, code: str = "", **options) -> subprocess.Popen:
    """``physval ARGUMENTS`` in a new process group (``code`` runs first, to inject faults)."""
    script = f"import sys\n{code}\nfrom validation.cli import main\nsys.exit(main(sys.argv[1:]))"
    return subprocess.Popen(
        [sys.executable, "-c", script, *arguments],
        cwd=cwd,
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
        start_new_session=True,
        **options,
    )


def finish(process: subprocess.Popen) -> tuple[int, str, str]:
    out, err = process.communicate(timeout=RUN_TIMEOUT_S)
    return process.returncode, out, err


def run(*arguments: str, cwd: Path, code: str = "") -> tuple[int, str, str]:
    return finish(physval(*arguments, cwd=cwd, code=code))


def planned_jobs(*paths: Path) -> int:
    """The run's jobs: every (scene, engine) run and every job of the scenes' own sweeps."""
    from validation.jobs.plan import plan_run
    from validation.jobs.sweep import with_cross_checks

    plan = plan_run(list(paths), None, None, None)
    return len(plan.jobs) + len(with_cross_checks(plan.sweeps))


def leftovers(folder: Path) -> list[str]:
    return sorted(p.name for p in folder.iterdir() if "staging" in p.name or ".old-" in p.name)


def test_sigkill_mid_run_then_resume_gives_the_files_of_an_uninterrupted_run(tmp_path):
    scene = tmp_path / "slow_fall.yaml"
    scene.write_text(SLOW_SCENE)
    arguments = [str(scene), str(PROJECTILE), "--jobs", "1", "--sweeps", "on"]
    killed = physval("run", *arguments, "--out", "killed", cwd=tmp_path)
    deadline = time.monotonic() + RUN_TIMEOUT_S
    while not list(tmp_path.glob(".killed-staging-*/journal/job-*.zip")):
        assert killed.poll() is None, f"the run ended before a job finished: {killed.stderr.read()}"
        assert time.monotonic() < deadline, "no job finished in time"
        time.sleep(0.005)
    os.killpg(killed.pid, signal.SIGKILL)
    killed.wait()
    committed = len(list(tmp_path.glob(".killed-staging-*/journal/job-*.zip")))
    assert 1 <= committed < planned_jobs(scene, PROJECTILE), committed
    assert not (tmp_path / "killed").exists(), "a killed run must not publish"

    code, out, err = run("run", "--resume", "killed", "--jobs", "1", cwd=tmp_path)
    assert code == 0, err
    assert "Traceback" not in err
    assert f"{committed} of {planned_jobs(scene, PROJECTILE)} jobs from the journal" in out, out
    assert leftovers(tmp_path) == []
    code, _, err = run("run", *arguments, "--out", "whole", cwd=tmp_path)
    assert code == 0, err

    resumed = pd.read_csv(tmp_path / "killed" / "results.csv")
    whole = pd.read_csv(tmp_path / "whole" / "results.csv")
    pd.testing.assert_frame_equal(
        resumed.drop(columns=WALL_TIME_COLUMNS), whole.drop(columns=WALL_TIME_COLUMNS)
    )
    for name in ("series.csv", "impacts.csv"):
        assert (tmp_path / "killed" / name).read_bytes() == (tmp_path / "whole" / name).read_bytes()


KILL_AFTER_EXCHANGE = """
import os, signal
import validation.jobs.output as output
exchange = output._exchange
def exchange_then_die(a, b):
    done = exchange(a, b)
    os.kill(os.getpid(), signal.SIGKILL)
    return done
output._exchange = exchange_then_die
"""

KILL_BETWEEN_RENAMES = """
import os, signal
import validation.jobs.output as output
output._exchange = lambda a, b: False  # a system without an atomic exchange
replace = os.replace
def replace_then_die(source, target):
    replace(source, target)
    if ".old-" in str(target):
        os.kill(os.getpid(), signal.SIGKILL)
os.replace = replace_then_die
"""


def _two_scenes(tmp_path: Path) -> tuple[Path, Path]:
    first, second = tmp_path / "first.yaml", tmp_path / "second.yaml"
    fall = "dt: 0.01\nduration: 0.1\nengines: [mini]\nbodies: [{name: b, shape: {type: sphere, radius: 0.1}, mass: 1.0}]\n"
    first.write_text(fall)
    second.write_text(fall)
    return first, second


def test_a_kill_between_the_publish_steps_leaves_a_report_and_the_next_run_cleans_up(tmp_path):
    first, second = _two_scenes(tmp_path)
    assert run("run", str(first), "--out", "out", cwd=tmp_path)[0] == 0
    code, _, _ = run("run", str(second), "--out", "out", cwd=tmp_path, code=KILL_AFTER_EXCHANGE)
    assert code == -signal.SIGKILL
    results = pd.read_csv(tmp_path / "out" / "results.csv")
    assert set(results["scenario"]) == {"second"}, "the new report is at --out"
    assert leftovers(tmp_path), "the killed run left its staging folder (the old report)"
    code, _, err = run("run", str(first), "--out", "out", cwd=tmp_path)
    assert code == 0, err
    assert leftovers(tmp_path) == [], err
    assert set(pd.read_csv(tmp_path / "out" / "results.csv")["scenario"]) == {"first"}


def test_without_an_atomic_exchange_a_kill_between_the_renames_is_put_back(tmp_path):
    first, second = _two_scenes(tmp_path)
    assert run("run", str(first), "--out", "out", cwd=tmp_path)[0] == 0
    code, _, _ = run("run", str(second), "--out", "out", cwd=tmp_path, code=KILL_BETWEEN_RENAMES)
    assert code == -signal.SIGKILL
    assert not (tmp_path / "out").exists(), "the kill landed between the two renames"
    code, _, err = run("run", str(first), "--out", "out", cwd=tmp_path)
    assert code == 0 and "restored" in err, err
    assert leftovers(tmp_path) == []


def test_two_concurrent_runs_on_one_out_end_without_a_traceback_and_one_report(tmp_path):
    scene = tmp_path / "slow_fall.yaml"
    scene.write_text(SLOW_SCENE)
    first = physval("run", str(scene), "--out", "out", "--jobs", "1", cwd=tmp_path, code=HELD)
    while not list(tmp_path.glob(".out-staging-*")):
        time.sleep(0.01)
    second = finish(physval("run", str(scene), "--out", "out", "--jobs", "1", cwd=tmp_path))
    (tmp_path / RELEASE_FILE).touch()  # the first run holds its lock until the second has ended
    ended = [finish(first), second]
    assert all("Traceback" not in err for _, _, err in ended), ended
    assert sorted(code for code, _, _ in ended) == [0, 2], ended
    loser = next(err for code, _, err in ended if code == 2)
    assert len(message_lines(loser)) == 1 and "another physval run" in loser, loser
    assert {"results.csv", "report.html", "series.csv"} <= {
        p.name for p in (tmp_path / "out").iterdir()
    }
    assert leftovers(tmp_path) == []


@pytest.mark.parametrize("kind", ["file", "symlink", "below a file"])
def test_out_a_file_or_a_symlink_exits_2_and_leaves_it(tmp_path, kind):
    target = tmp_path / "precious.txt"
    target.write_text("keep me")
    elsewhere = tmp_path / "elsewhere"
    elsewhere.mkdir()
    out = {
        "file": target,
        "symlink": tmp_path / "link",
        "below a file": target / "run",
    }[kind]
    if kind == "symlink":
        out.symlink_to(elsewhere)
    code, _, err = run("run", str(PROJECTILE), "--dt", "0.01", "--out", str(out), cwd=tmp_path)
    assert code == 2, err
    assert len(message_lines(err)) == 1 and "Traceback" not in err, err
    assert target.read_text() == "keep me"
    assert list(elsewhere.iterdir()) == []
    assert kind != "symlink" or out.is_symlink()


@pytest.fixture
def read_only_folder(tmp_path):
    """A folder nobody can write to (root included: chattr +i where run as root)."""
    folder = tmp_path / "read_only"
    folder.mkdir()
    if os.geteuid() == 0:
        if shutil.which("chattr") is None or subprocess.run(["chattr", "+i", folder]).returncode:
            pytest.skip("root, and no chattr +i here to make a folder read-only")
        yield folder
        subprocess.run(["chattr", "-i", folder], check=True)
    else:
        folder.chmod(stat.S_IRUSR | stat.S_IXUSR)
        yield folder
        folder.chmod(stat.S_IRWXU)


def test_a_read_only_output_exits_2_before_any_engine_runs(tmp_path, read_only_folder):
    fail_if_run = (
        "import validation.jobs.run as run\n"
        "def never(*a, **k): raise SystemExit('an engine ran')\n"
        "run.run_engine = never\n"
    )
    out = read_only_folder / "out"
    code, _, err = run(
        "run", str(PROJECTILE), "--out", str(out), "--jobs", "1", cwd=tmp_path, code=fail_if_run
    )
    assert code == 2, err
    assert len(message_lines(err)) == 1 and "cannot be written" in err, err


def test_run_folders_honour_the_umask_and_the_report_names_the_published_folder(tmp_path):
    first, _ = _two_scenes(tmp_path)
    code, _, err = run(
        "run", str(first), "--out", "out", cwd=tmp_path, code="import os; os.umask(0o027)"
    )
    assert code == 0, err
    assert stat.S_IMODE((tmp_path / "out").stat().st_mode) == 0o750
    page = (tmp_path / "out" / "report.html").read_text()
    assert "staging" not in page
    assert '<td class="mono">out</td>' in page


def test_default_history_folders_are_unique_within_a_second():
    names = {history_name() for _ in range(100)}
    assert len(names) == 100
    assert all(len(name.split("-")) == 3 and "." in name for name in names), names


def test_a_full_disk_is_refused_before_any_engine_runs(tmp_path):
    first, _ = _two_scenes(tmp_path)
    code, _, err = run(
        "run",
        str(first),
        "--out",
        "out",
        cwd=tmp_path,
        code="import validation.jobs.output as output; output.MIN_FREE_BYTES = 2**62",
    )
    assert code == 2 and "MIN_FREE_BYTES" in err, err
    assert len(message_lines(err)) == 1 and "Traceback" not in err, err


DISK_FULL_WHILE_WRITING = """
import errno
import validation.jobs.run as run
def disk_full(*_):
    raise OSError(errno.ENOSPC, "No space left on device")
run.write_run = disk_full
"""


def test_a_write_failing_after_the_engines_ran_keeps_their_jobs_for_resume(tmp_path):
    first, _ = _two_scenes(tmp_path)
    arguments = ("run", str(first), "--out", "out")
    code, _, err = run(*arguments, cwd=tmp_path, code=DISK_FULL_WHILE_WRITING)
    assert code == 2 and "No space left" in err and "--resume" in err, err
    assert len(message_lines(err)) == 1 and "Traceback" not in err, err
    assert len(list(tmp_path.glob(".out-staging-*/journal/job-*.zip"))) == 1
    code, out, err = run("run", "--resume", "out", cwd=tmp_path)
    assert code == 0 and "1 of 1 jobs from the journal" in out, err
    assert set(pd.read_csv(tmp_path / "out" / "results.csv")["scenario"]) == {"first"}
