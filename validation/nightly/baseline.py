"""Baselines: a reviewed record of a run, and every later row classified against it.

``physval baseline save RUN_DIR --to FILE`` writes, per row of the run, its key (scenario,
engine spec, metric), value, error, tolerance, status and outcome, the engine's version and
the scene file's content hash, as CSV (reviewed in a pull request like code).
``physval run --baseline FILE`` classifies every row of the new run:

- ``scene_changed``: the scene file's hash differs (the numbers may move; not a regression);
- ``new``: the baseline has no such row; ``missing``: the baseline's row is not in the run
  (a row of a scene the run ran, in an engine it asked for: with ``--engines`` the engines it
  names, else every engine of the baseline, so an engine that reads ``not_installed`` or is
  absent now leaves its rows missing; an engine left out of ``--engines`` is absent on purpose);
- ``regressed`` / ``improved`` / ``changed`` / ``unchanged``: decided by the noise rule
  (``validation.measure.noise.classify_change``, the one rule of baseline, compare and history):
  the verdict got worse / better (passed -> failed, ok -> unstable), or the error moved beyond
  noise up / down (finite -> inf up, inf -> finite down, a lost error up), or (regressed) its
  size held while its sign or direction moved beyond noise; a row without an error (a fitted
  order, a cross-check) whose value moved is ``changed``;
- ``reference_moved``: a ``divergence`` row that moved because only its scene's reference
  engine moved (``noise.attribute_divergence``). A divergence row reaches the baseline already
  judged on its pair (``comparator.judge_divergence``): one whose reference alone is off its
  closed forms is not judged, so it is never a failure, new or not, of the other engine.

The run fails (exit 1) on a regression, a ``changed`` row, a ``missing`` row or a *new
failure*: a failing row (bad status, not a known finding) that the baseline does not have
failing too.
"""

from __future__ import annotations

import hashlib
import math
import sys
from collections.abc import Iterable
from pathlib import Path

import numpy as np
import pandas as pd

from validation.contract import (
    BASELINE_CLASSES,
    EXIT_BAD_INPUT,
    EXIT_OK,
    PROVENANCE_FILE,
    RESULTS_FILE,
    RUN_FAILURE_STATUSES,
    SIGNED_COLUMNS,
    SIGNED_ERROR_COLUMN,
    SWEEP_CROSS_CHECK,
    SWEEP_ERROR,
    SWEEP_ORDER,
    VECTOR_ERROR_COLUMNS,
)
from validation.csv_safe import csv_text, restored
from validation.files import csv_written, file_target_problem, write_atomically
from validation.measure.noise import (
    FAILS_A_RUN,
    Reading,
    attribute_divergence,
    classify_change,
    floor_for,
)
from validation.nightly.cases import MISSING
from validation.nightly.known import FIXED, KNOWN, outcome_of
from validation.report.read import ReportInputError, read_provenance, read_results

KEY = ("scenario", "engine", "metric")
"""What identifies a row across runs."""

SWEEP_ROWS = (SWEEP_ORDER, SWEEP_ERROR, SWEEP_CROSS_CHECK)
"""How the metrics of a scene's sweep rows begin (``nightly_run.sweep_result_rows``): a run
that did not sweep lacks them on purpose."""

BASELINE_COLUMNS = (
    *KEY,
    "value",
    "error",
    "tolerance",
    "status",
    "outcome",
    "engine_version",
    "scene_sha256",
    *SIGNED_COLUMNS,
)
"""The columns of a baseline file, in order (CI jobs and reviewers read them); the signed
error's (``SIGNED_COLUMNS``) may be absent from a baseline saved before they existed."""

REQUIRED_COLUMNS = tuple(c for c in BASELINE_COLUMNS if c not in SIGNED_COLUMNS)
"""What a file must have to be a baseline."""

BASELINE_WRITTEN = csv_written("a physval baseline", REQUIRED_COLUMNS)
"""How a baseline file begins (its header, the signed columns last): ``--to`` replaces only a
file that does."""

CLASSES = BASELINE_CLASSES
"""Every class a row can get against a baseline, the news first (``validation.contract``)."""

VERDICT_RANK = {
    **dict.fromkeys(RUN_FAILURE_STATUSES, 0),
    "failed": 1,
    KNOWN: 1,
    "unsupported": 2,
    "not_installed": 2,
    "no_tolerance": 2,
    "passed": 3,
    FIXED: 3,
}
"""How good a row's verdict is (higher is better): a move between ranks is always news; a
known failure is as bad as a failure (the baseline compares physics, not paperwork)."""

FAILING = (*RUN_FAILURE_STATUSES, "failed")
"""Outcomes that fail a run when they are new (a ``known`` row never does)."""


def scene_hash(path: str | Path) -> str:
    """sha256 of a scene file's bytes ('' when it cannot be read: then it never matches)."""
    try:
        return hashlib.sha256(Path(path).read_bytes()).hexdigest()
    except OSError:
        return ""


def baseline_table(results: pd.DataFrame, scene_hashes: dict[str, str]) -> pd.DataFrame:
    """The baseline record of a run's ``results`` (results.csv) with each scene's hash."""
    table = results.copy()
    table["outcome"] = [outcome_of(row) for _, row in table.iterrows()]
    table["scene_sha256"] = [scene_hashes.get(scene, "") for scene in table["scenario"]]
    return table.reindex(columns=list(BASELINE_COLUMNS))


def read_baseline(path: Path) -> pd.DataFrame:
    """A baseline file, its text cells as written (``csv_safe.restored``); ValueError naming
    the file and what is wrong when it is not one (columns missing, a key on two rows)."""
    try:
        text = dict.fromkeys((*KEY, "scene_sha256", "engine_version"), str)  # "3.10" is no 3.1
        table = pd.read_csv(path, dtype=text, keep_default_na=False)
    except (OSError, pd.errors.ParserError, pd.errors.EmptyDataError, UnicodeDecodeError) as error:
        raise ValueError(f"{path}: not a readable baseline CSV ({error})") from None
    absent = [c for c in REQUIRED_COLUMNS if c not in table.columns]
    if absent:
        raise ValueError(f"{path}: not a baseline: columns {', '.join(absent)} are missing")
    for column in SIGNED_COLUMNS:  # a baseline saved before the signed error was recorded
        if column not in table.columns:
            table[column] = ""
    for column in ("value", "error", "tolerance", *SIGNED_COLUMNS):
        table[column] = pd.to_numeric(table[column], errors="coerce")
    return _one_row_per_key(restored(table), path)


def _one_row_per_key(table: pd.DataFrame, path: Path) -> pd.DataFrame:
    """``table``, or ValueError naming the first key (``KEY``) that has two rows and their
    lines: which of two rows would a run be classified against?"""
    twice = table[table.duplicated(list(KEY), keep=False)]
    if twice.empty:
        return table
    keys = list(zip(*(twice[k] for k in KEY), strict=True))
    key = keys[0]
    lines = [i + 2 for i, found in zip(twice.index, keys, strict=True) if found == key]  # 1: header
    raise ValueError(
        f"{path}: not a baseline: lines {', '.join(map(str, lines))} are all the row "
        f"({', '.join(map(str, key))}); a baseline has one row per (scenario, engine, metric)"
    )


def _number(value: object) -> float:
    try:
        return float(value)
    except (TypeError, ValueError):
        return math.nan


def signed_error(row: dict) -> np.ndarray | None:
    """A row's signed error: (3,) components, (1,) a scalar, or None when it has none."""
    vector = np.array([_number(row.get(c)) for c in VECTOR_ERROR_COLUMNS])
    if np.isfinite(vector).all():
        return vector
    scalar = _number(row.get(SIGNED_ERROR_COLUMN))
    return np.array([scalar]) if math.isfinite(scalar) else None


def reading(row: dict, outcome: str) -> Reading:
    """A results or baseline row as the noise rule reads it, its verdict ``outcome``."""
    return Reading(
        error=_number(row.get("error")),
        value=_number(row.get("value")),
        signed=signed_error(row),
        rank=VERDICT_RANK.get(outcome, 0),
        verdict=outcome,
    )


def classify_row(now: dict, before: dict | None, scene_sha256: str) -> str:
    """The class of one row of the run against its baseline row (``before``, None if absent),
    divergence attribution aside (``classify``)."""
    if before is None:
        return "new"
    if before["scene_sha256"] != scene_sha256:
        return "scene_changed"
    was = reading(before, str(before["outcome"]))
    floor = floor_for(now.get("scenario"), now.get("metric"))
    return classify_change(was, reading(now, outcome_of(now)), floor)


def _lacked_on_purpose(row: dict, asked: set[str] | None, swept: bool) -> bool:
    """Whether a baseline row the run lacks was left out on purpose: its engine not among the
    ``asked`` ones, or a sweep row of a run that did not sweep."""
    if asked is not None and str(row["engine"]) not in asked:
        return True
    return not swept and str(row["metric"]).startswith(SWEEP_ROWS)


def classify(
    rows: list[dict],
    baseline: pd.DataFrame,
    scene_hashes: dict[str, str],
    asked: Iterable[str] | None = None,
    swept: bool = True,
) -> tuple[list[dict], list[dict]]:
    """The run's rows with a ``baseline`` class each, and the baseline's rows the run lacks
    (class ``missing``) for the scenes the run ran, in the engines it ``asked`` for (the
    ``--engines`` labels; None: every engine), sweep rows only when it ``swept``. A moved
    divergence row whose reference engine moved (and its own did not) reads
    ``reference_moved``."""
    index = {tuple(r[k] for k in KEY): r for r in baseline.to_dict("records")}
    classified = []
    for row in rows:
        before = index.pop(tuple(str(row[k]) for k in KEY), None)
        sha = scene_hashes.get(str(row["scenario"]), "")
        version_moved = before is not None and str(before.get("engine_version", "")) != str(
            row.get("engine_version", "")
        )
        classified.append(
            {**row, "baseline": classify_row(row, before, sha), "version_moved": version_moved}
        )
    attributed = attribute_divergence(classified, "baseline")
    classified = [
        {k: v for k, v in {**row, "baseline": change}.items() if k != "version_moved"}
        for row, change in zip(classified, attributed, strict=True)
    ]
    ran = {str(r["scenario"]) for r in rows}
    wanted = None if asked is None else set(asked)
    missing = [
        {**r, "baseline": "missing"}
        for r in index.values()
        if r["scenario"] in ran and not _lacked_on_purpose(r, wanted, swept)
    ]
    return classified, missing


def is_new_failure(row: dict) -> bool:
    """A failing row (not a known finding) that the baseline did not have failing: new to it,
    or regressed into failure, or in a changed scene."""
    if outcome_of(row) not in FAILING:
        return False
    return row.get("baseline", "new") != "unchanged"


def missing_rows(comparison: pd.DataFrame | None) -> pd.DataFrame:
    """The ``missing`` rows of a run's baseline comparison (``baseline.csv``); none without a
    baseline."""
    if comparison is None or comparison.empty:
        return pd.DataFrame(columns=list(KEY))
    return comparison[comparison["baseline"] == "missing"]


def missing_case_rows(comparison: pd.DataFrame | None) -> list[dict]:
    """The ``missing`` rows of a run's baseline comparison as result rows of their (scene,
    engine) case, outcome ``missing`` (a failure of the case: ``cases.OUTCOME_KINDS``), for the
    JUnit XML."""
    return [
        {
            **{k: row[k] for k in KEY},
            "outcome": MISSING,
            "message": f"in the baseline ({row['baseline_outcome']}), not in this run",
        }
        for row in missing_rows(comparison).to_dict("records")
    ]


def missing_note(comparison: pd.DataFrame | None) -> str:
    """One line naming the (scene, engine) pairs whose baseline rows the run lacks, with their
    row counts (``missing against the baseline (fails the run; ...): drop · rapier (12 rows),
    ...``); empty when none."""
    missing = missing_rows(comparison)
    if missing.empty:
        return ""
    counts = missing.groupby(["scenario", "engine"], sort=True).size()
    named = ", ".join(f"{scene} · {engine} ({n} rows)" for (scene, engine), n in counts.items())
    return (
        f"missing against the baseline (fails the run; leave an engine out of --engines to "
        f"run without it on purpose): {named}"
    )


def exit_failed(rows: list[dict], comparison: pd.DataFrame | None = None) -> bool:
    """Whether the run fails (exit 1): a regression or a ``changed`` row (``FAILS_A_RUN``), a
    new failure, or a row of the baseline ``comparison`` that is missing (module docstring).
    Without a baseline every failing row counts as new."""
    if not missing_rows(comparison).empty:
        return True
    return any(row.get("baseline") in FAILS_A_RUN or is_new_failure(row) for row in rows)


def save_baseline(run_dir: Path, to: Path) -> int:
    """``physval baseline save RUN_DIR --to FILE``: the run's baseline record, written
    atomically (missing folders of ``FILE`` created); the number of rows. ValueError naming
    the file when the run cannot be read, or when ``FILE`` is in the run folder (a run
    replaces that whole) or a file that is not a baseline physval wrote (``BASELINE_WRITTEN``:
    never overwritten)."""
    inputs = (run_dir / RESULTS_FILE, run_dir / PROVENANCE_FILE)
    problem = file_target_problem(to, BASELINE_WRITTEN, inputs)
    if problem is None and run_dir.resolve() in to.resolve().parents:
        problem = f"{to} is inside the run folder {run_dir}, which a run replaces whole"
    if problem:
        raise ValueError(f"--to: {problem}")
    try:
        results = read_results(run_dir / RESULTS_FILE)
        provenance = read_provenance(run_dir / PROVENANCE_FILE, [])
    except ReportInputError as error:
        raise ValueError(f"{run_dir}: {error}") from None
    except OSError as error:
        raise ValueError(f"{run_dir}: {RESULTS_FILE}: cannot be read ({error})") from None
    if provenance is None:  # the scenes' hashes are the baseline's
        raise ValueError(f"{run_dir / PROVENANCE_FILE}: missing (not a run folder)")
    scenes = provenance.get("scenes", {})
    hashes = {name: str(entry.get("sha256", "")) for name, entry in scenes.items()}
    table = baseline_table(results, hashes)
    write_atomically(to, csv_text(table))
    return len(table)


def baseline_main(action: str, run_dir: Path, to: Path) -> int:
    """The ``baseline`` command (one action, ``save``): exit 0, or 2 with one line."""
    try:
        count = BASELINE_ACTIONS[action](run_dir, to)
    except ValueError as error:
        print(error, file=sys.stderr)
        return EXIT_BAD_INPUT
    print(f"{count} rows -> {to} (review it in a pull request; physval run compares against it)")
    return EXIT_OK


BASELINE_ACTIONS = {"save": save_baseline}
"""``physval baseline ACTION``: what each action does (its names are the contract's
``BASELINE_ACTION_NAMES``, which the command line offers without importing this module)."""
