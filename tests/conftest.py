"""Fixtures shared by test modules: one small real run, made once per test session.

``real_run``: ``physval run`` of two cheap scenes (a projectile with its own dt sweep, a
bouncing ball with impacts) in two engines, whose write of the run folder fails (a full
disk, injected) after every job was journaled: its journal is kept as the killed run left
it, and the files an uninterrupted run would have written are kept beside it. Then
``--resume`` publishes the run folder, records it in the history database and renders its
report. Tests copy what they mutate; nothing here is changed by a test.
"""

from __future__ import annotations

import errno
import os
import shutil
from dataclasses import dataclass
from pathlib import Path

import pytest

from validation.cli import BUNDLED_SCENARIOS, main

REAL_RUN_SCENES = (
    BUNDLED_SCENARIOS / "formulas" / "projectile.yaml",
    BUNDLED_SCENARIOS / "formulas" / "bounce_impact_times.yaml",
)
"""Two cheap scenes that between them give every kind of job and record: engine runs with
series and impacts, a dt sweep with its cross-check."""

REAL_RUN_ENGINES = "mini, pybullet"
"""Two engines: two adapters' provenance, and a cross-engine comparison."""


@dataclass(frozen=True)
class RealRun:
    """The session's real run (module docstring).

    Attributes:
        root: the working folder it ran in (its journal's ``cwd``).
        journal: a copy of the killed run's staging folder (``.killed-staging-<id>``).
        uninterrupted: the files the run would have written had its disk not filled.
        folder: the published run folder (after ``--resume``), with report.html.
        history: the history database the resumed run was recorded in.
        argv: the run's command line (after ``physval``).
    """

    root: Path
    journal: Path
    uninterrupted: Path
    folder: Path
    history: Path
    argv: tuple[str, ...]


def _records_into(folder: Path, write_run, write_table):
    """``run.write_run`` and ``run.write_table`` that write into ``folder`` too; the table
    (the sweep's, the run's last record file before its page) then fails as a full disk
    would, after every job was journaled."""

    def run_files(run_folder: Path, *arguments) -> None:
        folder.mkdir(exist_ok=True)
        write_run(folder, *arguments)
        write_run(run_folder, *arguments)

    def table_then_full(rows: list[dict], path: Path) -> None:
        write_table(rows, folder / path.name)
        raise OSError(errno.ENOSPC, "No space left on device (injected)")

    return run_files, table_then_full


@pytest.fixture(scope="session")
def real_run(tmp_path_factory) -> RealRun:
    import validation.jobs.run as run_module

    root = tmp_path_factory.mktemp("real_run")
    argv = (
        "run",
        *(str(p) for p in REAL_RUN_SCENES),
        "--engines",
        REAL_RUN_ENGINES,
        "--out",
        "killed",
        "--jobs",
        "1",
        "--sweeps",
        "on",
    )
    uninterrupted = root / "uninterrupted"
    before = Path.cwd()
    os.chdir(root)
    try:
        with pytest.MonkeyPatch.context() as patch:
            run_files, table_then_full = _records_into(
                uninterrupted, run_module.write_run, run_module.write_table
            )
            patch.setattr(run_module, "write_run", run_files)
            patch.setattr(run_module, "write_table", table_then_full)
            assert main(list(argv)) == 2, "the injected full disk must fail the write"
        (stage,) = root.glob(".killed-staging-*")
        journal = root / "journal-copy" / stage.name
        shutil.copytree(stage, journal, symlinks=True)
        assert main(["run", "--resume", "killed", "--jobs", "1"]) == 0
    finally:
        os.chdir(before)
    return RealRun(root, journal, uninterrupted, root / "killed", root / "history.sqlite", argv)
