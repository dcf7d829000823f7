"""physval's Python API: the ``physval`` command's work from a notebook or an engine's own tests.

- ``run(scenes, engines=None, out=None)``: a ``physval run`` of the scenes (the same planning,
  isolated workers, rows, baseline classes and run folder: ``validation.jobs.run``), its rows
  returned as a pandas DataFrame in a ``Results``;
- ``load_scene(path)``: one scenario file, validated (``validation.scenario.Scenario``);
- ``check(paths)``: every problem of the scenario files under ``paths``, as ``physval check``
  finds them.

Nothing prints and nothing exits: input physval refuses (a scene that does not validate, an
unknown engine, an ``out`` folder that is not physval's, a missing path) raises ``InputError``,
whose ``problems`` are the lines ``physval`` would print. ``import physval`` is light: each
function imports what it uses when it is called (``check`` and ``load_scene`` import neither
pandas nor an engine). See docs/python-api.md.
"""

from __future__ import annotations

import contextlib
import io
import os
import tempfile
from collections.abc import Iterable
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING

if TYPE_CHECKING:  # imported when a function runs (the module docstring)
    import pandas as pd

    from validation.scenario import Problem, Scenario

__all__ = ["InputError", "Results", "check", "load_scene", "run"]

PathLike = str | os.PathLike
"""A path: a ``str`` or a ``pathlib.Path``."""


class InputError(ValueError):
    """Input physval refuses, before any work: ``problems`` holds one line per problem, each
    naming the file (or argument), the field and what was expected, as ``physval`` prints them
    (the message is those lines joined)."""

    def __init__(self, problems: list[str]):
        super().__init__("\n".join(problems))
        self.problems = problems


@dataclass(frozen=True)
class Results:
    """What ``run`` gave.

    Attributes:
        rows: the run's rows, one per (scene, engine, metric), with results.csv's columns
            (``validation.contract.RESULTS_COLUMNS``): numbers parsed, ``passed`` True, False
            or None (no tolerance), ``baseline`` the row's class against a baseline.
        folder: the published run folder (``out``: results.csv, report.html, ...), or None
            when ``run`` was given no ``out`` (its files were written to a temporary folder,
            removed before ``run`` returned).
        exit_code: ``physval run``'s exit code: 0 nothing regressed and no new failure, 1 a
            regression or a new failure (``validation.contract``).
    """

    rows: pd.DataFrame
    folder: Path | None
    exit_code: int

    @property
    def passed(self) -> bool:
        """Whether the run passed as ``physval run`` judges it (exit code 0)."""
        return self.exit_code == 0


def run(
    scenes: PathLike | Iterable[PathLike],
    engines: str | Iterable[str] | None = None,
    out: PathLike | None = None,
    *,
    sweeps: bool = False,
    jobs: int = 1,
    baseline: PathLike | None = None,
    history: str | None = None,
) -> Results:
    """``physval run SCENES [--engines ENGINES] [--out OUT]``: each scene (a file or a folder
    of them) in each engine (a spec list as ``--engines`` takes it, ``"mini, mujoco"``, or an
    iterable of specs; default: each scene's own ``engines:``), measured and compared.

    ``out``: the run folder, published as ``physval run --out`` publishes it (a new path, an
    empty folder or an earlier run folder); None: the run is written to a temporary folder that
    is removed before this returns, so nothing is left on disk. ``sweeps``: also run the
    scenes' dt sweeps (``--sweeps on``). ``jobs``: worker processes (each job runs in one,
    so an engine that crashes is a ``crashed`` row, never this process's crash).
    ``baseline``: classify every row against this baseline file (default: none). ``history``:
    record the run in this history database URL (default: not recorded). Nothing is printed.

    Raises ``InputError`` for input ``physval run`` refuses with exit 2 (before any work);
    ``OSError`` when the run folder cannot be written."""
    from validation.contract import RESULTS_COLUMNS, RESULTS_FILE
    from validation.jobs.plan import BadInputError
    from validation.jobs.run import run_main
    from validation.report.read import read_results

    if isinstance(jobs, bool) or not isinstance(jobs, int) or jobs < 1:
        raise InputError([f"jobs: expected a whole number >= 1; got {jobs!r}"])
    paths = [Path(scenes)] if isinstance(scenes, PathLike) else [Path(s) for s in scenes]
    specs = engines if engines is None or isinstance(engines, str) else ", ".join(engines)
    argv = _argv(paths, specs, out, sweeps, baseline, history)
    with contextlib.ExitStack() as stack:
        folder = (
            Path(stack.enter_context(tempfile.TemporaryDirectory(prefix="physval-"))) / "run"
            if out is None
            else Path(out)
        )
        quiet = io.StringIO()  # the matrix, the news, the progress lines: a notebook reads rows
        stack.enter_context(contextlib.redirect_stdout(quiet))
        stack.enter_context(contextlib.redirect_stderr(quiet))
        try:
            code = run_main(
                paths,
                specs,
                folder,
                None,
                None,
                argv,
                jobs,
                baseline="none" if baseline is None else str(baseline),
                history="none" if history is None else history,
                sweeps=sweeps,
                raise_refusals=True,
            )
        except BadInputError as error:
            raise InputError(str(error).split("\n")) from None
        rows = read_results(folder / RESULTS_FILE)[list(RESULTS_COLUMNS)]
    return Results(rows, None if out is None else folder, code)


def _argv(
    paths: list[Path],
    engines: str | None,
    out: PathLike | None,
    sweeps: bool,
    baseline: PathLike | None,
    history: str | None,
) -> list[str]:
    """The ``physval run`` command line that does what ``run`` was asked (provenance.json and
    the history name it)."""
    argv = ["run", *map(str, paths), "--sweeps", "on" if sweeps else "off"]
    flags = {"--engines": engines, "--out": out, "--baseline": baseline, "--history": history}
    for flag, value in flags.items():
        if value is not None:
            argv += [flag, str(value)]
    return argv


def load_scene(path: PathLike) -> Scenario:
    """The validated scenario at ``path`` (``validation.scenario.Scenario``: its bodies,
    ``dt``, ``duration``, ``engines``, ``expect``, ``checks``, ...); its warnings are issued as
    ``ScenarioWarning``. Raises ``InputError`` with every problem when it does not validate
    (or the file cannot be read)."""
    from validation.scenario import ScenarioError, load_scenario

    try:
        return load_scenario(path)
    except ScenarioError as error:
        raise InputError([str(problem) for problem in error.problems]) from None


def check(paths: PathLike | Iterable[PathLike]) -> list[Problem]:
    """Every problem of the scenario files under ``paths`` (files or folders), warnings
    included, as ``physval check`` finds them: each a ``validation.scenario.Problem`` (``file``,
    ``line``, ``column``, ``path`` the field, ``message``, ``warning``; ``str()`` is its
    line). An empty list: every file is valid. Raises ``InputError`` when a path does not exist
    or holds no ``.yaml`` file."""
    from validation.jobs.check import check_files
    from validation.jobs.plan import BadInputError

    found = [Path(paths)] if isinstance(paths, PathLike) else [Path(p) for p in paths]
    try:
        return check_files(found).problems
    except BadInputError as error:
        raise InputError(str(error).split("\n")) from None
