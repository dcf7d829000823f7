"""The Python API (``physval``): ``run``, ``load_scene`` and ``check`` do what the commands do,
print nothing, never exit, and refuse bad input with ``physval.InputError``."""

from __future__ import annotations

import os
import subprocess
import sys
import tempfile
from pathlib import Path

import pandas as pd
import pytest

import physval
from validation.cli import BUNDLED_SCENARIOS
from validation.contract import RESULTS_COLUMNS

ROOT = Path(__file__).resolve().parent.parent
PROJECTILE = BUNDLED_SCENARIOS / "formulas" / "projectile.yaml"
NOTEBOOK = ROOT / "docs" / "examples" / "python_api.py"

TOO_TIGHT = """\
dt: 0.001
duration: 0.5
bodies: [{name: b, shape: {type: sphere, radius: 0.1}, mass: 1.0}]
checks: {position_error: 1.0e-6}   # semi-implicit Euler is off by g·dt·t/2 = 1.2 mm
"""
"""A scene whose check mini fails: the run's exit code is 1."""

BAD_SCENE = """\
dt: 0.001
duration: 0.5
bodies: [{name: b, shape: {type: sphere, radius: -0.1}, mass: 1.0}]
"""
"""A scene that does not validate: its sphere's radius is negative (line 3)."""


@pytest.fixture
def private_tmp(tmp_path, monkeypatch) -> Path:
    """The temporary folder ``tempfile`` uses, empty: what a run leaves there is seen."""
    folder = tmp_path / "tmp"
    folder.mkdir()
    monkeypatch.setattr(tempfile, "tempdir", str(folder))
    return folder


def test_run_without_out_returns_the_rows_and_leaves_nothing(private_tmp, tmp_path, capsys):
    before = set(os.listdir(tmp_path))
    results = physval.run(PROJECTILE, engines=["mini", "mujoco"])
    assert isinstance(results.rows, pd.DataFrame)
    assert list(results.rows.columns) == list(RESULTS_COLUMNS)
    assert set(results.rows["engine"]) == {"mini", "mujoco"}
    assert set(results.rows["scenario"]) == {"projectile"}
    assert results.rows["value"].dtype == float
    assert not results.rows["metric"].str.startswith("sweep_").any(), "no sweep unless asked"
    assert results.exit_code == 0 and results.passed and results.folder is None
    assert list(private_tmp.iterdir()) == [], "the temporary run folder must be removed"
    assert set(os.listdir(tmp_path)) == before
    printed = capsys.readouterr()
    assert printed.out == "" and printed.err == "", printed


def test_run_with_out_publishes_the_run_folder(tmp_path):
    results = physval.run([PROJECTILE], engines="mini", out=tmp_path / "run", sweeps=True)
    assert results.folder == tmp_path / "run"
    written = pd.read_csv(results.folder / "results.csv")
    assert len(written) == len(results.rows) > 0
    assert results.rows["metric"].str.startswith("sweep_").any(), "sweeps=True sweeps"
    assert (results.folder / "report.html").is_file()
    beside = sorted(p.name for p in tmp_path.iterdir())
    assert beside == [".run.lock", "run"], "its lock (as physval run's), no history database"


def test_a_failed_check_is_exit_code_1_and_not_passed(tmp_path):
    scene = tmp_path / "tight.yaml"
    scene.write_text(TOO_TIGHT)
    results = physval.run(scene, engines="mini")
    assert results.exit_code == 1 and not results.passed
    row = results.rows.set_index("metric").loc["position_error"]
    assert row["status"] == "failed" and row["passed"] is False, row


@pytest.mark.parametrize(
    ("arguments", "says"),
    [
        ({"scenes": PROJECTILE, "engines": "mujoko"}, "--engines: unknown engine 'mujoko'"),
        ({"scenes": "no/such.yaml"}, "no/such.yaml: no such file or folder"),
        ({"scenes": BAD_SCENE}, "bodies[0].shape.radius"),
        ({"scenes": PROJECTILE, "jobs": 0}, "jobs: expected a whole number >= 1; got 0"),
    ],
)
def test_run_refuses_bad_input_with_input_error(arguments, says, tmp_path, private_tmp):
    if arguments["scenes"] is BAD_SCENE:
        arguments["scenes"] = tmp_path / "bad.yaml"
        arguments["scenes"].write_text(BAD_SCENE)
    mine = tmp_path / "mine"
    mine.mkdir()
    (mine / "notes.txt").write_text("mine")
    with pytest.raises(physval.InputError) as refused:
        physval.run(**arguments, out=mine)
    assert any(says in line for line in refused.value.problems), refused.value.problems
    assert isinstance(refused.value, ValueError) and not isinstance(refused.value, SystemExit)
    assert sorted(p.name for p in mine.iterdir()) == ["notes.txt"], "nothing of the user's touched"
    assert list(private_tmp.iterdir()) == []


def test_run_refuses_an_out_folder_that_is_not_a_run(tmp_path):
    mine = tmp_path / "mine"
    mine.mkdir()
    (mine / "notes.txt").write_text("mine")
    with pytest.raises(physval.InputError) as refused:
        physval.run(PROJECTILE, engines="mini", out=mine)
    assert str(mine) in refused.value.problems[0], refused.value.problems
    assert (mine / "notes.txt").read_text() == "mine"


def test_load_scene_returns_the_validated_scene():
    scene = physval.load_scene(PROJECTILE)
    assert scene.name == "projectile" and scene.dt == 1e-3
    assert [body.name for body in scene.bodies] == ["ball"]
    assert len(scene.engine_specs) == 6


def test_load_scene_refuses_a_bad_scene_with_every_problem(tmp_path):
    bad = tmp_path / "bad.yaml"
    bad.write_text(BAD_SCENE)
    with pytest.raises(physval.InputError) as refused:
        physval.load_scene(bad)
    (line,) = refused.value.problems
    assert line.startswith(f"{bad}:3:") and "bodies[0].shape.radius" in line, line
    with pytest.raises(physval.InputError, match="cannot read the file"):
        physval.load_scene(tmp_path / "missing.yaml")


def test_check_returns_every_problem_without_printing(tmp_path, capsys):
    assert physval.check(BUNDLED_SCENARIOS / "formulas") == []
    (tmp_path / "bad.yaml").write_text(BAD_SCENE)
    for folder in ("one", "two"):  # two scenes named "tight"
        (tmp_path / folder).mkdir()
        (tmp_path / folder / "tight.yaml").write_text(TOO_TIGHT)
    problems = physval.check([tmp_path])
    found = {(Path(p.file).relative_to(tmp_path), p.path) for p in problems if not p.warning}
    expected = {(Path("bad.yaml"), "bodies[0].shape.radius"), (Path("two/tight.yaml"), "name")}
    assert found == expected, problems
    assert all(str(p).startswith(p.file) for p in problems)
    printed = capsys.readouterr()
    assert printed.out == "" and printed.err == "", printed


def test_check_refuses_a_missing_path_and_an_empty_folder(tmp_path):
    with pytest.raises(physval.InputError) as refused:
        physval.check([tmp_path / "nope", tmp_path / "gone"])
    assert refused.value.problems == [
        f"{tmp_path / 'nope'}: no such file or folder",
        f"{tmp_path / 'gone'}: no such file or folder",
    ]
    with pytest.raises(physval.InputError, match=r"no \.yaml files found"):
        physval.check(tmp_path)


def test_import_physval_and_check_stay_light():
    """``import physval`` and ``check`` import neither pandas nor an engine (as ``physval
    check``): a notebook that only checks scenes pays for the scene loader only."""
    code = (
        "import sys, physval; physval.check(sys.argv[1]); physval.load_scene(sys.argv[1]);"
        "heavy = ('pandas', 'mujoco', 'pybullet', 'matplotlib', 'sqlalchemy', 'scipy');"
        "print(sorted(m for m in heavy if m in sys.modules))"
    )
    done = subprocess.run(
        [sys.executable, "-c", code, str(PROJECTILE)],
        capture_output=True,
        text=True,
        check=True,
        env={**os.environ, "PYTHONPATH": str(ROOT)},
    )
    assert done.stdout.strip() == "[]", done.stdout + done.stderr


def test_the_notebook_example_runs(tmp_path):
    """docs/examples/python_api.py, run whole as its first cell says."""
    done = subprocess.run(
        [sys.executable, str(NOTEBOOK)],
        capture_output=True,
        text=True,
        cwd=tmp_path,
        env={**os.environ, "PYTHONPATH": str(ROOT), "TMPDIR": str(tmp_path)},
        check=False,
    )
    assert done.returncode == 0, done.stderr
    assert "True" in done.stdout and "did you mean 'mujoco'?" in done.stdout, done.stdout
