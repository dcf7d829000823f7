"""The history store: every recorded run and its rows, in a database opened from a URL.

An embedded SQLite file by default (``reports/history.sqlite``); a team may point ``--db`` at
a PostgreSQL server instead (``postgresql://user@host/physval``): the schema uses only types
SQLAlchemy maps on every dialect (integers, doubles, strings, booleans, JSON, timestamps) and
the queries are SQLAlchemy Core, nothing dialect-specific.

Tables (``METADATA``):

- ``runs``: one per recorded run folder: time (the run's ``created``), git commit, engine
  versions (label -> version), machine, command line, run folder, ``complete``, and the run's
  selection (what it was asked to run: paths, ``--only``, ``--engines``, ``--dt``, whether
  sweeps ran; provenance.json's ``selection``) with its key (``selection_key``);
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

Migration: a column added to ``runs`` after its first version (``ADDED_RUN_COLUMNS``) is added
to an existing database by its next writer (``ALTER TABLE runs ADD COLUMN``, NULL for the runs
recorded before); a reader never writes, and reads a missing column as NULL. A run without a
(readable) selection has the key ``unrecorded``.

A database that cannot be read (a damaged page, text that is not UTF-8, a table without a
column physval reads) is one ``HistoryInputError`` line (``readable``). Everything read back
is checked, as any input is: numbers that are not numbers read as NaN,
JSON that is not the expected object reads as empty, a time that is not a time as none.
"""

from __future__ import annotations

import contextlib
import datetime as dt_module
import hashlib
import json
import math
import os
import re
from collections.abc import Iterable, Iterator
from dataclasses import dataclass
from fnmatch import fnmatch
from pathlib import Path

import numpy as np
import pandas as pd
import sqlalchemy as sa

from validation.contract import PROVENANCE_FILE, RESULTS_FILE
from validation.redact import shown_url
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

SELECTION_KEY_DIGITS = 8
"""Hex digits of a selection key (the sha256 of the canonical selection): 32 bits, so that even
1,000 distinct selections in one history collide with probability 1e-4 (n² / 2³³)."""

UNRECORDED = "unrecorded"
"""The selection key of a run recorded without a selection (by an earlier version), or whose
recorded selection is not a valid one."""

MAX_SELECTION_CHARS = 65536
"""Longest selection read back (its canonical JSON): a hundred paths are a few kilobytes; a
longer text is not a selection physval wrote."""

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
    sa.Column("selection", sa.JSON, nullable=True),
    sa.Column("selection_key", sa.String(SELECTION_KEY_DIGITS), nullable=True),
)

ADDED_RUN_COLUMNS = ("selection", "selection_key")
"""``runs`` columns added after the table's first version (databases written before them lack
them): added by the next writer, read as NULL until then."""

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
    """id, created, commit, engine_versions (dict), machine (dict), command, folder, selection
    (dict or None), selection_key (``UNRECORDED`` for None): the runs drawn."""
    trend: pd.DataFrame
    """Every row of every run: run_id, scenario, engine, metric, value, error, tolerance."""
    latest: pd.DataFrame
    """The latest run's rows: run_id, names and every ``results`` column; NULL numbers NaN."""
    recorded: pd.DataFrame | None = None
    """Every complete run of the history, drawn or not (the columns of ``runs``)."""
    selection: str = "all"
    """The selection drawn: its key, or ``all``."""


# --- selections ------------------------------------------------------------------------


def canonical_selection(selection: dict) -> str:
    """The selection as canonical JSON (sorted keys, no spaces): what its key hashes."""
    return json.dumps(selection, sort_keys=True, separators=(",", ":"), allow_nan=False)


def selection_key(selection: dict | None) -> str:
    """A short hash of the selection (``SELECTION_KEY_DIGITS`` hex digits), ``UNRECORDED`` for
    None: equal for two runs that selected the same work, however it was spelled."""
    if selection is None:
        return UNRECORDED
    digest = hashlib.sha256(canonical_selection(selection).encode("utf-8"))
    return digest.hexdigest()[:SELECTION_KEY_DIGITS]


def _selection_value(value: object) -> bool:
    """A value a selection may hold: None, a bool, a finite number, text, a list of text."""
    if value is None or isinstance(value, (bool, str)):
        return True
    if isinstance(value, (int, float)):
        return math.isfinite(value)
    return isinstance(value, list) and all(isinstance(item, str) for item in value)


SELECTION_TYPES = {
    "paths": (list,),
    "only": (str, type(None)),
    "engines": (list, type(None)),
    "dt": (int, float, type(None)),
    "sweeps": (bool,),
}
"""The entries ``physval run`` writes (``nightly_run.run_selection``) and their types; a
later version's other entries are kept as long as they are ``_selection_value``s."""


def _selection_entry(name: object, value: object) -> bool:
    if not isinstance(name, str) or not _selection_value(value):
        return False
    types = SELECTION_TYPES.get(name)
    if types is None:
        return True
    return isinstance(value, types) and not (name == "dt" and isinstance(value, bool))


def valid_selection(raw: object) -> dict | None:
    """A selection read back (a dict, or its JSON text), checked: an object of text keys whose
    values are ``_selection_value``s of the types of ``SELECTION_TYPES``, at most
    ``MAX_SELECTION_CHARS`` long; None otherwise."""
    if isinstance(raw, (str, bytes)):
        if len(raw) > MAX_SELECTION_CHARS:
            return None
        try:
            raw = json.loads(raw)
        except (ValueError, RecursionError):
            return None
    if not isinstance(raw, dict) or not all(_selection_entry(k, v) for k, v in raw.items()):
        return None
    try:
        text = canonical_selection(raw)
    except ValueError:
        return None
    return raw if len(text) <= MAX_SELECTION_CHARS else None


SELECTION_FLAGS = {"only": "--only", "engines": "--engines", "dt": "--dt"}
"""Selection entries shown as the ``physval run`` flag that sets them."""


def describe_selection(selection: dict | None) -> str:
    """One line for people: the paths and flags as ``physval run`` takes them, and whether the
    scenes' sweeps ran (``unrecorded`` when the run recorded no selection)."""
    if selection is None:
        return "selection not recorded (a run recorded before selections were)"
    words = [" ".join(selection.get("paths") or []) or "default scenes"]
    for name, flag in SELECTION_FLAGS.items():
        value = selection.get(name)
        if value is not None:
            words.append(f"{flag} {', '.join(value) if isinstance(value, list) else value}")
    if "sweeps" in selection:
        words.append("with sweeps" if selection["sweeps"] else "no sweeps")
    known = {"paths", "sweeps", *SELECTION_FLAGS}
    words += [f"{name}={value}" for name, value in sorted(selection.items()) if name not in known]
    return " ".join(words)


SELECTION_RULES = ("latest", "all")
"""``--selection``: the selection of the latest run (default), every run, or a key."""

KEY_PATTERN = re.compile(rf"[0-9a-f]{{{SELECTION_KEY_DIGITS}}}")


def chosen_selection(runs: pd.DataFrame, rule: str | None) -> str:
    """The key ``--selection`` names among ``runs`` (every complete run, oldest first):
    ``latest`` (None: the default) the latest run's, ``all``, ``unrecorded`` or a key given;
    ``HistoryInputError`` for anything else or a key no run has."""
    rule = "latest" if rule is None else rule
    if rule == "all":
        return "all"
    if rule == "latest":
        return str(runs["selection_key"].iloc[-1]) if len(runs) else "all"
    if rule != UNRECORDED and not KEY_PATTERN.fullmatch(rule):
        raise HistoryInputError(
            f"--selection {rule[:40]!r}: expected latest, all, {UNRECORDED} or a selection key "
            f"({SELECTION_KEY_DIGITS} hex digits, as physval history lists them)"
        )
    counts = runs["selection_key"].value_counts()
    if rule not in counts:
        known = ", ".join(f"{key} ({n} runs)" for key, n in counts.items()) or "none"
        raise HistoryInputError(f"--selection {rule}: no recorded run has it (selections: {known})")
    return rule


# --- URLs --------------------------------------------------------------------------------


def database_url(text: str | Path | None) -> str:
    """``--db``: a URL as given, a bare path as an SQLite file, nothing as the default."""
    if text is None:
        return DEFAULT_URL
    text = str(text)
    return text if "://" in text else f"sqlite:///{text}"


CONNECT_SECONDS = 10
"""How long connecting to a database server may take before it counts as unreachable: a
server on the network answers within milliseconds, and without a limit the drivers wait for
TCP's retries (minutes) while the run has not started."""

CONNECT_TIMEOUT_ARGUMENT = {
    "psycopg": "connect_timeout",
    "psycopg2": "connect_timeout",
    "pg8000": "timeout",
    "pymysql": "connect_timeout",
}
"""Driver -> the connect argument that bounds its connection time (``CONNECT_SECONDS``); a URL
that sets it itself keeps its own."""


def sqlite_file(url: str, flag: str = "--db") -> Path | None:
    """The file of an ``sqlite:///`` URL (None for other dialects and in-memory databases);
    ``HistoryInputError`` naming ``flag`` when ``url`` is not a URL."""
    try:
        parsed = sa.engine.make_url(url)
    except sa.exc.ArgumentError:
        raise HistoryInputError(
            f"{flag} {shown_url(url)}: not a database URL (expected dialect://..., e.g. "
            f"sqlite:///path/to/history.sqlite or postgresql://user@host/physval)"
        ) from None
    if parsed.get_backend_name() != "sqlite" or parsed.database in (None, "", ":memory:"):
        return None
    return Path(parsed.database)


def _first_line(error: BaseException) -> str:
    """An error's first line, passwords hidden (a driver's message may quote the URL)."""
    text = str(getattr(error, "orig", None) or error).strip()
    return shown_url(text.splitlines()[0] if text else type(error).__name__)


@contextlib.contextmanager
def usable(url: str, flag: str) -> Iterator[None]:
    """Whatever makes ``url`` unusable, as one ``HistoryInputError`` line naming ``flag`` and
    the URL with its password hidden: an unknown dialect or a driver not installed, a server
    that cannot be reached or refuses the login, a file that is not a database."""
    try:
        yield
    except (sa.exc.ArgumentError, sa.exc.NoSuchModuleError, ModuleNotFoundError) as error:
        raise HistoryInputError(
            f"{flag} {shown_url(url)}: not a usable database URL ({_first_line(error)})"
        ) from None
    except sa.exc.DBAPIError as error:
        raise HistoryInputError(
            f"{flag} {shown_url(url)}: cannot open ({_first_line(error)})"
        ) from None


@contextlib.contextmanager
def readable(url: str, flag: str = "--db") -> Iterator[None]:
    """Whatever makes reading the history at ``url`` fail, as one ``HistoryInputError`` line
    naming ``flag``: a damaged file (``database disk image is malformed``), text that is not
    UTF-8, a table without a column physval reads, a foreign database."""
    try:
        yield
    except sa.exc.SQLAlchemyError as error:
        raise HistoryInputError(
            f"{flag} {shown_url(url)}: not a readable physval history ({_first_line(error)})"
        ) from None


def create_engine(url: str) -> sa.Engine:
    """An engine on ``url``, connecting within ``CONNECT_SECONDS`` where its driver allows."""
    parsed = sa.engine.make_url(url)
    argument = CONNECT_TIMEOUT_ARGUMENT.get(parsed.get_driver_name())
    if argument is None or argument in parsed.query:
        return sa.create_engine(url)
    return sa.create_engine(url, connect_args={argument: CONNECT_SECONDS})


def open_database(url: str, create: bool, flag: str = "--db") -> sa.Engine:
    """An engine on ``url`` with the schema in place (``create``), or on an existing database.

    Reading never creates an empty SQLite file (nor its folder): a missing one is
    ``HistoryInputError``.
    """
    with usable(url, flag):
        path = sqlite_file(url, flag)
        if path is not None and not create and not path.is_file():
            raise HistoryInputError(f"{path}: no history database (physval run records one)")
        if path is not None and create:  # physval run checked it first (check_database)
            path.parent.mkdir(parents=True, exist_ok=True)
        engine = create_engine(url)
        if create:
            METADATA.create_all(engine)
            add_missing_columns(engine)
        elif not sa.inspect(engine).has_table(RUNS.name):
            raise HistoryInputError(
                f"{shown_url(url)}: not a physval history database (no runs table)"
            )
    return engine


def check_url(url: str, flag: str = "--db") -> None:
    """``url`` parses and names a dialect whose driver is installed (no connection made)."""
    with usable(url, flag):
        sqlite_file(url, flag)
        create_engine(url).dispose()


def _transactional_sqlite(engine: sa.Engine) -> None:
    """Make Python's sqlite3 driver run DDL inside the transaction (it commits ``CREATE
    TABLE`` at once otherwise), so that a probe can roll it back: SQLAlchemy's recipe for
    pysqlite (its "Serializable isolation / Savepoints / Transactional DDL" section), with
    ``BEGIN IMMEDIATE``, which takes the write lock: a read-only or locked file fails here."""

    @sa.event.listens_for(engine, "connect")
    def _no_implicit_transactions(dbapi_connection, _record) -> None:
        dbapi_connection.isolation_level = None

    @sa.event.listens_for(engine, "begin")
    def _explicit_begin(connection) -> None:
        connection.exec_driver_sql("BEGIN IMMEDIATE")


def _missing_sqlite_file(path: Path, url: str, flag: str, made: tuple[Path, ...]) -> None:
    """An SQLite file that does not exist yet: its folder must (nothing is created before the
    run is recorded, and no folder but those of ``made``), and be writable."""
    folder = path.parent
    if folder.resolve() in made:
        return  # the run makes it or checks it (a folder of its --out), and records into it
    if not folder.is_dir():
        raise HistoryInputError(
            f"{flag} {shown_url(url)}: no folder {folder} (the database file is created in an "
            "existing folder)"
        )
    if not os.access(folder, os.W_OK | os.X_OK):
        raise HistoryInputError(f"{flag} {shown_url(url)}: folder {folder} is not writable")


def check_database(url: str, flag: str = "--history", made: tuple[Path, ...] = ()) -> None:
    """Before any work: the history at ``url`` can be recorded into. Connect, create the
    tables and the missing columns, write a row into each table (``_probe_write``: a
    read-only or trigger-guarded database fails here, not after the run) and roll it all back
    (the rows have explicit ids: a PostgreSQL sequence is not rolled back, and the run ids
    would have gaps); a missing SQLite file is not
    created (its folder is checked, ``_missing_sqlite_file``: it must exist, or be one of the
    folders ``made`` by the run, resolved). One ``HistoryInputError`` line otherwise
    (``usable``)."""
    with usable(url, flag):
        path = sqlite_file(url, flag)
        if path is not None and path.is_dir():
            raise HistoryInputError(f"{flag} {shown_url(url)}: {path} is a folder, not a file")
        if path is not None and not path.exists():
            _missing_sqlite_file(path, url, flag, made)
            return
        engine = create_engine(url)
        if engine.dialect.name == "sqlite":
            _transactional_sqlite(engine)
        try:
            with engine.connect() as connection:
                transaction = connection.begin()
                try:
                    METADATA.create_all(connection)
                    for name in ADDED_RUN_COLUMNS:
                        if name not in run_columns(connection):
                            connection.execute(sa.text(_column_ddl(connection, name)))
                    _probe_write(connection)
                finally:
                    transaction.rollback()
        finally:
            engine.dispose()


PROBE = "physval-write-probe"
"""The names of the rows ``check_database`` writes and rolls back."""


def _next_id(connection: sa.Connection, table: sa.Table) -> int:
    return int(connection.execute(sa.select(sa.func.max(table.c.id))).scalar() or 0) + 1


def _probe_write(connection: sa.Connection) -> None:
    """Write one row into each table, as ``record_run`` does (the caller rolls them back): a
    read-only file, folder or file system, or a trigger that refuses inserts, fails here and
    not after the run. Explicit ids past the last: no sequence is consumed (a PostgreSQL
    sequence is not rolled back)."""
    run_id, series_id = _next_id(connection, RUNS), _next_id(connection, SERIES)
    connection.execute(
        RUNS.insert().values(
            id=run_id, engine_versions={}, machine={}, command=PROBE, folder=PROBE, complete=False
        )
    )
    connection.execute(
        SERIES.insert().values(id=series_id, scenario=PROBE, engine=PROBE, metric=PROBE)
    )
    connection.execute(
        RESULTS.insert().values(
            id=_next_id(connection, RESULTS),
            run_id=run_id,
            series_id=series_id,
            status=PROBE[:WORD_LENGTH],
            engine_version="",
        )
    )


def run_columns(connection: sa.Connection | sa.Engine) -> set[str]:
    """The columns the database's ``runs`` table has (an older one lacks ADDED_RUN_COLUMNS)."""
    return {column["name"] for column in sa.inspect(connection).get_columns(RUNS.name)}


def _column_ddl(bind: sa.Connection | sa.Engine, name: str) -> str:
    """``ALTER TABLE runs ADD COLUMN`` of one of ``ADDED_RUN_COLUMNS``, in ``bind``'s dialect."""
    quote = bind.dialect.identifier_preparer.quote
    column_type = RUNS.c[name].type.compile(dialect=bind.dialect)
    return f"ALTER TABLE {quote(RUNS.name)} ADD COLUMN {quote(name)} {column_type}"


def add_missing_columns(engine: sa.Engine) -> None:
    """Bring an older database's ``runs`` table up to ``RUNS``: each of ``ADDED_RUN_COLUMNS``
    it lacks is added (NULL for the runs already recorded). Two writers migrating at once:
    the second one's ALTER fails, and the column it wanted is there."""
    for name in ADDED_RUN_COLUMNS:
        if name in run_columns(engine):
            continue
        try:
            with engine.begin() as connection:
                connection.execute(sa.text(_column_ddl(engine, name)))
        except sa.exc.DBAPIError:
            if name not in run_columns(engine):
                raise


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
    """The ``runs`` row of a run folder (incomplete until ``finish_run``), its selection
    checked (``valid_selection``: a malformed one is recorded as none)."""
    engines = provenance.get("engines") or {}
    engines = engines if isinstance(engines, dict) else {}
    selection = valid_selection(provenance.get("selection"))
    machine = provenance.get("machine")
    return {
        "created": _created(provenance, folder),
        "commit": _word(provenance.get("git_commit")),
        "engine_versions": {
            str(label): str(info.get("version", "") if isinstance(info, dict) else "")
            for label, info in engines.items()
        },
        "machine": machine if isinstance(machine, dict) else {},
        "command": shown_url(provenance.get("command", "")),  # a foreign folder's too
        "folder": str(folder.resolve()),
        "complete": False,
        "selection": selection,
        "selection_key": None if selection is None else selection_key(selection),
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
        provenance = read_provenance(folder / PROVENANCE_FILE, []) or {}
    except FileNotFoundError:
        raise HistoryInputError(f"{folder}: no {RESULTS_FILE} (not a physval run folder)") from None
    except ReportInputError as error:
        raise HistoryInputError(f"{folder}: {error}") from None
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


RUN_COLUMNS = (
    "id",
    "created",
    "commit",
    "engine_versions",
    "machine",
    "command",
    "folder",
    "selection",
    "selection_key",
)
"""The columns of a run as readers get it (``selection_key`` computed from ``selection``)."""


def _json_object(raw: object) -> dict:
    """A JSON column read back: the object it holds, {} for anything else."""
    if isinstance(raw, (str, bytes)):
        try:
            raw = json.loads(raw)
        except (ValueError, RecursionError):
            return {}
    return raw if isinstance(raw, dict) else {}


def _time(raw: object) -> pd.Timestamp | None:
    """A stored time read back (a datetime, or text as SQLite keeps it), None if it is none."""
    if isinstance(raw, dt_module.datetime):
        return pd.Timestamp(raw)
    try:
        return pd.Timestamp(dt_module.datetime.fromisoformat(str(raw)))
    except ValueError:
        return None


def _text(raw: object) -> str:
    return "" if raw is None else str(raw)


def _run_row(found: sa.Row, selection_recorded: bool) -> dict:
    """One ``runs`` row checked: each column read as raw as the driver gives it (no type
    processing that could raise on a malformed value) and validated here."""
    selection = valid_selection(found.selection) if selection_recorded else None
    return {
        "id": int(found.id),
        "created": _time(found.created),
        "commit": _text(found.commit),
        "engine_versions": {
            str(label): _text(version) for label, version in _json_object(found.engines).items()
        },
        "machine": _json_object(found.machine),
        "command": _text(found.command),
        "folder": _text(found.folder),
        "selection": selection,
        "selection_key": selection_key(selection),
    }


def _runs_frame(connection: sa.Connection, where: sa.ColumnElement) -> pd.DataFrame:
    """The complete runs matching ``where``, oldest first, checked (``_run_row``); a database
    written before ``selection`` existed reads as every run ``unrecorded``."""
    recorded = "selection" in run_columns(connection)
    raw = {
        name: sa.type_coerce(RUNS.c[column], sa.Text).label(name)
        for name, column in (
            ("created", "created"),
            ("engines", "engine_versions"),
            ("machine", "machine"),
            ("selection", "selection"),
        )
        if name != "selection" or recorded
    }
    query = (
        sa.select(RUNS.c.id, RUNS.c.commit, RUNS.c.command, RUNS.c.folder, *raw.values())
        .where(RUNS.c.complete, where)
        .order_by(RUNS.c.id)
    )
    rows = [_run_row(found, recorded) for found in connection.execute(query)]
    frame = pd.DataFrame(rows, columns=list(RUN_COLUMNS))
    frame["created"] = frame["created"].astype(object)
    return frame


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
    for column in KEY_COLUMNS:  # text, whatever a foreign writer stored
        names[column] = names[column].astype(str)
    if only:
        names = names[[fnmatch(name, only) for name in names["scenario"]]]
    return names


def _numbers(column: tuple) -> np.ndarray:
    """A number column read back as doubles: NULL as NaN, and anything that is not a number
    (SQLite keeps whatever a foreign writer put in a column) as NaN too, not an exception."""
    try:
        return np.array(column, dtype=float)
    except (TypeError, ValueError):
        return pd.to_numeric(pd.Series(column, dtype=object), errors="coerce").to_numpy(float)


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
            name: _numbers(column) if name in NUMBER_COLUMNS else np.array(column, dtype=object)
            for name, column in zip(("run_id", "series_id", *columns), values, strict=True)
        }
    )
    frame = frame[frame["run_id"].isin(run_ids) & frame["series_id"].isin(names["series_id"])]
    frame = frame.merge(names, on="series_id", how="left", sort=False)
    frame["run_id"] = frame["run_id"].astype(int)
    return frame[["run_id", *KEY_COLUMNS, *columns]].reset_index(drop=True)


def load_history(
    url: str, last: int | None = None, only: str | None = None, selection: str | None = None
) -> History:
    """The ``last`` complete runs (all when None) of one selection, oldest first: the trend
    columns of every row, and the full rows of the latest of them; ``only`` keeps the scenarios
    matching the glob. ``selection`` (``chosen_selection``): ``latest`` (None) the selection of
    the latest complete run, ``all`` every run, or a selection key."""
    engine = open_database(url, create=False)
    try:
        with readable(url), engine.connect() as connection:
            recorded = _runs_frame(connection, sa.true())
            chosen = chosen_selection(recorded, selection)
            runs = recorded if chosen == "all" else recorded[recorded["selection_key"] == chosen]
            runs = (runs.tail(last) if last else runs).reset_index(drop=True)
            run_ids = [int(i) for i in runs["id"]]
            trend = _fetch_rows(connection, run_ids, TREND_COLUMNS, only)
            latest = _fetch_rows(connection, run_ids[-1:], ROW_COLUMNS, only)
    finally:
        engine.dispose()
    return History(runs, trend, latest, recorded, chosen)


def load_run(url: str, run_id: int) -> History:
    """One complete run of the history (its rows as ``latest`` and ``trend``);
    ``HistoryInputError`` when there is no such run."""
    engine = open_database(url, create=False)
    try:
        with readable(url), engine.connect() as connection:
            runs = _runs_frame(connection, RUNS.c.id == run_id)
            if runs.empty:
                raise HistoryInputError(f"run {run_id}: no such run in {shown_url(url)}")
            rows = _fetch_rows(connection, [run_id], ROW_COLUMNS, None)
    finally:
        engine.dispose()
    key = str(runs["selection_key"].iloc[0])
    return History(runs, rows[["run_id", *KEY_COLUMNS, *TREND_COLUMNS]], rows, runs, key)
