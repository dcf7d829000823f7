"""Damaged, foreign and read-only history databases: ``history`` and ``compare`` read them as
one line (exit 2), never a traceback; ``run`` proves before any work that it can write its
history (a write it rolls back), so a database it cannot write is refused up front instead of
losing the run's record with a note at the end."""

from __future__ import annotations

import shutil
import sqlite3
import subprocess
from pathlib import Path

import pytest
from test_early_input import FALL, refused
from test_history import night, row, write_run

from validation.cli import main
from validation.contract import EXIT_OK
from validation.nightly import history

PAGE_BYTES = 4096
"""SQLite's default page size: the pages past the first two are the tables' rows."""


@pytest.fixture
def database(tmp_path) -> Path:
    """A history of two runs of 300 rows (several pages per table)."""
    run = write_run(tmp_path / "a", [row(f"s{i}", "mini", "m", 1e-3) for i in range(300)], night(1))
    path = tmp_path / "history.sqlite"
    history.record_run(run, f"sqlite:///{path}")
    history.record_run(run, f"sqlite:///{path}")
    return path


def damaged_page(path: Path) -> None:
    """Garbage in the middle of every page after the schema's: ``database disk image is
    malformed`` when read."""
    data = bytearray(path.read_bytes())
    for page in range(2, len(data) // PAGE_BYTES):
        data[page * PAGE_BYTES + 100 : page * PAGE_BYTES + 300] = b"\xab" * 200
    path.write_bytes(bytes(data))


def bad_utf8(path: Path) -> None:
    with sqlite3.connect(path) as connection:
        connection.execute("update series set scenario = cast(X'ff61' as text) where id = 1")


def missing_column(path: Path) -> None:
    with sqlite3.connect(path) as connection:
        connection.execute("alter table results drop column dt")


DAMAGES = {
    "a damaged page": (damaged_page, "database disk image is malformed"),
    "bad UTF-8": (bad_utf8, "Could not decode to UTF-8"),
    "a missing column": (missing_column, "no such column: results.dt"),
}


@pytest.mark.parametrize("damage", sorted(DAMAGES))
@pytest.mark.parametrize("command", ["history", "compare"])
def test_a_damaged_history_is_one_line(tmp_path, capsys, database, damage, command):
    """A traceback (sqlite3.DatabaseError / OperationalError) before."""
    make, says = DAMAGES[damage]
    make(database)
    arguments = {
        "history": ["history", "--db", str(database), "--out", str(tmp_path / "h.html")],
        "compare": ["compare", "1", "2", "--db", str(database), "--out", str(tmp_path / "c")],
    }[command]
    line = refused(arguments, capsys)
    assert line.startswith(f"--db sqlite:///{database}: not a readable physval history"), line
    assert says in line, line
    assert not (tmp_path / "h.html").exists() and not (tmp_path / "c").exists()


def run_recording(tmp_path: Path, url: str) -> list[str]:
    fall = tmp_path / "fall.yaml"
    fall.write_text(FALL)
    return ["run", str(fall), "--out", str(tmp_path / "out"), "--history", url, "--jobs", "1"]


def test_a_trigger_guarded_history_is_refused_before_any_work(tmp_path, capsys, database):
    """Passed the check before (it created tables and rolled back, never inserted), then the
    run's record was lost with a note."""
    with sqlite3.connect(database) as connection:
        connection.execute(
            "create trigger guard before insert on runs "
            "begin select raise(abort, 'this history is read-only'); end"
        )
    line = refused(run_recording(tmp_path, f"sqlite:///{database}"), capsys)
    assert line.startswith("--history ") and "this history is read-only" in line, line
    assert not (tmp_path / "out").exists()
    assert history.load_history(f"sqlite:///{database}").runs["id"].tolist() == [1, 2]


@pytest.fixture
def immutable(database):
    """``chattr +i``: read-only for root too (as on a read-only file system)."""
    if shutil.which("chattr") is None:
        pytest.skip("no chattr here to make a file read-only")

    def make(path: Path) -> Path:
        if subprocess.run(["chattr", "+i", path]).returncode:
            pytest.skip("chattr +i is not permitted here")
        made.append(path)
        return path

    made: list[Path] = []
    yield make
    for path in made:
        subprocess.run(["chattr", "-i", path], check=True)


@pytest.mark.parametrize("what", ["file", "folder"])
def test_a_read_only_history_is_refused_before_any_work(
    tmp_path, capsys, database, immutable, what
):
    """An immutable database file or folder passed the check before (the journal or the
    write fails only on the first insert): the run's record was lost with a note."""
    folder = tmp_path / "store"
    folder.mkdir()
    stored = folder / database.name
    shutil.copy(database, stored)
    immutable(stored if what == "file" else folder)
    line = refused(run_recording(tmp_path, f"sqlite:///{stored}"), capsys)
    assert line.startswith(f"--history sqlite:///{stored}: cannot open"), line
    assert not (tmp_path / "out").exists()


def test_the_write_probe_leaves_no_trace(tmp_path, capsys, database):
    """The check's rows are rolled back: the next run is recorded as run 3, nothing else."""
    before = sqlite3.connect(database).execute("select count(*) from series").fetchone()
    history.check_database(f"sqlite:///{database}")
    with sqlite3.connect(database) as connection:
        assert connection.execute("select count(*) from series").fetchone() == before
        assert connection.execute("select max(id) from runs").fetchone() == (2,)
    assert main(run_recording(tmp_path, f"sqlite:///{database}")) == EXIT_OK
    assert "history run 3" in capsys.readouterr().out
