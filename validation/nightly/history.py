"""The history store: every recorded run and its rows, in a database opened from a URL.

An embedded SQLite file by default (``reports/history.sqlite``); a team may point ``--db`` at
a PostgreSQL server instead (``postgresql://user@host/physval``): the schema uses only types
SQLAlchemy maps on every dialect (integers, doubles, strings, booleans, JSON, timestamps) and
the queries are SQLAlchemy Core, nothing dialect-specific.

Tables (``METADATA``):

- ``runs``: one per recorded run folder: time (the run's ``created``), git commit, engine
  versions (label -> version), machine, command line, run folder, and ``complete``;
- ``series``: one per (scenario, engine spec, metric) ever recorded, so that the long names are
  stored once and not once per run (365 runs x 1,000 rows stay ~20 MB, see
  ``benchmarks/history_scale.py``);
- ``results``: one per row of a run's results.csv, keyed by run and series: value, expected,
  error, tolerance, passed, status, outcome and baseline class (when the run wrote them),
  engine version, dt.

Writing (``record_run``) is three steps, ``begin_run`` -> ``add_rows`` -> ``finish_run``, all
in ONE transaction: a writer killed at any point leaves no trace of its run (the database's
own journal rolls the transaction back). Readers see only ``complete`` runs, so per-job writes
(one transaction per ``add_rows``, as a kill-safe journal may want) can be added later without
changing any reader: an interrupted run then stays incomplete and invisible.
"""

from __future__ import annotations

import datetime as dt_module
import math
from collections.abc import Iterable
from dataclasses import dataclass
from fnmatch import fnmatch
from pathlib import Path

import numpy as np
import pandas as pd
import sqlalchemy as sa

from validation.contract import PROVENANCE_FILE, RESULTS_FILE
from validation.report.read import ReportInputError, read_provenance, read_results

DEFAULT_DATABASE = Path("reports") / "history.sqlite"
"""Where ``physval history`` and ``physval compare`` look when no ``--db`` is given."""

DEFAULT_URL = f"sqlite:///{DEFAULT_DATABASE}"

NAME_LENGTH = 200
"""Longest scenario, engine-spec or metric name stored (library names are under 60)."""

WORD_LENGTH = 32
"""Longest status, outcome or baseline class (the longest today, ``model_mismatch``, is 14)."""

VERSION_LENGTH = 64
"""Longest engine version or git commit (a SHA-256 commit is 64 hex digits)."""

OPTIONAL_COLUMNS = ("outcome", "baseline")
"""results.csv columns a run may carry (known findings, baseline classes): NULL when absent."""

METADATA = sa.MetaData()

RUNS = sa.Table(
    "runs",
    METADATA,
    sa.Column("id", sa.Integer, primary_key=True, autoincrement=True),
    sa.Column("created", sa.DateTime(timezone=True), nullable=True),
    sa.Column("commit", sa.String(VERSION_LENGTH), nullable=True),
    sa.Column("engine_versions", sa.JSON, nullable=False),
    sa.Column("machine", sa.JSON, nullable=False),
    sa.Column("command", sa.Text, nullable=False),
    sa.Column("folder", sa.Text, nullable=False),
    sa.Column("complete", sa.Boolean, nullable=False, default=False),
)

SERIES = sa.Table(
    "series",
    METADATA,
    sa.Column("id", sa.Integer, primary_key=True, autoincrement=True),
    sa.Column("scenario", sa.String(NAME_LENGTH), nullable=False),
    sa.Column("engine", sa.String(NAME_LENGTH), nullable=False),
    sa.Column("metric", sa.String(NAME_LENGTH), nullable=False),
    sa.UniqueConstraint("scenario", "engine", "metric"),
)

RESULTS = sa.Table(
    "results",
    METADATA,
    sa.Column("id", sa.Integer, primary_key=True, autoincrement=True),
    sa.Column("run_id", sa.ForeignKey("runs.id"), nullable=False, index=True),
    sa.Column("series_id", sa.ForeignKey("series.id"), nullable=False),
    sa.Column("value", sa.Double, nullable=True),
    sa.Column("expected", sa.Double, nullable=True),
    sa.Column("error", sa.Double, nullable=True),
    sa.Column("tolerance", sa.Double, nullable=True),
    sa.Column("passed", sa.Boolean, nullable=True),
    sa.Column("status", sa.String(WORD_LENGTH), nullable=False),
    sa.Column("outcome", sa.String(WORD_LENGTH), nullable=True),
    sa.Column("baseline", sa.String(WORD_LENGTH), nullable=True),
    sa.Column("engine_version", sa.String(VERSION_LENGTH), nullable=False),
    sa.Column("dt", sa.Double, nullable=True),
)

NUMBER_COLUMNS = ("value", "expected", "error", "tolerance", "dt")
"""Stored as doubles; NaN is stored as NULL (SQLite has no NaN) and read back as NaN."""

KEY_COLUMNS = ("scenario", "engine", "metric")


class HistoryInputError(ValueError):
    """A database URL, run folder or run id that cannot be used; exit code 2, one line."""


@dataclass(frozen=True)
class History:
    """Recorded runs, oldest first: every run's trend columns and the latest run's full rows."""

    runs: pd.DataFrame
    """id, created, commit, engine_versions (dict), machine (dict), command, folder."""
    trend: pd.DataFrame
    """Every row of every run: run_id, scenario, engine, metric, value, error, tolerance."""
    latest: pd.DataFrame
    """The latest run's rows: run_id, names and every ``results`` column; NULL numbers NaN."""


def database_url(text: str | Path | None) -> str:
    """``--db``: a URL as given, a bare path as an SQLite file, nothing as the default."""
    if text is None:
        return DEFAULT_URL
    text = str(text)
    return text if "://" in text else f"sqlite:///{text}"


def sqlite_file(url: str) -> Path | None:
    """The file of an ``sqlite:///`` URL (None for other dialects and in-memory databases)."""
    try:
        parsed = sa.engine.make_url(url)
    except sa.exc.ArgumentError as error:
        raise HistoryInputError(f"--db {url}: not a database URL ({error})") from None
    if parsed.get_backend_name() != "sqlite" or parsed.database in (None, "", ":memory:"):
        return None
    return Path(parsed.database)


def open_database(url: str, create: bool) -> sa.Engine:
    """An engine on ``url`` with the schema in place (``create``), or on an existing database.

    Reading never creates an empty SQLite file: a missing one is ``HistoryInputError``.
    """
    try:
        path = sqlite_file(url)
        if path is not None and not create and not path.is_file():
            raise HistoryInputError(f"{path}: no history database (physval run records one)")
        if path is not None:
            path.parent.mkdir(parents=True, exist_ok=True)
        engine = sa.create_engine(url)
        if create:
            METADATA.create_all(engine)
        elif not sa.inspect(engine).has_table(RUNS.name):
            raise HistoryInputError(f"{url}: not a physval history database (no runs table)")
    except (sa.exc.ArgumentError, sa.exc.NoSuchModuleError, ModuleNotFoundError) as error:
        raise HistoryInputError(f"--db {url}: not a usable database URL ({error})") from None
    except sa.exc.OperationalError as error:
        raise HistoryInputError(f"--db {url}: cannot open ({error.orig})") from None
    return engine


# --- writing -----------------------------------------------------------------------------


def _number(value: object) -> float | None:
    try:
        number = float(value)
    except (TypeError, ValueError):
        return None
    return None if math.isnan(number) else number


def _word(value: object) -> str | None:
    text = "" if value is None or (isinstance(value, float) and math.isnan(value)) else str(value)
    return text.strip() or None


def _created(provenance: dict, folder: Path) -> dt_module.datetime:
    """The run's time: provenance ``created``, else results.csv's modification time (UTC)."""
    try:
        return dt_module.datetime.fromisoformat(str(provenance["created"]))
    except (KeyError, ValueError):
        stamp = (folder / RESULTS_FILE).stat().st_mtime
        return dt_module.datetime.fromtimestamp(stamp, dt_module.UTC)


def run_record(folder: Path, provenance: dict) -> dict:
    """The ``runs`` row of a run folder (incomplete until ``finish_run``)."""
    engines = provenance.get("engines") or {}
    return {
        "created": _created(provenance, folder),
        "commit": provenance.get("git_commit"),
        "engine_versions": {label: str(info.get("version", "")) for label, info in engines.items()},
        "machine": provenance.get("machine") or {},
        "command": str(provenance.get("command", "")),
        "folder": str(folder.resolve()),
        "complete": False,
    }


def begin_run(connection: sa.Connection, record: dict) -> int:
    """Insert the ``runs`` row; returns its id. Invisible to readers until ``finish_run``."""
    return int(connection.execute(RUNS.insert().values(**record)).inserted_primary_key[0])


def _series_ids(connection: sa.Connection, keys: Iterable[tuple[str, str, str]]) -> dict:
    """(scenario, engine, metric) -> series id, inserting the keys not seen before."""
    known = {
        (scenario, engine, metric): series_id
        for series_id, scenario, engine, metric in connection.execute(
            sa.select(SERIES.c.id, SERIES.c.scenario, SERIES.c.engine, SERIES.c.metric)
        )
    }
    new = sorted(set(keys) - set(known))
    if new:
        connection.execute(
            SERIES.insert(), [dict(zip(KEY_COLUMNS, key, strict=True)) for key in new]
        )
        return _series_ids(connection, [])
    return known


def add_rows(connection: sa.Connection, run_id: int, results: pd.DataFrame) -> int:
    """Insert ``results`` (results.csv as read by ``read_results``) under ``run_id``; returns
    the number of rows. May be called once per finished job as well as once per run."""
    keys = list(zip(*(results[c].astype(str) for c in KEY_COLUMNS), strict=True))
    ids = _series_ids(connection, keys)
    optional = {c: results[c] if c in results else [None] * len(results) for c in OPTIONAL_COLUMNS}
    rows = [
        {
            "run_id": run_id,
            "series_id": ids[key],
            **{c: _number(results[c].iat[i]) for c in NUMBER_COLUMNS},
            "passed": results["passed"].iat[i],
            "status": _word(results["status"].iat[i]) or "",
            **{c: _word(optional[c][i]) for c in OPTIONAL_COLUMNS},
            "engine_version": _word(results["engine_version"].iat[i]) or "",
        }
        for i, key in enumerate(keys)
    ]
    if rows:
        connection.execute(RESULTS.insert(), rows)
    return len(rows)


def finish_run(connection: sa.Connection, run_id: int) -> None:
    """Mark the run complete: from now on readers see it."""
    connection.execute(RUNS.update().where(RUNS.c.id == run_id).values(complete=True))


def read_run_folder(folder: Path) -> tuple[pd.DataFrame, dict]:
    """A run folder's results.csv (parsed) and provenance.json (empty when absent)."""
    folder = Path(folder)
    if not folder.is_dir():
        raise HistoryInputError(f"{folder}: no such run folder")
    try:
        results = read_results(folder / RESULTS_FILE)
    except FileNotFoundError:
        raise HistoryInputError(f"{folder}: no {RESULTS_FILE} (not a physval run folder)") from None
    except ReportInputError as error:
        raise HistoryInputError(f"{folder}: {error}") from None
    provenance = read_provenance(folder / PROVENANCE_FILE, []) or {}
    return results, provenance


def record_run(folder: Path, url: str = DEFAULT_URL) -> int:
    """Record one run folder (results.csv + provenance.json) in the history at ``url``, in one
    transaction; returns the new run's id. Recording a folder twice records two runs."""
    folder = Path(folder)
    results, provenance = read_run_folder(folder)
    engine = open_database(url, create=True)
    try:
        with engine.begin() as connection:  # one transaction: all of the run or none of it
            run_id = begin_run(connection, run_record(folder, provenance))
            add_rows(connection, run_id, results)
            finish_run(connection, run_id)
    finally:
        engine.dispose()
    return run_id


# --- reading -----------------------------------------------------------------------------


def _runs_frame(connection: sa.Connection, query: sa.Select) -> pd.DataFrame:
    columns = [c for c in RUNS.c if c.name != "complete"]
    found = connection.execute(query.with_only_columns(*columns)).all()
    return pd.DataFrame(found, columns=[c.name for c in columns])


ROW_COLUMNS = (*NUMBER_COLUMNS, "passed", "status", *OPTIONAL_COLUMNS, "engine_version")
"""The ``results`` columns of a full row (with run_id and the series' names)."""

TREND_COLUMNS = ("value", "error", "tolerance")
"""The columns a trend needs from every run (engine versions come from ``runs``)."""


def _series_names(connection: sa.Connection, only: str | None) -> pd.DataFrame:
    """series_id and names of every series (``only``: those whose scenario matches the glob)."""
    names = pd.DataFrame(
        connection.execute(sa.select(SERIES.c.id, *(SERIES.c[k] for k in KEY_COLUMNS))).all(),
        columns=["series_id", *KEY_COLUMNS],
    )
    if only:
        names = names[[fnmatch(name, only) for name in names["scenario"]]]
    return names


def _fetch_rows(
    connection: sa.Connection, run_ids: list[int], columns: tuple[str, ...], only: str | None
) -> pd.DataFrame:
    """run_id, the series' names and ``columns`` of every row of ``run_ids``. Fetched as plain
    tuples into one numpy array per column: building a DataFrame of 365,000 rows from row
    objects costs seconds, and a year of history must render in 5."""
    names = _series_names(connection, only)
    query = (
        sa.select(RESULTS.c.run_id, RESULTS.c.series_id, *(RESULTS.c[c] for c in columns))
        .where(RESULTS.c.run_id.between(min(run_ids), max(run_ids)) if run_ids else sa.false())
        .order_by(RESULTS.c.run_id, RESULTS.c.id)
    )
    found = connection.execute(query).all()
    values = list(zip(*found, strict=True)) if found else [()] * (len(columns) + 2)
    frame = pd.DataFrame(
        {
            name: np.array(column, dtype=float if name in NUMBER_COLUMNS else object)
            for name, column in zip(("run_id", "series_id", *columns), values, strict=True)
        }
    )
    frame = frame[frame["run_id"].isin(run_ids) & frame["series_id"].isin(names["series_id"])]
    frame = frame.merge(names, on="series_id", how="left", sort=False)
    frame["run_id"] = frame["run_id"].astype(int)
    return frame[["run_id", *KEY_COLUMNS, *columns]].reset_index(drop=True)


def load_history(url: str, last: int | None = None, only: str | None = None) -> History:
    """The ``last`` complete runs (all when None), oldest first: the trend columns of every
    row, and the full rows of the latest run; ``only`` keeps the scenarios matching the glob."""
    engine = open_database(url, create=False)
    try:
        with engine.connect() as connection:
            newest = sa.select(RUNS).where(RUNS.c.complete).order_by(RUNS.c.id.desc())
            runs = _runs_frame(connection, newest.limit(last) if last else newest)
            runs = runs.iloc[::-1].reset_index(drop=True)
            run_ids = [int(i) for i in runs["id"]]
            trend = _fetch_rows(connection, run_ids, TREND_COLUMNS, only)
            latest = _fetch_rows(connection, run_ids[-1:], ROW_COLUMNS, only)
    finally:
        engine.dispose()
    return History(runs, trend, latest)


def load_run(url: str, run_id: int) -> History:
    """One complete run of the history (its rows as ``latest`` and ``trend``);
    ``HistoryInputError`` when there is no such run."""
    engine = open_database(url, create=False)
    try:
        with engine.connect() as connection:
            runs = _runs_frame(
                connection, sa.select(RUNS).where(RUNS.c.complete, RUNS.c.id == run_id)
            )
            if runs.empty:
                raise HistoryInputError(f"run {run_id}: no such run in {url}")
            rows = _fetch_rows(connection, [run_id], ROW_COLUMNS, None)
    finally:
        engine.dispose()
    return History(runs, rows[["run_id", *KEY_COLUMNS, *TREND_COLUMNS]], rows)
