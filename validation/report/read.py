"""Phase 1 of report.html: read a run folder's record files, checked against the contract.

- ``results.csv`` (required): one row per (scenario, engine spec, metric);
- ``series.csv`` (optional): energy, linear and angular momentum over time;
- ``impacts.csv`` (optional): every impact with its requested and measured restitution;
- ``provenance.json`` (optional here, always written by the run): command, commit, machine,
  engine versions and settings.

Only a missing or unreadable results.csv raises (``ReportInputError``); a malformed optional
file becomes a warning printed on the page.
"""

from __future__ import annotations

import json
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import pandas as pd

from validation.contract import (
    BASELINE_FILE,
    IMPACTS_COLUMNS,
    IMPACTS_FILE,
    PROVENANCE_FILE,
    RESULTS_COLUMNS,
    RESULTS_FILE,
    SERIES_COLUMNS,
    SERIES_FILE,
    SIGNED_COLUMNS,
    SWEEP_FILE,
)
from validation.csv_safe import restored

NUMERIC_RESULTS_COLUMNS = (
    "value",
    "expected",
    "error",
    "tolerance",
    "band",
    *SIGNED_COLUMNS,
    "dt",
    "steps",
    "wall_time_s",
)

OPTIONAL_RESULTS_COLUMNS = ("band", *SIGNED_COLUMNS, "outcome", "known", "baseline")

OPTIONAL_IMPACTS_COLUMNS = ("delta_e", "band")
"""impacts.csv columns added after its first version (derived again when absent)."""
"""Columns added to results.csv after its first version: empty when an older record lacks them."""
"""results.csv columns parsed as numbers; their raw text is kept in ``<column>_text``."""


class ReportInputError(ValueError):
    """The run folder cannot be rendered (no or unreadable results.csv); exit code 2."""


@dataclass
class RunData:
    """The record files of one run folder, read and checked."""

    run_dir: Path
    results: pd.DataFrame
    series: pd.DataFrame | None = None
    impacts: pd.DataFrame | None = None
    provenance: dict[str, Any] | None = None
    sweep: pd.DataFrame | None = None
    baseline: pd.DataFrame | None = None
    warnings: list[str] = field(default_factory=list)


def _read_csv(path: Path, **options) -> pd.DataFrame:
    try:
        return pd.read_csv(path, **options)
    except (pd.errors.ParserError, pd.errors.EmptyDataError, UnicodeDecodeError) as error:
        raise ReportInputError(f"{path.name}: cannot be read as CSV ({error})") from error
    except OSError as error:  # permissions, a folder of that name, an I/O error
        raise ReportInputError(f"{path.name}: cannot be read ({error.strerror or error})") from None


def _parse_passed(text: str) -> bool | None:
    word = text.strip().lower()
    return True if word in ("true", "1") else False if word in ("false", "0") else None


def read_results(path: Path) -> pd.DataFrame:
    """results.csv with numeric columns parsed, ``passed`` as True/False/None, and the raw
    text of value/expected/error/tolerance kept in ``<column>_text`` for display."""
    table = _read_csv(path, dtype=str, keep_default_na=False)
    for column in OPTIONAL_RESULTS_COLUMNS:  # record files written before the column existed
        if column not in table.columns:
            table[column] = ""
    missing = [c for c in RESULTS_COLUMNS if c not in table.columns]
    if missing:
        raise ReportInputError(f"{path.name}: missing columns {', '.join(missing)}")
    table = table.astype(object)
    restored(table, [c for c in table.columns if c not in NUMERIC_RESULTS_COLUMNS])
    for column in NUMERIC_RESULTS_COLUMNS:
        table[f"{column}_text"] = table[column].str.strip()
        table[column] = pd.to_numeric(table[column].str.strip(), errors="coerce")
    table["passed"] = [_parse_passed(text) for text in table["passed"]]
    table["status"] = table["status"].str.strip()
    return table


def _read_optional_table(
    path: Path, columns: tuple[str, ...], text_columns: tuple[str, ...], warnings: list[str]
) -> pd.DataFrame | None:
    """A table that may be absent; a malformed one becomes a warning on the page, not a crash."""
    if not path.is_file():
        return None
    try:
        table = _read_csv(path, dtype=dict.fromkeys(text_columns, str), keep_default_na=False)
    except ReportInputError as error:
        warnings.append(str(error))
        return None
    missing = [c for c in columns if c not in table.columns]
    if missing:
        warnings.append(f"{path.name}: missing columns {', '.join(missing)}; not shown")
        return None
    restored(table, text_columns)
    for column in columns:
        if column not in text_columns:
            table[column] = pd.to_numeric(table[column], errors="coerce")
    return table


def read_provenance(path: Path, warnings: list[str]) -> dict[str, Any] | None:
    """provenance.json as a dict, or None with a warning when absent or malformed."""
    if not path.is_file():
        warnings.append(f"{path.name}: missing; engine versions and settings come from results.csv")
        return None
    try:
        provenance = json.loads(path.read_text(encoding="utf-8"))
    except (json.JSONDecodeError, UnicodeDecodeError) as error:
        warnings.append(f"{path.name}: not valid JSON ({error})")
        return None
    except OSError as error:
        warnings.append(f"{path.name}: cannot be read ({error.strerror or error})")
        return None
    if not isinstance(provenance, dict):
        warnings.append(f"{path.name}: expected a JSON object")
        return None
    return provenance


def load_run(run_dir: Path) -> RunData:
    """Read every record file of ``run_dir``; only a missing or broken results.csv raises."""
    results_path = run_dir / RESULTS_FILE
    if results_path.exists() and not results_path.is_file():
        raise ReportInputError(f"{RESULTS_FILE}: not a regular file")
    if not results_path.is_file():
        raise ReportInputError(f"no {RESULTS_FILE} (not a physval run folder)")
    run = RunData(run_dir, read_results(results_path))
    run.series = _read_optional_table(
        run_dir / SERIES_FILE, SERIES_COLUMNS, ("scenario", "engine"), run.warnings
    )
    run.impacts = _read_optional_table(
        run_dir / IMPACTS_FILE,
        tuple(c for c in IMPACTS_COLUMNS if c not in OPTIONAL_IMPACTS_COLUMNS),
        ("scenario", "engine", "body_a", "body_b"),
        run.warnings,
    )
    run.provenance = read_provenance(run_dir / PROVENANCE_FILE, run.warnings)
    run.sweep = _read_optional_table(
        run_dir / SWEEP_FILE, SWEEP_READ_COLUMNS, SWEEP_TEXT_COLUMNS, run.warnings
    )
    run.baseline = _read_optional_table(
        run_dir / BASELINE_FILE, BASELINE_READ_COLUMNS, BASELINE_READ_COLUMNS, run.warnings
    )
    return run


SWEEP_READ_COLUMNS = (
    "scenario",
    "engine",
    "metric",
    "dt",
    "value",
    "error",
    "status",
    "wall_time_s",
)
SWEEP_TEXT_COLUMNS = ("scenario", "engine", "metric", "status")
"""sweep.csv (a run whose scenes declare ``sweep:``): the columns the scene cards draw."""

BASELINE_READ_COLUMNS = ("scenario", "engine", "metric", "baseline")
"""baseline.csv (a run against a baseline): the columns the news reads."""
