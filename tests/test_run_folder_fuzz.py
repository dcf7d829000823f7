"""A run folder read back is data from elsewhere: ``physval report``, ``compare``, ``history``
and ``baseline save`` of a damaged one render it (missing values shown as missing) or exit 2
with one line; never a traceback, never exit 0 without a page, never a file followed out of
the folder. The folders are copies of the session's real run (``conftest.real_run``),
damaged by hand (``FOLDER_ATTACKS``) and by Hypothesis (``test_fuzzed_folders...``)."""

from __future__ import annotations

import json
import shutil
from collections.abc import Callable
from pathlib import Path

import pandas as pd
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from validation.cli import main
from validation.jobs.terminal import message_lines
from validation.nightly.history import HistoryInputError, record_run
from validation.report.read import MAX_PROVENANCE_BYTES

SECRET = "the-user's-private-key"
"""The text of a file outside the run folder that a symlink in it points to: it must never
reach a page or a baseline."""

FUZZ_EXAMPLES = 8
"""Damaged folders per fuzz test (one test per page). A report of the real two-scene run takes
1.3 s of CPU (its matplotlib plots), a compare or a history page about 0.3 s, so the three
tests take about 15 s of CPU; ``derandomize`` keeps the same examples on every run. Run once
with 60 random examples each, they found pandas' two-line parser error (now one line)."""

FUZZ_SETTINGS = settings(
    max_examples=FUZZ_EXAMPLES,
    deadline=None,
    derandomize=True,
    database=None,
    suppress_health_check=[HealthCheck.function_scoped_fixture, HealthCheck.too_slow],
)

RECORD_FILES = ("results.csv", "series.csv", "impacts.csv", "sweep.csv", "provenance.json")


def copy_run(real_run, folder: Path) -> Path:
    run = folder / "run"
    shutil.copytree(real_run.folder, run, symlinks=True)
    return run


def one_line_or_page(code: int, err: str, page: Path | None) -> None:
    """Exit 2 with one line and no traceback, or exit 0 with the page written."""
    assert "Traceback" not in err, err
    if code == 0:
        assert page is not None and page.is_file() and page.stat().st_size > 0, page
        return
    assert code == 2, (code, err)
    assert len(message_lines(err)) == 1, err


def report(run: Path, capsys) -> tuple[int, str, Path]:
    page = run / "report.html"
    page.unlink(missing_ok=True)
    code = main(["report", str(run)])
    return code, capsys.readouterr().err, page


def compare(run: Path, real_run, capsys) -> tuple[int, str, Path]:
    out = run.parent / "compare"
    shutil.rmtree(out, ignore_errors=True)
    code = main(["compare", str(real_run.folder), str(run), "--out", str(out)])
    return code, capsys.readouterr().err, out / "compare.html"


def baseline(run: Path, capsys) -> tuple[int, str, Path]:
    to = run.parent / "baseline.csv"
    to.unlink(missing_ok=True)
    code = main(["baseline", "save", str(run), "--to", str(to)])
    return code, capsys.readouterr().err, to


def history(run: Path, real_run, capsys) -> tuple[int, str, Path | None]:
    """The history page of a database holding the real run and the damaged one (when the
    history takes it: a folder it refuses is one line, ``HistoryInputError``)."""
    database = run.parent / "history.sqlite"
    database.unlink(missing_ok=True)
    url = f"sqlite:///{database}"
    record_run(real_run.folder, url)
    try:
        record_run(run, url)
    except HistoryInputError as error:
        assert len(str(error).splitlines()) == 1, error
    page = run.parent / "history.html"
    page.unlink(missing_ok=True)
    code = main(["history", "--db", url, "--out", str(page)])
    return code, capsys.readouterr().err, page


def _provenance(change: Callable[[dict], object]) -> Callable[[Path], None]:
    def damage(run: Path) -> None:
        path = run / "provenance.json"
        provenance = json.loads(path.read_text())
        change(provenance)
        path.write_text(json.dumps(provenance))

    return damage


def _symlink_out(name: str) -> Callable[[Path], None]:
    def damage(run: Path) -> None:
        secret = run.parent / "secret.txt"
        secret.write_text(SECRET)
        (run / name).unlink()
        (run / name).symlink_to(secret)

    return damage


def _huge(run: Path) -> None:
    with open(run / "provenance.json", "r+b") as handle:
        handle.truncate(MAX_PROVENANCE_BYTES + 1)


def _results(change: Callable[[pd.DataFrame], pd.DataFrame]) -> Callable[[Path], None]:
    def damage(run: Path) -> None:
        path = run / "results.csv"
        table = pd.read_csv(path, dtype=str, keep_default_na=False)
        change(table).to_csv(path, index=False)

    return damage


FOLDER_ATTACKS: dict[str, tuple[Callable[[Path], None], str]] = {
    "provenance.json not JSON": (
        lambda run: (run / "provenance.json").write_text("{'engines': None,"),
        "provenance.json",
    ),
    "provenance.json a list": (
        lambda run: (run / "provenance.json").write_text("[1, 2]"),
        "provenance.json",
    ),
    "provenance engines of the wrong type": (
        _provenance(lambda p: p.update(engines={"mini": {"notes": 5}})),
        "engines.mini.notes",
    ),
    "provenance scenes a list": (_provenance(lambda p: p.update(scenes=[1])), "scenes"),
    "provenance machine a list": (_provenance(lambda p: p.update(machine=["x"])), "machine"),
    "provenance nested without end": (
        lambda run: (run / "provenance.json").write_text('{"a":' * 50_000 + "1" + "}" * 50_000),
        "provenance.json",
    ),
    "provenance.json huge": (_huge, "larger than"),
    "provenance.json a symlink out of the folder": (
        _symlink_out("provenance.json"),
        "symlink",
    ),
    "results.csv a symlink out of the folder": (_symlink_out("results.csv"), "symlink"),
    "results.csv with a row of too many cells": (
        lambda run: (run / "results.csv").write_text(
            (run / "results.csv").read_text() + "," * 46 + "\n"
        ),
        "results.csv: cannot be read as CSV",
    ),
    "results.csv without its metric column": (
        _results(lambda t: t.drop(columns=["metric"])),
        "metric",
    ),
}
"""Damage to a run folder that every reader refuses -> what its one line names."""

READERS: dict[str, Callable] = {
    "report": lambda run, real_run, capsys: report(run, capsys),
    "compare": lambda run, real_run, capsys: compare(run, real_run, capsys),
    "baseline save": lambda run, real_run, capsys: baseline(run, capsys),
}
"""The commands that read a run folder given on their command line."""


@pytest.mark.parametrize("reader", sorted(READERS))
@pytest.mark.parametrize("attack", sorted(FOLDER_ATTACKS))
def test_a_malformed_run_folder_is_one_line_and_exit_2(real_run, tmp_path, capsys, attack, reader):
    run = copy_run(real_run, tmp_path)
    damage, expected = FOLDER_ATTACKS[attack]
    damage(run)
    code, err, written = READERS[reader](run, real_run, capsys)
    assert code == 2 and expected in err, err
    assert len(message_lines(err)) == 1 and "Traceback" not in err, err
    assert not written.exists(), f"{written} written from a refused folder"
    assert not any(SECRET in p.read_text(errors="replace") for p in tmp_path.rglob("*.html"))


TEXT_CELLS = st.sampled_from(
    [
        "",
        "NaN",
        "nan",
        "inf",
        "-inf",
        "1e308",
        "-1e-320",
        "-0",
        "text",
        "True",
        "<script>alert(1)</script>",
        "</td></tr></table><b>x",
        '=HYPERLINK("http://x")',
        "é\u202e\u0000",
        "x" * 10_000,
        "1,2",
        '"',
    ]
)
"""Cell values a damaged CSV may hold: empty, non-finite, huge, text in number columns, HTML,
formula, control and bidi characters, a separator, a lone quote."""

PROVENANCE_VALUES = st.recursive(
    st.none() | st.booleans() | st.integers() | st.floats() | st.text(max_size=20),
    lambda inner: (
        st.lists(inner, max_size=3) | st.dictionaries(st.text(max_size=8), inner, max_size=3)
    ),
    max_leaves=8,
)
"""Any JSON value, for a field of provenance.json."""


@st.composite
def damage(draw) -> Callable[[Path], None]:
    """One to three changes to a run folder's files: a file deleted, truncated, given bytes
    that are not UTF-8, a column dropped, cells or rows replaced, a field of provenance.json
    replaced by any JSON value."""
    changes = []
    for _ in range(draw(st.integers(1, 3))):
        name = draw(st.sampled_from(RECORD_FILES))
        kind = draw(
            st.sampled_from(
                ["delete", "truncate", "bytes", "column", "cells", "rows"]
                if name.endswith(".csv")
                else ["delete", "truncate", "bytes", "field"]
            )
        )
        changes.append((name, kind, draw(_change_detail(kind))))

    def apply(run: Path) -> None:
        for name, kind, detail in changes:
            path = run / name
            if path.is_file():
                CHANGES[kind](path, detail)

    apply.changes = changes  # shown by Hypothesis when an example fails
    return apply


def _change_detail(kind: str):
    return {
        "delete": st.none(),
        "truncate": st.floats(0.0, 1.0),
        "bytes": st.binary(min_size=1, max_size=40),
        "column": st.integers(0, 100),
        "cells": st.lists(
            st.tuples(st.integers(0, 10_000), st.integers(0, 100), TEXT_CELLS),
            min_size=1,
            max_size=6,
        ),
        "rows": st.sampled_from(["duplicate", "drop", "shuffle", "header only"]),
        "field": st.tuples(
            st.sampled_from(
                ["command", "created", "engines", "scenes", "machine", "selection", "git_commit"]
            ),
            PROVENANCE_VALUES,
        ),
    }[kind]


def _truncate(path: Path, fraction: float) -> None:
    data = path.read_bytes()
    path.write_bytes(data[: int(len(data) * fraction)])


def _inject_bytes(path: Path, junk: bytes) -> None:
    data = path.read_bytes()
    middle = len(data) // 2
    path.write_bytes(data[:middle] + junk + data[middle:])


def _table_change(change: Callable[[pd.DataFrame, object], pd.DataFrame]):
    def apply(path: Path, detail) -> None:
        try:
            table = pd.read_csv(path, dtype=str, keep_default_na=False)
        except (pd.errors.ParserError, pd.errors.EmptyDataError, UnicodeDecodeError):
            return  # already damaged beyond a table
        change(table, detail).to_csv(path, index=False)

    return apply


def _drop_column(table: pd.DataFrame, which: int) -> pd.DataFrame:
    return (
        table.drop(columns=[table.columns[which % len(table.columns)]])
        if len(table.columns)
        else table
    )


def _set_cells(table: pd.DataFrame, cells) -> pd.DataFrame:
    for row, column, text in cells:
        if len(table) and len(table.columns):
            table.iat[row % len(table), column % len(table.columns)] = text
    return table


ROW_CHANGES: dict[str, Callable[[pd.DataFrame], pd.DataFrame]] = {
    "duplicate": lambda t: pd.concat([t, t.head(3)]),
    "drop": lambda t: t.iloc[len(t) // 2 :],
    "shuffle": lambda t: t.iloc[::-1],
    "header only": lambda t: t.head(0),
}


def _replace_field(path: Path, detail) -> None:
    try:
        provenance = json.loads(path.read_text())
    except (ValueError, UnicodeDecodeError):
        return
    if isinstance(provenance, dict):
        key, value = detail
        provenance[key] = value
        path.write_text(json.dumps(provenance))


CHANGES: dict[str, Callable[[Path, object], None]] = {
    "delete": lambda path, _: path.unlink(),
    "truncate": _truncate,
    "bytes": _inject_bytes,
    "column": _table_change(_drop_column),
    "cells": _table_change(_set_cells),
    "rows": _table_change(lambda t, how: ROW_CHANGES[how](t)),
    "field": _replace_field,
}
"""A kind of damage -> how it is done to a file (``damage``)."""


def _fuzz(real_run, tmp_path_factory, change, read) -> None:
    folder = tmp_path_factory.mktemp("fuzz")
    run = copy_run(real_run, folder)
    change(run)
    code, err, page = read(run)
    one_line_or_page(code, err, page)


@FUZZ_SETTINGS
@given(change=damage())
def test_fuzzed_folders_render_or_are_one_line_in_report(
    real_run, tmp_path_factory, capsys, change
):
    _fuzz(real_run, tmp_path_factory, change, lambda run: report(run, capsys))


@FUZZ_SETTINGS
@given(change=damage())
def test_fuzzed_folders_render_or_are_one_line_in_compare(
    real_run, tmp_path_factory, capsys, change
):
    _fuzz(real_run, tmp_path_factory, change, lambda run: compare(run, real_run, capsys))


@FUZZ_SETTINGS
@given(change=damage())
def test_fuzzed_folders_render_or_are_one_line_in_history(
    real_run, tmp_path_factory, capsys, change
):
    _fuzz(real_run, tmp_path_factory, change, lambda run: history(run, real_run, capsys))


def test_a_damaged_value_is_shown_as_missing(real_run, tmp_path, capsys):
    """Text and nothing in number cells: the page renders, the row still there, its value
    shown as missing (the report's dash), the text escaped."""
    run = copy_run(real_run, tmp_path)
    damage = _results(lambda t: t.assign(value=["<b>x</b>", *[""] * (len(t) - 1)]))
    damage(run)
    code, err, page = report(run, capsys)
    assert code == 0, err
    html = page.read_text()
    assert "<b>x</b>" not in html and "&lt;b&gt;x&lt;/b&gt;" in html


def test_a_symlinked_table_is_never_followed(real_run, tmp_path, capsys):
    """series.csv pointing out of the folder: the report refuses it in one line (compare and
    baseline save never open it)."""
    run = copy_run(real_run, tmp_path)
    _symlink_out("series.csv")(run)
    code, err, page = report(run, capsys)
    assert code == 2 and "series.csv" in err and "symlink" in err, err
    assert not page.exists()
