"""``physval check``: validate scenario files and folders, print every problem."""

from __future__ import annotations

import os
import sys
from pathlib import Path

from validation.contract import EXIT_BAD_INPUT, EXIT_OK
from validation.jobs.plan import duplicate_name
from validation.scenario import check_scenario, scenario_files
from validation.scenario.problems import printable


def _counted(count: int, noun: str) -> str:
    """``1 file``, ``2 files``, ``0 warnings``."""
    return f"{count} {noun}{'' if count == 1 else 's'}"


def check_main(paths: list[Path]) -> int:
    """Print every problem of the files under ``paths``; 0 if all are valid, else 2."""
    missing = [p for p in paths if not os.path.lexists(p)]  # a dangling link is read (refused)
    if missing:
        for path in missing:
            print(f"{printable(path)}: no such file or folder", file=sys.stderr)
        return EXIT_BAD_INPUT
    files = scenario_files(paths)
    if not files:
        print(f"{printable(', '.join(map(str, paths)))}: no .yaml files found", file=sys.stderr)
        return EXIT_BAD_INPUT
    invalid = warnings = 0
    names: dict[str, Path] = {}
    for file in files:
        scenario, problems = check_scenario(file)
        duplicate = duplicate_name(scenario, file, names) if scenario is not None else None
        if duplicate:  # two files of one name would merge into one scene's rows
            print(duplicate, file=sys.stderr)
            scenario = None
        invalid += scenario is None
        warnings += sum(p.warning for p in problems)
        for problem in problems:
            print(problem, file=sys.stderr if not problem.warning else sys.stdout)
    valid = len(files) - invalid
    print(
        f"{_counted(len(files), 'file')}: {valid} valid, {invalid} invalid, "
        f"{_counted(warnings, 'warning')}"
    )
    return EXIT_OK if invalid == 0 else EXIT_BAD_INPUT
