"""The README as a new user follows it: the two set-up commands are the ones CI runs, the first
scene is ten lines that ``physval check`` accepts and ``physval run`` passes in every engine, and
every ``physval`` command the README and the docs/ pages show is one the CLI accepts."""

from __future__ import annotations

import argparse
import re
import shlex
from pathlib import Path

import pandas as pd
import pytest

from validation.cli import main, parser
from validation.pytest_plugin import OPTION
from validation.scenario import check_scenario

ROOT = Path(__file__).resolve().parent.parent
README = ROOT / "README.md"
DOCS = sorted((ROOT / "docs").glob("*.md"))

SETUP_RUN = 'python3 -m venv .venv && . .venv/bin/activate && pip install -e ".[rapier]" && physval run'
SETUP_TEST = (
    'python3 -m venv .venv && . .venv/bin/activate && pip install -e ".[test,rapier]" && ruff check '
    ". && pytest"
)
"""The README's two set-up commands, byte for byte (``.ci/run`` runs the second's tail)."""

FIRST_SCENE_LINES = 10
"""The README promises a 10-line first scene."""

RUN_FILES = (
    "results.csv",
    "series.csv",
    "impacts.csv",
    "trace.csv",
    "provenance.json",
    "report.html",
)
"""What the README says the first scene's run folder holds."""

CODE_INDENT = "    "
"""A markdown indented code block's indent: the README's commands are written in such blocks."""


def first_scene(text: str) -> str:
    """The first ```yaml block after the README's "A first scene" heading."""
    section = text.split("## A first scene", 1)[1]
    return section.split("```yaml\n", 1)[1].split("```", 1)[0]


def code_commands(text: str, program: str) -> list[str]:
    """Every command of an indented code block that starts with ``program``, with its synopsis
    continuation lines (a code line that starts with ``[``) and shell continuations (a line
    ending in a backslash) joined to it."""
    commands: list[str] = []
    continued = False  # the previous line was a command's and ended in a backslash
    for line in text.splitlines():
        code = line.strip() if line.startswith(CODE_INDENT) else ""
        if continued and code:
            commands[-1] += " " + code
        elif code.startswith(program + " "):
            commands.append(code)
        elif code.startswith("[") and commands and commands[-1].startswith(program + " "):
            commands[-1] += " " + code
        else:
            continued = False
            continue
        continued = commands[-1].endswith("\\")
        if continued:
            commands[-1] = commands[-1][:-1].rstrip()
    return commands


def _argv(line: str) -> list[str]:
    return shlex.split(line, comments=True)[1:]


def _subcommand_options(name: str) -> set[str]:
    root = parser()
    (sub,) = [a for a in root._actions if isinstance(a, argparse._SubParsersAction)]
    return set(sub.choices[name]._option_string_actions)


def test_the_two_setup_commands_are_in_the_readme_and_ci_runs_the_test_command():
    readme = README.read_text()
    for command in (SETUP_RUN, SETUP_TEST):
        assert f"\n{CODE_INDENT}{command}\n" in readme, command
    ci_line = (ROOT / ".ci" / "run").read_text().strip().splitlines()[-1]
    assert SETUP_TEST.endswith(ci_line), (ci_line, SETUP_TEST)


def test_the_first_scene_is_ten_lines_that_check_accepts(tmp_path):
    block = first_scene(README.read_text())
    assert len(block.splitlines()) == FIRST_SCENE_LINES, block
    path = tmp_path / "first_bounce.yaml"
    path.write_text(block)
    scenario, problems = check_scenario(path)
    assert scenario is not None and not problems, [str(p) for p in problems]
    assert [e.metric for e in scenario.expect] == ["bounce_heights.ball"]
    assert set(scenario.checks) == {"restitution_error", "bounce_heights.ball"}
    assert [s.name for s in scenario.engine_specs] == ["mini", "mujoco", "pybullet"]


@pytest.mark.slow
def test_the_first_scene_runs_and_passes_in_every_engine(tmp_path, monkeypatch, capsys):
    """What the README says the run prints and writes: every checked row passes, exit 0."""
    monkeypatch.chdir(tmp_path)  # no baselines/default.csv of the working folder
    path = tmp_path / "first_bounce.yaml"
    path.write_text(first_scene(README.read_text()))
    out = tmp_path / "reports" / "mine"
    assert main(["run", str(path), "--out", str(out), "--jobs", "1"]) == 0
    printed = capsys.readouterr().out
    assert "first_bounce" in printed and "history run 1" in printed, printed
    rows = pd.read_csv(out / "results.csv")
    checked = rows[rows["tolerance"].notna()]
    assert set(checked["metric"]) == {"restitution_error", "bounce_heights.ball"}, checked
    assert set(checked["engine"]) == {"mini", "mujoco", "pybullet"}, checked
    failed = checked[checked["passed"] != True]  # noqa: E712 (NaN and False alike)
    assert failed.empty, failed[["engine", "metric", "value", "error", "tolerance"]]
    for name in RUN_FILES:
        assert (out / name).is_file(), name
    assert (tmp_path / "reports" / "history.sqlite").is_file()


def test_every_physval_command_of_the_readme_is_valid(capsys):
    commands = code_commands(README.read_text(), "physval")
    assert len(commands) >= 10, commands
    for line in [SETUP_RUN.rsplit("&& ", 1)[1], *commands]:
        argv = _argv(line)
        try:
            parser().parse_args(argv)
        except SystemExit as refused:
            raise AssertionError(f"README: {line}: {capsys.readouterr().err}") from refused


def test_the_readme_pytest_command_uses_the_plugin_option():
    (line,) = code_commands(README.read_text(), "pytest")
    assert _argv(line)[0] == OPTION, line


SYNOPSIS_OPTION = re.compile(r"(?<![\w-])--[a-z][a-z-]*")


@pytest.mark.parametrize("page", [README, *DOCS], ids=lambda p: p.name)
def test_every_flag_a_page_shows_for_a_command_exists(page):
    """Synopsis lines (``physval run [PATHS...] [--engines SPECS]``) name only real options."""
    commands = parser()._actions
    (sub,) = [a for a in commands if isinstance(a, argparse._SubParsersAction)]
    for line in code_commands(page.read_text(), "physval"):
        words = line.split()
        if words[1] not in sub.choices:
            assert words[1] == "--version", f"{page.name}: {line}"
            continue
        options = _subcommand_options(words[1])
        for flag in SYNOPSIS_OPTION.findall(line.split("#", 1)[0]):
            assert flag in options, f"{page.name}: {line}: {flag} is not a {words[1]} option"


def test_a_wrong_flag_in_a_synopsis_would_be_caught():
    line = "physval run [PATHS...] [--engine SPECS]"
    (flag,) = SYNOPSIS_OPTION.findall(line)
    assert flag not in _subcommand_options("run")
