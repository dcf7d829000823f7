"""What ``physval run`` adds for the nightly job: known findings, the baseline, the
scenes' own sweeps as rows, JUnit XML and the history store.

Each function here is one phase of ``run._finish``; none runs an engine.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from pathlib import Path

import pandas as pd

from validation.contract import BASELINE_FILE, SWEEP_CROSS_CHECK, SWEEP_ERROR, SWEEP_ORDER
from validation.csv_safe import csv_text
from validation.files import file_target_problem, write_atomically
from validation.jobs.output import check_inside
from validation.jobs.plan import BadInputError, Plan
from validation.jobs.sweep import SWEEP_METRICS
from validation.nightly.baseline import (
    KEY,
    classify,
    missing_case_rows,
    read_baseline,
    scene_hash,
)
from validation.nightly.history import HistoryInputError, check_database, record_run, sqlite_file
from validation.nightly.junit import JUNIT_WRITTEN, write_junit
from validation.nightly.known import outcome_of
from validation.redact import shown_url
from validation.scenario import BUNDLED_SCENARIOS
from validation.scenario.engine_spec import parse_engine_spec, split_engine_list

DEFAULT_BASELINE = Path("baselines") / "default.csv"
"""The baseline a run compares against when the repository (the working folder) has one."""

HISTORY_FILE = "history.sqlite"
"""The default history database, next to the run folder (``reports/history.sqlite`` for a
default run)."""


@dataclass(frozen=True)
class NightlyOptions:
    """The run's nightly flags, checked before any work.

    Attributes:
        baseline: the baseline file, or None (no comparison).
        junit: where to write JUnit XML, or None.
        history: the history database URL, or None (not recorded).
    """

    baseline: Path | None = None
    junit: Path | None = None
    history: str | None = None
    baseline_table: pd.DataFrame | None = field(default=None, compare=False, repr=False)


def nightly_options(
    baseline: str | None, junit: str | None, history: str | None, destination: Path
) -> NightlyOptions:
    """The flags resolved and checked: the baseline read (``none`` turns the default off), the
    JUnit file's folder present, the history URL (``none``: not recorded; default: next to
    the run folder) recordable into (``_check_history``). BadInputError naming the flag
    otherwise."""
    path = _baseline_path(baseline)
    table = None
    if path is not None:
        try:
            table = read_baseline(path)
        except ValueError as error:
            raise BadInputError(f"--baseline: {error}") from None
    junit_path = None if junit is None else Path(junit)
    problem = junit_path and file_target_problem(junit_path, JUNIT_WRITTEN)
    if problem:
        raise BadInputError(f"--junit: {problem}")
    check_inside(destination, "--junit", junit_path)
    if history is None:
        url = f"sqlite:///{(destination.parent / HISTORY_FILE).resolve()}"
    else:
        url = None if history == "none" else history
    _check_history(url, given=history is not None, destination=destination)
    return NightlyOptions(path, junit_path, url, table)


def _check_history(url: str | None, given: bool, destination: Path) -> None:
    """The history database checked before any work (``history.check_database``: connected,
    the tables created and rolled back): a bad ``--history`` is exit 2, not a note after the
    run. An SQLite file may be in a folder the run makes (one that holds ``--out``: the
    default ``reports/history.sqlite``, or a CI cache's before its first run)."""
    if url is None:
        return
    made = tuple(destination.resolve().parents)
    try:
        check_inside(destination, "--history", sqlite_file(url, "--history"))
        check_database(url, "--history" if given else "the history database", made)
    except HistoryInputError as error:
        raise BadInputError(str(error)) from None


def _baseline_path(baseline: str | None) -> Path | None:
    if baseline == "none":
        return None
    if baseline is None:
        return DEFAULT_BASELINE if DEFAULT_BASELINE.is_file() else None
    path = Path(baseline)
    if not path.is_file():
        raise BadInputError(f"--baseline: {path}: no such file")
    return path


PROJECT_ROOT = BUNDLED_SCENARIOS.parent
"""Paths inside the project are recorded relative to it (``scenarios``, whatever the checkout's
folder), so the nightly of two checkouts or CI workspaces has one selection."""


def selection_path(path: str, cwd: str) -> str:
    """One PATH of a run as its selection records it: relative to the project when inside it,
    else absolute; POSIX separators, no trailing slash (``scenarios/`` is ``scenarios``)."""
    resolved = (Path(cwd) / path).resolve()
    try:
        return resolved.relative_to(PROJECT_ROOT).as_posix() or "."
    except ValueError:
        return resolved.as_posix()


def run_selection(
    paths: list[str], cwd: str, only: str | None, engines: str | None, dt: float | None, plan: Plan
) -> dict:
    """What a run selected, normalised, for provenance.json and the history (its key tells
    the nightly's runs from a scene author's): the paths (sorted, ``selection_path``), the
    ``--only`` glob, the ``--engines`` labels (sorted; None: each scene's own), ``--dt`` (None:
    each scene's) and whether the scenes' sweeps ran. Spelling does not count: ``--engines
    "mujoco( integrator = RK4 ), mini"`` and ``"mini,mujoco(integrator=RK4)"`` are one."""
    labels = None
    if engines is not None:
        labels = sorted({parse_engine_spec(text).label for text in split_engine_list(engines)})
    return {
        "paths": sorted({selection_path(path, cwd) for path in paths}),
        "only": only,
        "engines": labels,
        "dt": None if dt is None else float(dt),
        "sweeps": bool(plan.sweeps),
    }


def scene_hashes(plan: Plan) -> dict[str, dict[str, str]]:
    """Scene name -> its file and the sha256 of its bytes, read when the run is written."""
    return {
        scene.name: {"file": scene.scenario.source, "sha256": scene_hash(scene.scenario.source)}
        for scene, _ in plan.scenes
    }


def against_baseline(
    rows: list[dict],
    options: NightlyOptions,
    hashes: dict[str, dict[str, str]],
    folder: Path,
    selection: dict | None = None,
) -> tuple[list[dict], pd.DataFrame | None]:
    """The rows with their ``baseline`` class, and ``baseline.csv`` (every class, the missing
    rows too, each with the baseline's value and error), written into the run folder and
    returned; the rows unchanged and None without a baseline. ``selection``
    (``run_selection``): its ``--engines`` labels (None: every engine) are the engines whose
    baseline rows the run must have, and their sweep rows when it ``sweeps``."""
    if options.baseline_table is None:
        return rows, None
    sha = {name: entry["sha256"] for name, entry in hashes.items()}
    selection = selection or {}
    classified, missing = classify(
        rows, options.baseline_table, sha, selection.get("engines"), selection.get("sweeps", True)
    )
    before = {_key(r): r for r in options.baseline_table.to_dict("records")}
    comparison = pd.DataFrame(
        [_comparison(row, before.get(_key(row), {})) for row in [*classified, *missing]]
    )
    write_atomically(folder / BASELINE_FILE, csv_text(comparison))
    return classified, comparison


def _key(row: dict) -> tuple[str, ...]:
    return tuple(str(row[k]) for k in KEY)


def _comparison(row: dict, before: dict) -> dict:
    """One line of baseline.csv: the row's key and class, its outcome, value and error in this
    run (empty for a missing row) and in the baseline."""
    present = row["baseline"] != "missing"
    return {
        **{k: row[k] for k in KEY},
        "baseline": row["baseline"],
        "outcome": outcome_of(row) if present else "",
        "value": row.get("value") if present else math.nan,
        "error": row.get("error") if present else math.nan,
        "baseline_outcome": before.get("outcome", ""),
        "baseline_value": before.get("value"),
        "baseline_error": before.get("error"),
    }


def write_ci_files(
    rows: list[dict], options: NightlyOptions, comparison: pd.DataFrame | None = None
) -> None:
    """JUnit XML, when asked for: the rows, and the baseline rows the run lacks (each a failure
    of its case, ``missing_case_rows``)."""
    if options.junit is not None:
        write_junit([*rows, *missing_case_rows(comparison)], options.junit)


def record_history(folder: Path, options: NightlyOptions) -> str:
    """The published run recorded in the history store; a note instead of a failure when the
    store cannot be written (the run folder is the record; the history is a convenience)."""
    if options.history is None:
        return ""
    try:
        run_id = record_run(folder, options.history)
    except Exception as error:  # a locked or unreachable database must not fail the run
        return f"history not recorded ({type(error).__name__}: {shown_url(error)})"
    return f"history run {run_id}"


def sweep_result_rows(sweep_rows: list[dict]) -> list[dict]:
    """results.csv rows of the scenes' sweeps: each fitted order, each point's error and each
    cross-check, with the columns of a result row; no tolerance, so they are tracked, not
    judged."""
    found = []
    for row in sweep_rows:
        metric = _sweep_metric(row)
        if metric is None:
            continue
        value = row.get("value")
        error = row.get("error", value)
        found.append(
            {
                "scenario": row["scenario"],
                "engine": row["engine"],
                "metric": metric,
                "value": value,
                "expected": 0.0 if row["metric"] in SWEEP_METRICS else math.nan,
                "expected_kind": row.get("expected_kind", ""),
                "error": error if row["metric"] in SWEEP_METRICS else math.nan,
                "tolerance": None,
                "passed": None,
                "status": row.get("status", "ok"),
                "dt": row.get("dt", math.nan),
                "steps": row.get("steps", math.nan),
                "wall_time_s": row.get("wall_time_s", math.nan),
                "engine_version": row.get("engine_version", ""),
                "settings": "",
                "message": row.get("message", ""),
                "band": 0.0,
            }
        )
    return found


def _sweep_metric(row: dict) -> str | None:
    """The result-row metric of one sweep row (None for rows that are not tracked)."""
    if row["metric"] == "convergence_order":
        return f"{SWEEP_ORDER}.{row['of']}"
    if row["metric"] == "reference_cross_check":
        return f"{SWEEP_CROSS_CHECK}.{row['of']}"
    accuracy = row.get("accuracy")
    if row["metric"] in SWEEP_METRICS and accuracy is not None and math.isfinite(float(accuracy)):
        return f"{SWEEP_ERROR}.{row['metric']}@accuracy={float(row['accuracy']):.3g}"
    if row["metric"] in SWEEP_METRICS:
        return f"{SWEEP_ERROR}.{row['metric']}@dt={float(row['dt']):.3g}"
    return None
