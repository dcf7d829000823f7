"""Runs differ in what they select: the selection recorded (provenance.json, the history's
``runs``), read back checked, and the migration of a database written before it existed.

Run folders are synthetic (``test_history.write_run``) but for one real ``physval run`` of a
0.05 s scene in mini_engine.
"""

from __future__ import annotations

import json
import sqlite3
from pathlib import Path
from types import SimpleNamespace

import numpy as np
import pytest
from test_history import night, row, write_run

from validation.cli import main
from validation.contract import EXIT_OK, PROVENANCE_FILE
from validation.nightly import history

NIGHTLY = {"paths": ["scenarios"], "only": None, "engines": None, "dt": None, "sweeps": True}
"""The selection of a bare ``physval run`` in a checkout (the nightly's)."""

AD_HOC = {**NIGHTLY, "only": "*bounce*"}

UNRECORDED = "unrecorded"
"""The key of a run without a (valid) selection (``history.UNRECORDED``, spelled out so that
this file loads, and fails test by test, on a version without selections)."""
"""A scene author's run of one scene into the same history."""

SCHEMA_BEFORE_SELECTIONS = """
CREATE TABLE runs (
    id INTEGER NOT NULL, created DATETIME, "commit" VARCHAR(64), engine_versions JSON NOT NULL,
    machine JSON NOT NULL, command TEXT NOT NULL, folder TEXT NOT NULL,
    complete BOOLEAN NOT NULL, PRIMARY KEY (id)
);
CREATE TABLE series (
    id INTEGER NOT NULL, scenario VARCHAR(200) NOT NULL, engine VARCHAR(200) NOT NULL,
    metric VARCHAR(200) NOT NULL, PRIMARY KEY (id), UNIQUE (scenario, engine, metric)
);
CREATE TABLE results (
    id INTEGER NOT NULL, run_id INTEGER NOT NULL, series_id INTEGER NOT NULL, value DOUBLE,
    expected DOUBLE, error DOUBLE, tolerance DOUBLE, passed BOOLEAN,
    status VARCHAR(32) NOT NULL, outcome VARCHAR(32), baseline VARCHAR(32),
    engine_version VARCHAR(64) NOT NULL, dt DOUBLE, PRIMARY KEY (id),
    FOREIGN KEY(run_id) REFERENCES runs (id), FOREIGN KEY(series_id) REFERENCES series (id)
);
CREATE INDEX ix_results_run_id ON results (run_id);
"""
"""The history schema as commit 7bbfea0 (before selections) created it in SQLite (its
``.schema``, reflowed), with the values it stored: times as SQLAlchemy writes them to SQLite,
JSON as text, booleans as 0/1."""


def old_database(path: Path, runs: int) -> str:
    """An SQLite history written before selections: ``runs`` runs of one series, error 1e-3."""
    with sqlite3.connect(path) as connection:
        connection.executescript(SCHEMA_BEFORE_SELECTIONS)
        connection.execute("INSERT INTO series VALUES (1, 'bounce', 'mini', 'energy_drift')")
        for run_id in range(1, runs + 1):
            connection.execute(
                "INSERT INTO runs VALUES (?, ?, ?, ?, '{}', 'physval run', '/runs/x', 1)",
                (run_id, f"2025-01-0{run_id} 02:00:00.000000", "c0ffee", '{"mini": "0.1.0"}'),
            )
            connection.execute(
                "INSERT INTO results VALUES (?, ?, 1, 1.001, 1.0, 0.001, 0.01, 1, 'ok', NULL,"
                " NULL, '0.1.0', 0.001)",
                (run_id, run_id),
            )
    return f"sqlite:///{path}"


def test_an_old_database_without_the_selection_column_opens_and_is_read(tmp_path, capsys):
    database = tmp_path / "history.sqlite"
    url = old_database(database, runs=2)

    read = history.load_history(url)  # a reader: reads, and never writes
    assert list(read.runs["id"]) == [1, 2]
    assert list(read.runs["selection_key"]) == [history.UNRECORDED] * 2
    assert read.selection == history.UNRECORDED  # the latest run's: all of them here
    assert list(read.trend["error"]) == [0.001, 0.001]
    assert str(read.runs["created"].iloc[0])[:19] == "2025-01-01 02:00:00"
    assert read.runs["engine_versions"].iloc[0] == {"mini": "0.1.0"}
    with sqlite3.connect(database) as connection:
        columns = {r[1] for r in connection.execute("PRAGMA table_info(runs)")}
    assert "selection" not in columns, "reading must not migrate"
    assert main(["history", "--db", url]) == EXIT_OK
    assert "runs 1-2" in capsys.readouterr().out

    # the next writer adds the columns; the old runs stay, unrecorded, the new one has its key
    folder = write_run(tmp_path / "new", [row("bounce", "mini", "energy_drift", 2e-3)], night(3))
    (folder / PROVENANCE_FILE).write_text(
        json.dumps({**json.loads((folder / PROVENANCE_FILE).read_text()), "selection": NIGHTLY})
    )
    assert history.record_run(folder, url) == 3
    with sqlite3.connect(database) as connection:
        columns = {r[1] for r in connection.execute("PRAGMA table_info(runs)")}
        stored = connection.execute("SELECT id, selection_key FROM runs ORDER BY id").fetchall()
    assert {"selection", "selection_key"} <= columns
    key = history.selection_key(NIGHTLY)
    assert stored == [(1, None), (2, None), (3, key)]
    every = history.load_history(url, selection="all")
    assert list(every.runs["selection_key"]) == [history.UNRECORDED] * 2 + [key]
    assert list(every.trend["error"]) == [0.001, 0.001, 0.002]
    assert list(history.load_history(url).runs["id"]) == [3]  # the latest run's selection
    assert list(history.load_history(url, selection="unrecorded").runs["id"]) == [1, 2]
    history.record_run(folder, url)  # a migrated database is migrated once
    assert len(history.load_history(url).runs) == 2


def test_the_selection_is_recorded_and_its_key_ignores_spelling(tmp_path):
    from validation.jobs.nightly_run import PROJECT_ROOT, run_selection  # new with selections

    root = str(PROJECT_ROOT)
    no_sweeps = SimpleNamespace(sweeps=[])
    with_sweeps = SimpleNamespace(sweeps=[("a sweep",)])
    nightly = run_selection(["scenarios"], root, None, None, None, with_sweeps)
    assert nightly == NIGHTLY
    spelled = run_selection(
        [f"{root}/scenarios/", f"{root}/examples/../scenarios"],
        "/elsewhere",
        None,
        None,
        None,
        with_sweeps,
    )
    assert spelled == nightly  # one path, spelled twice, from another folder
    engines = run_selection(
        ["x.yaml"], "/tmp", None, "mujoco( integrator = RK4 ), mini", 1e-3, no_sweeps
    )
    assert engines["engines"] == ["mini", "mujoco(integrator=RK4)"]
    assert engines["paths"] == ["/tmp/x.yaml"] and engines["dt"] == 0.001
    assert history.selection_key(engines) == history.selection_key(
        run_selection(["/tmp/x.yaml"], "/", None, "mini,mujoco(integrator=RK4)", 0.001, no_sweeps)
    )
    keys = {
        history.selection_key(s)
        for s in (
            nightly,
            {**nightly, "only": "*bounce*"},
            {**nightly, "dt": 0.002},
            {**nightly, "engines": ["mini"]},
            run_selection(["scenarios"], root, None, None, None, no_sweeps),
        )
    }
    assert len(keys) == 5 and all(len(k) == history.SELECTION_KEY_DIGITS for k in keys)

    url = f"sqlite:///{tmp_path / 'h.sqlite'}"
    rows = [row("bounce", "mini", "energy_drift", 1e-4)]
    for day, selection in ((1, NIGHTLY), (2, AD_HOC)):
        history.record_run(write_run(tmp_path / f"r{day}", rows, night(day), None, selection), url)
    every = history.load_history(url, selection="all")
    assert list(every.runs["selection"]) == [NIGHTLY, AD_HOC]
    assert list(every.runs["selection_key"]) == [
        history.selection_key(s) for s in (NIGHTLY, AD_HOC)
    ]
    assert history.describe_selection(AD_HOC) == "scenarios --only *bounce* with sweeps"


@pytest.mark.parametrize(
    ("column", "stored", "read_as"),
    [
        ("selection", '{"paths": 5}', ("selection_key", UNRECORDED)),
        ("selection", "not json {", ("selection_key", UNRECORDED)),
        ("selection", '{"dt": 1e999}', ("selection_key", UNRECORDED)),
        ("selection", "[1, 2]", ("selection_key", UNRECORDED)),
        ("engine_versions", "[1, 2]", ("engine_versions", {})),
        ("engine_versions", "nonsense", ("engine_versions", {})),
        ("created", "the day after tomorrow", ("created", None)),
        ("commit", 42, ("commit", "42")),
    ],
)
def test_a_malformed_run_row_is_read_as_unknown_not_a_crash(tmp_path, column, stored, read_as):
    url = f"sqlite:///{tmp_path / 'h.sqlite'}"
    rows = [row("bounce", "mini", "energy_drift", 1e-4), row("bounce", "mini", "other", 1e-3)]
    history.record_run(write_run(tmp_path / "r", rows, night(1), None, NIGHTLY), url)
    with sqlite3.connect(tmp_path / "h.sqlite") as connection:
        connection.execute(f'UPDATE runs SET "{column}" = ?', (stored,))  # a foreign writer
        connection.execute("UPDATE results SET error = 'many' WHERE id = 2")
    found = history.load_history(url)
    name, expected = read_as
    assert found.runs[name].iloc[0] == expected
    assert np.isnan(found.trend["error"].iloc[1]) and found.trend["error"].iloc[0] == 1e-4
    assert main(["history", "--db", url]) == EXIT_OK


SPIN = """\
description: a free box spinning about its major axis, no gravity (a 50-step run)
dt: 0.001
duration: 0.05
gravity: [0, 0, 0]
engines: [mini]
bodies:
  - {name: spinner, shape: {type: box, half_extents: [0.2, 0.1, 0.05]}, mass: 1.0,
     angular_velocity: [0, 0, 5.0]}
checks:
  energy_drift: 0.05
"""


def test_physval_run_records_its_selection_and_history_draws_the_latest(tmp_path, capsys):
    scenes = tmp_path / "scenes"
    scenes.mkdir()
    (scenes / "spin.yaml").write_text(SPIN)
    (scenes / "spin_fast.yaml").write_text(SPIN.replace("[0, 0, 5.0]", "[0, 0, 9.0]"))
    url = f"sqlite:///{tmp_path / 'h.sqlite'}"
    common = ["--baseline", "none", "--history", url, "--jobs", "1"]
    for out, flags in (("r1", []), ("r2", ["--only", "spin_fast"]), ("r3", ["--dt", "0.0005"])):
        argv = ["run", str(scenes), "--out", str(tmp_path / out), *common, *flags]
        assert main(argv) == EXIT_OK, capsys.readouterr()
    recorded = [
        json.loads((tmp_path / o / PROVENANCE_FILE).read_text()) for o in ("r1", "r2", "r3")
    ]
    selections = [p["selection"] for p in recorded]
    path = scenes.resolve().as_posix()
    assert selections[0] == {
        "paths": [path],
        "only": None,
        "engines": None,
        "dt": None,
        "sweeps": False,
    }
    assert selections[1] == {**selections[0], "only": "spin_fast"}
    assert selections[2] == {**selections[0], "dt": 0.0005}
    capsys.readouterr()

    assert main(["history", "--db", url]) == EXIT_OK  # the latest run's selection: run 3
    printed = capsys.readouterr().out.splitlines()
    key = history.selection_key(selections[2])
    assert printed[0] == f"drew runs 3 (selection {key}: {path} --dt 0.0005 no sweeps)"
    others = [history.selection_key(s) for s in selections[1::-1]]
    assert printed[1].startswith(f"not drawn: {others[0]} (1 runs: 2), {others[1]} (1 runs: 1)")
    every = history.load_history(url, selection="all")
    assert list(every.runs["selection_key"]) == [history.selection_key(s) for s in selections]
