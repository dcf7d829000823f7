"""The nightly recipes in examples/ci/ are valid files whose every ``physval`` command the CLI
accepts, and each does the whole nightly: a baseline, JUnit, a kept history, published reports."""

from __future__ import annotations

import shlex
from pathlib import Path

import pytest
import yaml

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
