"""The nightly recipes in examples/ci/ are valid files whose every ``physval`` command the CLI
accepts, and each does the whole nightly: a baseline, JUnit, a kept history, published reports.
Each recipe's shell lines run, in order, in a fresh folder holding a tiny scene set and its
baseline (made by the README's commands, into folders that do not exist yet), with physval
already installed: they exit 0 and leave what the recipe publishes and caches."""

from __future__ import annotations

import shlex
import shutil
from pathlib import Path

import pytest
import yaml
from tiny_project import shell, tiny_project

from validation.cli import COMMANDS, parser

RECIPES = Path(__file__).resolve().parent.parent / "examples" / "ci"
SCRIPT_KEYS = ("run", "script", "before_script", "after_script")
"""Where a GitHub Actions step (``run``) or a GitLab job (``script``...) keeps its commands."""


def _commands(node) -> list[str]:
    """Every shell line under a script key of the parsed file."""
    found = []
    if isinstance(node, dict):
        for key, value in node.items():
            if key in SCRIPT_KEYS:
                lines = value if isinstance(value, list) else [value]
                found += [line for text in lines for line in str(text).splitlines()]
            else:
                found += _commands(value)
    elif isinstance(node, list):
        for item in node:
            found += _commands(item)
    return found


def _physval_commands(path: Path) -> list[list[str]]:
    lines = _commands(yaml.safe_load(path.read_text()))
    return [shlex.split(line)[1:] for line in lines if line.strip().startswith("physval ")]


ENGINE_EXTRAS = ("rapier", "drake")
"""The extras the README's baseline is made with: a recipe without them runs those engines as
``not_installed``, and the baseline's rows of them read ``missing``."""

PUBLISHED = ("reports/latest/report.html", "reports/junit.xml", "reports/history.html")
CACHED = "reports/history.sqlite"
"""What the recipes publish as artifacts and keep in the cache."""

BASELINE_COMMANDS = (
    "physval run --history none",
    "physval baseline save reports/latest --to baselines/default.csv",
)
"""The README's and the recipes' one-time commands that make the baseline to commit."""


def _installs(path: Path) -> list[list[str]]:
    lines = _commands(yaml.safe_load(path.read_text()))
    return [shlex.split(line) for line in lines if line.strip().startswith("pip install")]


@pytest.mark.parametrize("recipe", sorted(RECIPES.glob("*.yml")), ids=lambda p: p.name)
def test_every_physval_command_of_a_recipe_is_valid(recipe, capsys):
    commands = _physval_commands(recipe)
    assert commands, f"{recipe}: no physval command"
    for argv in commands:
        assert argv[0] in COMMANDS, argv
        try:
            parser().parse_args(argv)
        except SystemExit as refused:
            raise AssertionError(f"{recipe}: {argv}: {capsys.readouterr().err}") from refused
    runs = [argv for argv in commands if argv[0] == "run"]
    assert runs and all("--baseline" in a and "--junit" in a for a in runs), runs
    assert any(argv[0] == "history" for argv in commands), commands


@pytest.mark.parametrize("recipe", sorted(RECIPES.glob("*.yml")), ids=lambda p: p.name)
def test_a_recipe_keeps_the_history_and_publishes_the_report_and_junit(recipe):
    text = recipe.read_text()
    assert "reports/history.sqlite" in text and "cache" in text, recipe
    for published in ("reports/latest/", "reports/junit.xml", "reports/history.html"):
        assert published in text, (recipe, published)
    assert "when: always" in text or "if: always()" in text, recipe  # also when a run fails


def test_a_bad_flag_in_a_recipe_would_be_caught(tmp_path):
    broken = tmp_path / "broken.yml"
    broken.write_text("job:\n  script:\n    - physval run --basline baselines/default.csv\n")
    (argv,) = _physval_commands(broken)
    with pytest.raises(SystemExit):
        parser().parse_args(argv)


@pytest.mark.parametrize("recipe", sorted(RECIPES.glob("*.yml")), ids=lambda p: p.name)
def test_a_recipe_installs_every_engine_of_the_baseline(recipe):
    installs = _installs(recipe)
    assert installs, f"{recipe}: no pip install"
    for argv in installs:
        extras = {
            e for word in argv if "[" in word for e in word.split("[")[1].split("]")[0].split(",")
        }
        assert set(ENGINE_EXTRAS) <= extras, (recipe, argv)


@pytest.mark.parametrize("recipe", sorted(RECIPES.glob("*.yml")), ids=lambda p: p.name)
def test_a_recipe_saves_its_history_and_report_when_the_run_fails(recipe):
    parsed = yaml.safe_load(recipe.read_text())
    jobs = parsed.get("jobs", {}) if "jobs" in parsed else parsed
    for job in jobs.values():
        if not isinstance(job, dict):
            continue
        for kept in ("cache", "artifacts"):  # GitLab: saved only on success unless told
            if kept in job:
                assert job[kept].get("when") == "always", (recipe, kept)
        steps = job.get("steps", [])
        runs = [i for i, step in enumerate(steps) if "physval run" in str(step.get("run", ""))]
        for step in steps[runs[0] + 1 :] if runs else []:  # GitHub: after the run, always
            assert step.get("if") == "always()", (recipe, step.get("name"))


@pytest.mark.parametrize("recipe", sorted(RECIPES.glob("*.yml")), ids=lambda p: p.name)
def test_a_recipes_commands_run_in_a_fresh_project(recipe, tmp_path):
    tiny_project(tmp_path)
    for line in BASELINE_COMMANDS:  # on a fresh clone: no reports/, no baselines/
        done = shell(line, tmp_path)
        assert done.returncode == 0, f"{line}\n{done.stdout}\n{done.stderr}"
    assert (tmp_path / "baselines" / "default.csv").is_file()
    shutil.rmtree(tmp_path / "reports")  # a fresh runner: the committed files, the cache missed
    lines = _commands(yaml.safe_load(recipe.read_text()))
    ran = [line for line in lines if not line.strip().startswith("pip install")]  # installed
    assert any(line.strip().startswith("physval run") for line in ran), lines
    for line in ran:
        done = shell(line, tmp_path)
        assert done.returncode == 0, f"{recipe.name}: {line}\n{done.stdout}\n{done.stderr}"
    for path in (*PUBLISHED, CACHED):
        assert (tmp_path / path).is_file(), (recipe.name, path)


@pytest.fixture(scope="module")
def ran_once(tmp_path_factory) -> Path:
    """A project folder after one run: ``reports/latest`` and ``reports/history.sqlite``, and a
    file of the user's named ``taken``."""
    folder = tiny_project(tmp_path_factory.mktemp("ran"))
    done = shell("physval run --history sqlite:///reports/history.sqlite", folder)
    assert done.returncode == 0, done.stderr
    (folder / "taken").write_text(USERS_FILE)
    return folder


USERS_FILE = "the user's file\n"


@pytest.mark.parametrize(
    "line",
    [
        "physval run --history none --out reports/other --junit taken/reports/junit.xml",
        "physval run --history none --out taken/latest",
        "physval baseline save reports/latest --to taken/baselines/default.csv",
        "physval history --db reports/history.sqlite --out taken/history.html",
    ],
)
def test_a_missing_folder_is_made_but_a_file_in_its_place_is_refused(line, ran_once):
    done = shell(line, ran_once)
    assert done.returncode == 2 and "taken is a file" in done.stderr, done
    assert len(done.stderr.strip().splitlines()) == 1, done.stderr
    assert (ran_once / "taken").read_text() == USERS_FILE
