"""Phase 1 of report.html: read a run folder's record files, checked against the contract.

- ``results.csv`` (required): one row per (scenario, engine spec, metric);
- ``series.csv`` (optional): energy, linear and angular momentum over time;
- ``impacts.csv`` (optional): every kept impact (``impact_log``) with its requested and
  measured restitution;
- ``trace.csv`` (optional): the thin trace of each body's quantity under test;
- ``provenance.json`` (optional here, always written by the run): command, commit, machine,
  engine versions and settings.

A run folder may come from elsewhere (a CI cache, a downloaded artifact): its files are data.
None is followed through a symlink or read when it is not a regular file, provenance.json is
read only up to ``MAX_PROVENANCE_BYTES`` and checked field by field (``Provenance``). A
missing or unreadable results.csv and a malformed provenance.json raise
(``ReportInputError``: exit 2, one line); a malformed optional table becomes a warning
printed on the page.
"""

from __future__ import annotations

import errno
import json
import os
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd
import pydantic

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
    TRACE_COLUMNS,
    TRACE_FILE,
)
from validation.csv_safe import is_text_column, original, restored
from validation.files import open_regular, read_regular

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
    trace: pd.DataFrame | None = None
    warnings: list[str] = field(default_factory=list)


def _read_csv(path: Path, **options) -> pd.DataFrame:
    try:
        with open_regular(path) as handle:
            return pd.read_csv(handle, **options)
    except (pd.errors.ParserError, pd.errors.EmptyDataError, UnicodeDecodeError) as error:
        raise ReportInputError(f"{path.name}: cannot be read as CSV ({_one_line(error)})") from None
    except OSError as error:  # missing, a symlink, a folder of that name, permissions, an I/O error
        raise ReportInputError(f"{path.name}: cannot be read ({_why(error)})") from None


def _one_line(error: Exception) -> str:
    """An error's message on one line (pandas' parser errors end with a newline)."""
    return " ".join(str(error).split())


def _why(error: OSError) -> str:
    """What an ``OSError`` of ``open_regular`` means for a run folder's file."""
    if error.errno == errno.ELOOP:
        return "a symlink; a run folder's files are never followed"
    return error.strerror or str(error)


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


def _restored_by_value(table: pd.DataFrame, text_columns: tuple[str, ...]) -> None:
    """``csv_safe.restored`` of ``text_columns`` (in place), each distinct text restored once:
    series.csv repeats a few scene and engine names over 200,000 rows, and restoring cell by
    cell was a tenth of the report's time. A column with a missing cell is restored cell by
    cell."""
    for name in (c for c in text_columns if c in table.columns):
        if not is_text_column(table[name]):
            continue
        codes, distinct = pd.factorize(table[name])
        if (codes < 0).any() or not all(isinstance(text, str) for text in distinct):
            restored(table, [name])
            continue
        table[name] = np.asarray([original(text) for text in distinct], dtype=object)[codes]


def _read_optional_table(
    path: Path, columns: tuple[str, ...], text_columns: tuple[str, ...], warnings: list[str]
) -> pd.DataFrame | None:
    """A table that may be absent; a malformed one becomes a warning on the page, not a crash
    (a symlink is refused: ``ReportInputError``)."""
    if not os.path.lexists(path):
        return None
    if path.is_symlink():
        raise ReportInputError(f"{path.name}: cannot be read ({_why(OSError(errno.ELOOP, ''))})")
    try:
        table = _read_csv(path, dtype=dict.fromkeys(text_columns, str), keep_default_na=False)
    except ReportInputError as error:
        warnings.append(str(error))
        return None
    missing = [c for c in columns if c not in table.columns]
    if missing:
        warnings.append(f"{path.name}: missing columns {', '.join(missing)}; not shown")
        return None
    _restored_by_value(table, text_columns)
    for column in columns:
        if column not in text_columns:
            table[column] = pd.to_numeric(table[column], errors="coerce")
    return table


MAX_PROVENANCE_BYTES = 16 * 1024 * 1024
"""provenance.json larger than this is refused unread: the library's run writes about 0.1 MB
(every engine spec's settings and one hash per scene), so 16 MiB is over 100 times that."""


class _Strict(pydantic.BaseModel):
    """Fields of their declared type (no coercion); other fields allowed (newer runs)."""

    model_config = pydantic.ConfigDict(strict=True, extra="allow")


class EngineProvenance(_Strict):
    """One engine spec's entry of provenance.json (``run._provenance``)."""

    engine: str = ""
    version: str = ""
    settings: dict[str, Any] | str = {}
    notes: list[str] = []


class SceneHash(_Strict):
    """One scene's entry of provenance.json: its file and the sha256 of its bytes."""

    file: str = ""
    sha256: str = ""


class Provenance(_Strict):
    """provenance.json as the pages, ``compare`` and ``baseline save`` read it: every field
    optional (runs of earlier versions lack some), each of its type when present."""

    command: str = ""
    git_commit: str = ""
    created: str = ""
    machine: dict[str, str | int | float | bool | None] = {}
    engines: dict[str, EngineProvenance] = {}
    scenes: dict[str, SceneHash] = {}
    selection: dict[str, Any] | None = None
    resumed: dict[str, int] | None = None


def read_provenance(path: Path, warnings: list[str]) -> dict[str, Any] | None:
    """provenance.json as a dict, every field checked (``Provenance``); None with a warning
    when absent. ``ReportInputError`` (one line naming the field) when it is not a regular
    file, too large, not JSON or not of the run's layout."""
    if not os.path.lexists(path):
        warnings.append(f"{path.name}: missing; engine versions and settings come from results.csv")
        return None
    try:
        data = read_regular(path, MAX_PROVENANCE_BYTES)
        Provenance.model_validate_json(data)
        return json.loads(data)
    except pydantic.ValidationError as error:
        first = error.errors()[0]
        where = ".".join(str(part) for part in first["loc"])
        raise ReportInputError(
            f"{path.name}: {where + ': ' if where else ''}{first['msg']}"
        ) from None
    except OSError as error:
        raise ReportInputError(f"{path.name}: cannot be read ({_why(error)})") from None
    except (ValueError, RecursionError) as error:
        raise ReportInputError(f"{path.name}: cannot be read ({_one_line(error)})") from None


def load_run(run_dir: Path) -> RunData:
    """Read every record file of ``run_dir``; only a missing or broken results.csv raises."""
    results_path = run_dir / RESULTS_FILE
    if not os.path.lexists(results_path):
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
    run.trace = _read_optional_table(
        run_dir / TRACE_FILE,
        TRACE_COLUMNS,
        ("scenario", "engine", "body", "quantity"),
        run.warnings,
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
