"""Nothing of the user's is ever lost: every command that writes refuses, before any work and
with one line (exit 2), a destination that holds something physval did not write or that the
command reads; ``run --out`` replaces only a new path, an empty folder or a physval run folder
(``--new-folder`` publishes into a new subfolder instead); lock files are never followed
through a symlink; missing parent folders are created."""

from __future__ import annotations

import os
import sqlite3
from pathlib import Path

import pytest
from test_early_input import FALL, refused
from test_history import night, row, write_run

import validation.jobs.run as run_module
from validation.cli import main
from validation.contract import EXIT_BAD_INPUT, EXIT_OK
from validation.nightly import history

MINE = "mine, not physval's\n"
"""The content of every file of the user's below: it must be there, unchanged, afterwards."""


def no_work(monkeypatch) -> None:
    """``run`` fails the test if it gets to its jobs: a refusal must come before any work."""

    def work_began(*_, **__):
        raise AssertionError("the run's jobs began: the destination was not checked first")

    monkeypatch.setattr(run_module, "execute", work_began)


@pytest.fixture(name="no_work")
def _no_work(monkeypatch) -> None:
    no_work(monkeypatch)


@pytest.fixture
def scene(tmp_path) -> Path:
    path = tmp_path / "fall.yaml"
    path.write_text(FALL)
    return path


def run_argv(scene: Path, out: str | Path, *more: str) -> list[str]:
    return ["run", str(scene), "--out", str(out), "--jobs", "1", "--history", "none", *more]


def mount_point() -> Path:
    """A mounted folder other than ``/`` (a run cannot rename it)."""
    for line in Path("/proc/self/mounts").read_text().splitlines():
        where = Path(line.split()[1])
        if where != Path("/") and where.is_dir() and os.path.ismount(where):
            return where
    pytest.skip("no mount point but / here")


def users_folder(tmp_path: Path) -> Path:
    folder = tmp_path / "thesis"
    folder.mkdir()
    (folder / "chapter1.tex").write_text(MINE)
    return folder


def test_out_on_a_folder_of_the_users_is_refused_and_kept(tmp_path, capsys, scene, no_work):
    """Before: the run replaced the folder whole (chapter1.tex deleted)."""
    folder = users_folder(tmp_path)
    line = refused(run_argv(scene, folder), capsys)
    assert line.startswith(f"--out {folder}: holds 1 entry (chapter1.tex) and is not"), line
    assert "--new-folder" in line, line
    assert (folder / "chapter1.tex").read_text() == MINE


def test_out_on_the_input_scenes_is_refused(tmp_path, capsys, no_work):
    """Before: the scene files were deleted by publishing."""
    scenes = tmp_path / "scenes"
    scenes.mkdir()
    (scenes / "fall.yaml").write_text(FALL)
    line = refused(run_argv(scenes / "fall.yaml", scenes), capsys)
    assert line.startswith(f"--out {scenes}: holds 1 entry (fall.yaml)"), line
    assert (scenes / "fall.yaml").read_text() == FALL


@pytest.mark.parametrize("out", [".", "..", "/"])
def test_out_the_working_folder_or_a_parent_is_one_line(
    tmp_path, capsys, monkeypatch, scene, no_work, out
):
    """Before: ``.`` and ``/`` were a ValueError traceback; ``..`` failed only at publish."""
    work = tmp_path / "work"
    work.mkdir()
    (work / "notes.txt").write_text(MINE)
    monkeypatch.chdir(work)
    line = refused(run_argv(scene, out), capsys)
    assert line.startswith(f"--out {out}: is the working folder or one of its parents"), line
    assert (work / "notes.txt").read_text() == MINE


def test_out_on_a_mount_point_is_refused_before_any_work(capsys, scene, no_work):
    """Before: the run ran, then failed to publish (a mount point cannot be renamed)."""
    where = mount_point()
    line = refused(run_argv(scene, where), capsys)
    assert line.startswith(f"--out {where}: is a mount point"), line


def test_a_run_folder_holding_a_file_of_the_users_is_refused(tmp_path, capsys, scene):
    out = tmp_path / "out"
    assert main(run_argv(scene, out)) == EXIT_OK
    (out / "notes.txt").write_text(MINE)
    capsys.readouterr()
    line = refused(run_argv(scene, out), capsys)
    assert line.startswith(f"--out {out}: is a physval run folder that also holds notes.txt"), line
    assert (out / "notes.txt").read_text() == MINE and (out / "results.csv").is_file()


def test_a_file_put_into_out_during_the_run_is_kept_and_the_run_resumable(
    tmp_path, capsys, monkeypatch, scene
):
    """Publishing checks ``--out`` again: what appeared there meanwhile is not replaced."""
    out = tmp_path / "out"
    assert main(run_argv(scene, out)) == EXIT_OK
    execute = run_module.execute

    def meanwhile(*arguments, **options):
        (out / "notes.txt").write_text(MINE)
        return execute(*arguments, **options)

    monkeypatch.setattr(run_module, "execute", meanwhile)
    capsys.readouterr()
    assert main(run_argv(scene, out)) == EXIT_BAD_INPUT
    assert "also holds notes.txt" in capsys.readouterr().err.strip().splitlines()[-1]
    assert (out / "notes.txt").read_text() == MINE
    assert len(list(tmp_path.glob(".out-staging-*/journal"))) == 1  # --resume finishes it


@pytest.mark.parametrize("flag", ["--junit", "--history"])
def test_a_file_the_run_writes_inside_out_is_refused(tmp_path, capsys, monkeypatch, scene, flag):
    """Before: it was written into the earlier run folder at --out and lost when the run
    published (or at the next run's publishing)."""
    out = tmp_path / "out"
    assert main(run_argv(scene, out)) == EXIT_OK
    no_work(monkeypatch)
    target = out / ("junit.xml" if flag == "--junit" else "history.sqlite")
    given = str(target) if flag == "--junit" else f"sqlite:///{target}"
    argv = [a for a in run_argv(scene, out) if a not in ("--history", "none")]
    capsys.readouterr()
    line = refused([*argv, flag, given], capsys)
    assert line.startswith(f"{flag} {target}: is inside --out {out}"), line
    assert not target.exists()


def test_junit_on_a_file_physval_did_not_write_is_refused(tmp_path, capsys, scene, no_work):
    """Before: ``--junit fall.yaml`` overwrote the scene with XML after the run."""
    line = refused(run_argv(scene, tmp_path / "out", "--junit", str(scene)), capsys)
    assert line == (
        f"--junit: {scene} is a file physval did not write (not a physval JUnit file); it is "
        "left as it was: give a new file, or remove it first"
    ), line
    assert scene.read_text() == FALL


@pytest.mark.parametrize("link", ["symlink", "hard link"])
def test_a_planted_lock_link_is_refused_and_its_target_kept(tmp_path, capsys, scene, no_work, link):
    """Before: the lock was opened through the link, and its target truncated to a pid."""
    victim = tmp_path / "victim.txt"
    victim.write_text(MINE)
    lock = tmp_path / ".out.lock"
    lock.symlink_to(victim) if link == "symlink" else lock.hardlink_to(victim)
    line = refused(run_argv(scene, tmp_path / "out"), capsys)
    says = "a symlink, never followed" if link == "symlink" else "not a regular file of its own"
    assert line.startswith(f"--out {tmp_path / 'out'}: its lock") and says in line, line
    assert victim.read_text() == MINE


def test_an_earlier_run_its_junit_and_missing_parents(tmp_path, capsys, scene):
    """An earlier run folder and JUnit file of physval's are replaced; the missing folders of
    ``--out`` and ``--junit`` are created (``--junit`` needed an existing folder before)."""
    out, junit = tmp_path / "a" / "b" / "out", tmp_path / "ci" / "deeper" / "junit.xml"
    for _ in range(2):
        assert main(run_argv(scene, out, "--junit", str(junit))) == EXIT_OK
    assert (out / "results.csv").is_file() and junit.read_text().count("<testsuites") == 1


def test_new_folder_publishes_into_a_subfolder_and_keeps_the_rest(tmp_path, capsys, scene):
    folder = users_folder(tmp_path)
    assert main([*run_argv(scene, folder), "--new-folder"]) == EXIT_OK
    (published,) = folder.glob("run-*")
    assert (published / "results.csv").is_file()
    kept = sorted(p.name for p in folder.iterdir() if not p.name.startswith("."))  # its lock
    assert kept == ["chapter1.tex", published.name]
    assert (folder / "chapter1.tex").read_text() == MINE
    assert f"-> {published / 'results.csv'}" in capsys.readouterr().out


# --- the other commands that write -------------------------------------------------------


@pytest.fixture
def recorded(tmp_path) -> tuple[Path, Path, Path]:
    """Two run folders and a history database of both."""
    a = write_run(tmp_path / "a", [row("s", "mini", "m", 1e-3)], night(1))
    b = write_run(tmp_path / "b", [row("s", "mini", "m", 2e-3)], night(2))
    database = tmp_path / "history.sqlite"
    for folder in (a, b):
        history.record_run(folder, f"sqlite:///{database}")
    return a, b, database


def test_history_out_on_its_database_is_refused(capsys, recorded):
    """Before: the database was overwritten by the page."""
    *_, database = recorded
    before = database.read_bytes()
    line = refused(["history", "--db", str(database), "--out", str(database)], capsys)
    assert line == f"--out: {database} is an input of this command; it is left as it was", line
    assert database.read_bytes() == before
    assert sqlite3.connect(database).execute("select count(*) from runs").fetchone() == (2,)


def test_history_out_replaces_its_own_page_only(tmp_path, capsys, recorded):
    *_, database = recorded
    page = tmp_path / "pages" / "deeper" / "history.html"
    for _ in range(2):  # missing folders created, then its own page replaced
        assert main(["history", "--db", str(database), "--out", str(page)]) == EXIT_OK
    foreign = tmp_path / "index.html"
    foreign.write_text(MINE)
    capsys.readouterr()
    line = refused(["history", "--db", str(database), "--out", str(foreign)], capsys)
    assert "not a physval history page" in line, line
    assert foreign.read_text() == MINE


def test_compare_out_on_a_run_folder_it_reads_or_a_foreign_page_is_refused(
    tmp_path, capsys, recorded
):
    a, b, _ = recorded
    line = refused(["compare", str(a), str(b), "--out", str(a)], capsys)
    assert line == f"--out: {a} is the run folder {a} this command reads", line
    out = tmp_path / "c"
    out.mkdir()
    (out / "compare.html").write_text(MINE)
    line = refused(["compare", str(a), str(b), "--out", str(out)], capsys)
    assert "not a physval compare page" in line, line
    assert (out / "compare.html").read_text() == MINE
    (out / "compare.html").unlink()
    for _ in range(2):  # its own files replaced
        assert main(["compare", str(a), str(b), "--out", str(out)]) == EXIT_OK


def test_stability_out_on_a_scene_is_refused(capsys, scene):
    """Before: the search ran and replaced the scene file with its CSV."""
    line = refused(["stability", str(scene), "--jobs", "1", "--out", str(scene)], capsys)
    assert line == f"--out {scene}: {scene} is an input of this command; it is left as it was"
    assert scene.read_text() == FALL
    out = scene.parent / "limits" / "stability.csv"
    for _ in range(2):  # the missing folder created, then its own CSV replaced
        assert main(["stability", str(scene), "--jobs", "1", "--out", str(out)]) == EXIT_OK


def test_sweep_out_with_a_foreign_csv_is_refused(tmp_path, capsys, scene):
    """Before: the sweep ran and replaced the user's sweep.csv."""
    out = tmp_path / "sweep"
    out.mkdir()
    (out / "sweep.csv").write_text(MINE)
    argv = ["sweep", str(scene), "--engines", "mini", "--dt", "4e-3,2e-3", "--jobs", "1"]
    line = refused([*argv, "--out", str(out)], capsys)
    assert "sweep.csv is a file physval did not write (not a physval sweep.csv)" in line, line
    assert (out / "sweep.csv").read_text() == MINE
    (out / "sweep.csv").rename(out / "notes.csv")
    for _ in range(2):  # its own files replaced, the folder's other files kept
        assert main([*argv, "--out", str(out)]) == EXIT_OK
    assert (out / "notes.csv").read_text() == MINE


def test_baseline_to_a_file_of_the_run_is_refused(capsys, recorded):
    """Before: ``--to RUN/results.csv`` overwrote the run's record with the baseline."""
    a, *_ = recorded
    before = (a / "results.csv").read_text()
    line = refused(["baseline", "save", str(a), "--to", str(a / "results.csv")], capsys)
    assert line == f"--to: {a / 'results.csv'} is an input of this command; it is left as it was"
    assert (a / "results.csv").read_text() == before
    line = refused(["baseline", "save", str(a), "--to", str(a / "baseline.csv")], capsys)
    assert (
        line
        == f"--to: {a / 'baseline.csv'} is inside the run folder {a}, which a run replaces whole"
    )


def test_baseline_to_replaces_a_baseline_only(tmp_path, capsys, recorded):
    a, *_ = recorded
    to = tmp_path / "baselines" / "new" / "default.csv"
    for _ in range(2):  # the missing folders created (refused before), then its own replaced
        assert main(["baseline", "save", str(a), "--to", str(to)]) == EXIT_OK
    foreign = tmp_path / "table.csv"
    foreign.write_text("a,b\n1,2\n")
    capsys.readouterr()
    line = refused(["baseline", "save", str(a), "--to", str(foreign)], capsys)
    assert "not a physval baseline" in line, line
    assert foreign.read_text() == "a,b\n1,2\n"


@pytest.mark.parametrize("out", [".", "/"])
def test_sweep_out_the_working_folder_writes_into_it_and_root_is_one_line(
    tmp_path, capsys, monkeypatch, scene, out
):
    """``sweep --out .`` writes its two files into the working folder (its lock beside it);
    ``--out /`` is one line. Both were a ValueError traceback (the lock's name) before."""
    work = tmp_path / "work"
    work.mkdir()
    monkeypatch.chdir(work)
    argv = ["sweep", str(scene), "--engines", "mini", "--dt", "4e-3,2e-3", "--jobs", "1"]
    if out == "/":
        line = refused([*argv, "--out", out], capsys)
        assert line == "--out /: is the root folder; give a folder below it", line
        return
    assert main([*argv, "--out", out]) == EXIT_OK
    assert sorted(p.name for p in work.iterdir()) == ["sweep.csv", "sweep.html"]
