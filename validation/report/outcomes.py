"""Phase 2 of report.html: judge each row. What a row, a (scene, engine) cell and a summary
chip can be, worst first, and the colour each is drawn in."""

from __future__ import annotations

import math

import numpy as np
import pandas as pd

from validation.contract import (
    NOT_JUDGED_STATUSES,
    RESULTS_FILE,
    RUN_FAILURE_STATUSES,
    STATUS_DESCRIPTIONS,
)

OUTCOME_ORDER = (
    "error",
    "crashed",
    "timed_out",
    "model_mismatch",
    "unstable",
    "failed",
    "known",
    "fixed",
    "passed",
    "no_tolerance",
    "unsupported",
    "not_installed",
    "not_run",
)
"""Outcomes worst first; a cell shows the worst outcome of its rows."""

RUN_FAILURES = RUN_FAILURE_STATUSES
"""Outcomes that mean the engine produced no trustworthy numbers (the cell shows the word)."""

RED_OUTCOMES = (*RUN_FAILURES, "failed")
"""Outcomes that need a person's look (red, counted as offenders)."""

OUTCOME_LABELS = {
    "no_tolerance": "no tolerance",
    "not_run": "not run",
    "not_installed": "not installed",
}
"""Display words for outcomes that are not statuses of results.csv."""

# Cell and chip backgrounds: red needs a look, green passed, grey nothing was judged,
# near-white means the engine was not run on the scene. Pale so that black text stays legible.
RED, GREEN, GREY, BLANK = "#f3b3b0", "#b7e3bf", "#dedede", "#f7f7f7"
AMBER, BLUE = "#f6deb0", "#b9d5f2"
"""A known finding (expected, not news) and a fixed one (its entry can go)."""
OUTCOME_COLOURS = {
    "error": RED,
    "crashed": RED,
    "timed_out": RED,
    "model_mismatch": RED,
    "unstable": RED,
    "failed": RED,
    "known": AMBER,
    "fixed": BLUE,
    "passed": GREEN,
    "no_tolerance": GREY,
    "unsupported": GREY,
    "not_installed": GREY,
    "not_run": BLANK,
}


def outcome_label(outcome: str) -> str:
    """The word shown for an outcome (``no tolerance``, ``not run``, else the outcome)."""
    return OUTCOME_LABELS.get(outcome, outcome)


def row_outcome(status: str, passed: bool | None) -> str:
    """One row's outcome: a run failure or ``unsupported`` as such, else the check's verdict."""
    if status in (*RUN_FAILURES, *NOT_JUDGED_STATUSES):
        return status
    if status == "failed" or passed is False:
        return "failed"
    if passed is True:
        return "passed"
    return "no_tolerance" if status in ("ok", "") else "error"


def error_ratio(error: float, tolerance: float) -> float:
    """|error| / allowance, the allowance being tolerance + band (NaN when either is missing;
    a zero allowance gives 0 or inf)."""
    if not (math.isfinite(tolerance) and not math.isnan(error)):
        return math.nan
    if tolerance <= 0:
        return 0.0 if error == 0 else math.inf
    return abs(error) / tolerance


def classify_rows(results: pd.DataFrame, warnings: list[str]) -> pd.DataFrame:
    """Adds ``outcome`` (the record's own when it has one: known findings applied), ``ratio``
    (error/tolerance) and ``severity`` (0 = worst) per row."""
    table = results.copy()
    unknown = sorted(set(table["status"]) - set(STATUS_DESCRIPTIONS) - {""})
    if unknown:
        warnings.append(f"{RESULTS_FILE}: unknown status {', '.join(unknown)} (shown as error)")
    stated = table["outcome"] if "outcome" in table else [""] * len(table)
    table["outcome"] = [
        o if isinstance(o, str) and o in OUTCOME_ORDER else row_outcome(s, p)
        for o, s, p in zip(stated, table["status"], table["passed"], strict=True)
    ]
    table["ratio"] = [
        error_ratio(e, t + (0.0 if math.isnan(b) else b))
        for e, t, b in zip(table["error"], table["tolerance"], table["band"], strict=True)
    ]
    table["severity"] = [OUTCOME_ORDER.index(o) for o in table["outcome"]]
    return table


def worst_first(rows: pd.DataFrame) -> pd.DataFrame:
    """Rows sorted worst outcome first, then largest error/tolerance first."""
    negative_ratio = -rows["ratio"].fillna(-math.inf).to_numpy(float)
    severity = rows["severity"].to_numpy(int)
    return rows.iloc[np.lexsort((negative_ratio, severity))]  # stable: ties keep their order
