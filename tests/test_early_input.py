"""Bad input found before any work: a history database that cannot be recorded into, a baseline
with a key on two rows, and an ``--out`` where the other kind of path stands are exit 2 with one
line, before the first job, with nothing created and nothing of the user's overwritten. A
database that fails after the check (mid-way) stays a note on a run that exits 0."""

from __future__ import annotations

import signal
import sqlite3
import time
from pathlib import Path

import pandas as pd
import pytest
import sqlalchemy as sa

from validation.cli import BUNDLED_SCENARIOS, main
from validation.contract import EXIT_BAD_INPUT, EXIT_OK
from validation.nightly import history

PROJECTILE = str(BUNDLED_SCENARIOS / "formulas" / "projectile.yaml")
"""Four engines, ~10 s of work on this machine: a refusal within ``BAD_INPUT_SECONDS`` proves
that none of it ran."""

BAD_INPUT_SECONDS = 5
"""The project's bound for refusing bad input (tests/test_hostile_input.py): before any work."""

SECRET = "hunter2"
"""A password in the URLs below: it must appear in no output."""

UNREACHABLE = f"postgresql://ci:{SECRET}@127.0.0.1:1/physval"
"""A server that refuses the connection at once (nothing listens on port 1 of the loopback)."""


FALL = (
    "dt: 0.01\nduration: 0.05\nengines: [mini]\n"
    "bodies: [{name: b, shape: {type: sphere, radius: 0.1}, mass: 1.0}]\n"
)
"""A scene of five steps, for the runs that must get through."""


class TooSlow(BaseException):
    """The alarm of ``refused``: no ``except Exception`` or ``except OSError`` of the run may
    take it for one of its own errors (a TimeoutError is an OSError)."""


def refused(argv: list[str], capsys) -> str:
    """``physval ARGV`` in this process: exit 2 with one line on stderr and nothing on stdout,
    within ``BAD_INPUT_SECONDS`` (an alarm ends a hang); the line."""

    def too_slow(*_):
        raise TooSlow(f"physval {argv[0]} took more than {BAD_INPUT_SECONDS} s")

    previous = signal.signal(signal.SIGALRM, too_slow)
    signal.alarm(BAD_INPUT_SECONDS)
    try:
        code = main(argv)
    finally:
        signal.alarm(0)
        signal.signal(signal.SIGALRM, previous)
    captured = capsys.readouterr()
    lines = captured.err.strip().splitlines()
    assert code == EXIT_BAD_INPUT, (code, captured)
    assert len(lines) == 1 and "Traceback" not in captured.err, captured.err
    assert captured.out == "", captured.out
    assert SECRET not in captured.err, captured.err  # the one line hides the password too
    return lines[0]


BAD_HISTORIES = [
    ("nosuchdialect://ci:{secret}@db/physval", "not a usable database URL"),
    ("{tmp}/history.sqlite", "not a database URL (expected dialect://"),
    (UNREACHABLE, "cannot open"),
    ("sqlite:///{tmp}/nowhere/deeper/history.sqlite", "no folder"),
    ("sqlite:///{tmp}/not_a_database.sqlite", "cannot open (file is not a database)"),
    ("sqlite:///{tmp}", "is a folder, not a file"),
]
"""``--history`` values that cannot be recorded into, and what the line says."""


@pytest.mark.parametrize(("url", "says"), BAD_HISTORIES)
def test_a_bad_history_is_refused_before_the_first_job(tmp_path, capsys, url, says):
    (tmp_path / "not_a_database.sqlite").write_text("not a database\n")
    before = sorted(tmp_path.rglob("*"))
    out = tmp_path / "out"
    given = url.format(tmp=tmp_path, secret=SECRET)
    line = refused(["run", PROJECTILE, "--out", str(out), "--history", given], capsys)
    assert says in line and line.startswith("--history "), line
    assert sorted(tmp_path.rglob("*")) == before  # no run folder, no database, no folder


def test_an_sqlite_file_in_the_folder_the_run_makes_is_recorded(tmp_path, capsys):
    """A CI cache's first night: ``--history sqlite:///reports/history.sqlite`` before
    ``reports/`` exists, which the run makes for its ``--out``: accepted and recorded."""
    fall = tmp_path / "fall.yaml"
    fall.write_text(FALL)
    database = tmp_path / "reports" / "history.sqlite"
    out = tmp_path / "reports" / "latest"
    argv = ["run", str(fall), "--out", str(out), "--history", f"sqlite:///{database}"]
    assert main([*argv, "--jobs", "1", "--baseline", "none"]) == EXIT_OK
    assert "history run 1" in capsys.readouterr().out and database.is_file()


def test_the_check_rolls_back_what_it_created(tmp_path, capsys):
    """An empty SQLite file passes the check (the tables can be created) and is left empty:
    the check's CREATE TABLE is rolled back when the run then stops on a bad
    scene."""
    database = tmp_path / "history.sqlite"
    sqlite3.connect(database).close()
    bad_scene = tmp_path / "bad.yaml"
    bad_scene.write_text(
        "dt: -1\nduration: 0.1\nengines: [mini]\n"
        "bodies: [{name: b, shape: {type: sphere, radius: 0.1}, mass: 1.0}]\n"
    )
    url = f"sqlite:///{database}"
    refused(["run", str(bad_scene), "--out", str(tmp_path / "out"), "--history", url], capsys)
    assert sa.inspect(sa.create_engine(url)).get_table_names() == []


def test_the_check_leaves_an_older_recorded_history_as_it_was(tmp_path):
    """The check on a database of an older version (runs recorded, no selection columns)
    adds the columns, then rolls them back: the next run's recording migrates."""
    from test_history_selection import old_database

    database = tmp_path / "history.sqlite"
    url = old_database(database, runs=2)

    def contents() -> tuple[list, list]:
        with sqlite3.connect(database) as connection:
            runs = connection.execute("select * from runs order by id").fetchall()
            columns = [row[1] for row in connection.execute("pragma table_info(runs)")]
        return runs, columns

    before = contents()
    history.check_database(url)
    assert contents() == before
    assert "selection" not in before[1] and len(before[0]) == 2


def test_a_history_that_fails_after_the_check_is_a_note(tmp_path, capsys, monkeypatch):
    """The rule for a database that fails mid-way (after the check passed) is kept: the run is
    published, exit 0, the note says why (its password hidden)."""
    from validation.jobs import nightly_run

    def unreachable(*_):
        raise sa.exc.OperationalError("connect", {}, Exception(f"lost {UNREACHABLE}"))

    monkeypatch.setattr(nightly_run, "record_run", unreachable)
    fall = tmp_path / "fall.yaml"
    fall.write_text(FALL)
    url = f"sqlite:///{tmp_path / 'history.sqlite'}"
    out = tmp_path / "out"
    code = main(["run", str(fall), "--out", str(out), "--history", url, "--jobs", "1"])
    printed = capsys.readouterr().out
    assert code == EXIT_OK and (out / "results.csv").is_file()
    assert "history not recorded (OperationalError" in printed, printed
    assert SECRET not in printed and "ci:***@127.0.0.1:1" in printed, printed


def test_a_baseline_with_a_key_on_two_rows_is_refused(tmp_path, capsys):
    run = tmp_path / "run"
    assert main(["run", PROJECTILE, "--engines", "mini", "--out", str(run), "--jobs", "1",
                 "--history", "none", "--baseline", "none"]) == EXIT_OK  # fmt: skip
    baseline = tmp_path / "baseline.csv"
    assert main(["baseline", "save", str(run), "--to", str(baseline)]) == EXIT_OK
    table = pd.read_csv(baseline, dtype=str, keep_default_na=False)
    doubled = pd.concat([table, table.iloc[[3]]], ignore_index=True)
    doubled.loc[len(doubled) - 1, "error"] = "1.0"  # which of the two is the baseline?
    doubled.to_csv(baseline, index=False)
    capsys.readouterr()
    start = time.monotonic()
    line = refused(["run", PROJECTILE, "--out", str(tmp_path / "again"), "--baseline",
                    str(baseline)], capsys)  # fmt: skip
    key = ", ".join(table.iloc[3][["scenario", "engine", "metric"]])
    assert line.startswith(f"--baseline: {baseline}: not a baseline: lines 5, {len(doubled) + 1}")
    assert f"({key})" in line, line
    assert time.monotonic() - start < BAD_INPUT_SECONDS and not (tmp_path / "again").exists()


@pytest.fixture
def two_runs(tmp_path) -> tuple[Path, Path]:
    from test_history import night, row, write_run

    a = write_run(tmp_path / "a", [row("s", "mini", "m", 1e-3)], night(1))
    b = write_run(tmp_path / "b", [row("s", "mini", "m", 2e-3)], night(2))
    return a, b


def test_compare_out_on_a_file_is_refused_and_the_file_kept(tmp_path, capsys, two_runs):
    mine = tmp_path / "notes.txt"
    mine.write_text("mine\n")
    line = refused(["compare", *map(str, two_runs), "--out", str(mine)], capsys)
    assert line == f"--out: {mine} is a file; expected a folder", line
    assert mine.read_text() == "mine\n"


def test_compare_out_with_a_folder_where_its_csv_goes_is_refused(tmp_path, capsys, two_runs):
    out = tmp_path / "compare"
    (out / "compare.csv").mkdir(parents=True)
    line = refused(["compare", *map(str, two_runs), "--out", str(out)], capsys)
    assert "compare.csv is a folder; expected a file" in line, line
    assert not (out / "compare.html").exists()


def test_compare_checks_a_given_db_even_when_both_runs_are_folders(tmp_path, capsys, two_runs):
    db = f"nosuchdialect://ci:{SECRET}@db/physval"
    line = refused(
        ["compare", *map(str, two_runs), "--db", db, "--out", str(tmp_path / "c")], capsys
    )
    assert line.startswith("--db nosuchdialect://ci:***@db/physval: not a usable"), line
    assert not (tmp_path / "c").exists()


def test_history_out_on_a_folder_is_refused_and_the_folder_kept(tmp_path, capsys, two_runs):
    url = f"sqlite:///{tmp_path / 'h.sqlite'}"
    history.record_run(two_runs[0], url)
    page = tmp_path / "pages"
    (page / "keep.txt").parent.mkdir()
    (page / "keep.txt").write_text("mine\n")
    line = refused(["history", "--db", url, "--out", str(page)], capsys)
    assert line == f"--out: {page} is a folder; expected a file", line
    assert [p.name for p in page.iterdir()] == ["keep.txt"]


def test_history_out_under_a_file_is_refused(tmp_path, capsys, two_runs):
    url = f"sqlite:///{tmp_path / 'h.sqlite'}"
    history.record_run(two_runs[0], url)
    (tmp_path / "file").write_text("mine\n")
    line = refused(["history", "--db", url, "--out", str(tmp_path / "file" / "h.html")], capsys)
    assert line == f"--out: {tmp_path / 'file'} is a file; expected a folder", line
