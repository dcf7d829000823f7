"""``physval check``: validate scenario files and folders, print every problem."""

from __future__ import annotations

import os
import sys
from dataclasses import dataclass
from pathlib import Path

from validation.contract import EXIT_BAD_INPUT, EXIT_OK
from validation.jobs.plan import BadInputError, duplicate_problem
from validation.scenario import Problem, check_scenario, scenario_files
from validation.scenario.problems import printable


def _counted(count: int, noun: str) -> str:
    """``1 file``, ``2 files``, ``0 warnings``."""
    return f"{count} {noun}{'' if count == 1 else 's'}"


@dataclass
class Checked:
    """What checking the files under some paths found.

    Attributes:
        files: how many scenario files were read. invalid: how many of them cannot run.
        problems: every problem of every file, warnings included, in file order.
    """

    files: int
    invalid: int
    problems: list[Problem]


def check_files(paths: list[Path]) -> Checked:
    """Every problem of the scenario files under ``paths`` (a name two files share too);
    ``BadInputError`` when a path does not exist or no ``.yaml`` file is found."""
    missing = [p for p in paths if not os.path.lexists(p)]  # a dangling link is read (refused)
    if missing:
        raise BadInputError("\n".join(f"{printable(p)}: no such file or folder" for p in missing))
    files = scenario_files(paths)
    if not files:
        raise BadInputError(f"{printable(', '.join(map(str, paths)))}: no .yaml files found")
    checked = Checked(len(files), 0, [])
    names: dict[str, Path] = {}
    for file in files:
        scenario, problems = check_scenario(file)
        duplicate = duplicate_problem(scenario, file, names) if scenario is not None else None
        if duplicate:  # two files of one name would merge into one scene's rows
            problems = [duplicate, *problems]
            scenario = None
        checked.invalid += scenario is None
        checked.problems += problems
    return checked


def check_main(paths: list[Path]) -> int:
    """Print every problem of the files under ``paths``; 0 if all are valid, else 2."""
    try:
        checked = check_files(paths)
    except BadInputError as error:
        print(error, file=sys.stderr)
        return EXIT_BAD_INPUT
    for problem in checked.problems:
        print(problem, file=sys.stderr if not problem.warning else sys.stdout)
    warnings = sum(p.warning for p in checked.problems)
    print(
        f"{_counted(checked.files, 'file')}: {checked.files - checked.invalid} valid, "
        f"{checked.invalid} invalid, {_counted(warnings, 'warning')}"
    )
    return EXIT_OK if checked.invalid == 0 else EXIT_BAD_INPUT
