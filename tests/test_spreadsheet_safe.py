"""Spreadsheet-safe CSV: a text cell that a spreadsheet would run as a formula is written with
a quote before it (OWASP's CSV-injection rule), numbers never are, and every CSV physval reads
back (results, baselines, the run's baseline.csv, sweep and impacts tables, history imports)
reads the original text again."""

from __future__ import annotations

import csv
import io
import math
import sqlite3
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from validation.cli import main
from validation.contract import EXIT_FAILED, EXIT_OK
from validation.csv_safe import FORMULA_STARTS, csv_text, restored
from validation.nightly import history

SCENE = """\
name: "-cmd"
dt: 0.01
duration: 0.1
engines: [mini]
ground: {restitution: 0.5, friction: 0.0}
bodies:
  - {name: "-b", shape: {type: sphere, radius: 0.1}, mass: 1.0, position: [0, 0, 0.15],
     velocity: [0, 0, -2]}
"""
"""A scene whose name (and body) a spreadsheet reads as a formula: ``-cmd`` is ``=-cmd``,
#NAME? in Excel; the schema's name pattern allows a leading ``-``."""

ATTACKS = [start + 'HYPERLINK("http://x","y")' for start in FORMULA_STARTS]
"""One text cell per first character of OWASP's list."""


def cells(text: str | Path) -> list[list[str]]:
    """The raw cells of a CSV text or file, as a spreadsheet gets them (a carriage return in a
    cell kept as it is)."""
    if isinstance(text, Path):
        with text.open(newline="", encoding="utf-8") as handle:
            return list(csv.reader(handle))
    return list(csv.reader(io.StringIO(text, newline="")))


def test_every_formula_start_is_quoted_and_numbers_are_not():
    frame = pd.DataFrame(
        {
            "name": [*ATTACKS, "'quoted", "plain", None],
            "value": [-1.5] * len(ATTACKS) + [-2.0, 3.0, np.nan],
            "passed": [True] * (len(ATTACKS) + 3),
            "tolerance": [None] * len(ATTACKS) + [-1e-3, None, 2.0],  # mixed: object dtype
        }
    )
    written = cells(csv_text(frame))
    names = [row[0] for row in written[1:]]
    assert names == [f"'{a}" for a in ATTACKS] + ["''quoted", "plain", ""], names
    assert {row[1] for row in written[1 : len(ATTACKS) + 1]} == {"-1.5"}  # a number stays one
    assert written[len(ATTACKS) + 1][3] == "-0.001", written[len(ATTACKS) + 1]


def test_reading_back_gives_the_original_text():
    frame = pd.DataFrame({"name": [*ATTACKS, "'quoted", "''twice", "plain"], "value": -1.5})
    back = restored(pd.read_csv(io.StringIO(csv_text(frame)), dtype={"name": str}))
    assert back["name"].tolist() == frame["name"].tolist()
    assert back["value"].tolist() == [-1.5] * len(frame)


def scene_file(tmp_path: Path) -> Path:
    path = tmp_path / "cmd.yaml"
    path.write_text(SCENE)
    return path


def run(tmp_path: Path, out: str, *flags: str) -> int:
    return main(["run", str(scene_file(tmp_path)), "--out", str(tmp_path / out), "--jobs", "1",
                 "--history", "none", *flags])  # fmt: skip


def test_a_formula_named_scene_is_neutralised_in_every_csv_and_round_trips(
    tmp_path, monkeypatch, capsys
):
    """The scene ``-cmd`` (body ``-b``) run, saved as a baseline, run against it, compared
    and recorded: every CSV has ``'-cmd``, the negative signed errors stay numbers, and every
    reader gets ``-cmd`` back (the baseline matches itself: all rows unchanged)."""
    monkeypatch.chdir(tmp_path)
    assert run(tmp_path, "a", "--baseline", "none") == EXIT_OK
    results = cells(tmp_path / "a" / "results.csv")
    header, rows = results[0], results[1:]
    assert rows and {row[0] for row in rows} == {"'-cmd"}, rows
    signed = [row[header.index("signed_error")] for row in rows]
    assert any(s.startswith("-") and float(s) < 0 for s in signed), signed  # untouched
    for name in ("series.csv", "impacts.csv"):
        table = cells(tmp_path / "a" / name)
        assert table[1:] and {row[0] for row in table[1:]} == {"'-cmd"}, (name, table[:2])
    impacts = cells(tmp_path / "a" / "impacts.csv")
    assert "'-b" in impacts[1], impacts[:2]

    baseline = tmp_path / "baseline.csv"
    assert main(["baseline", "save", str(tmp_path / "a"), "--to", str(baseline)]) == EXIT_OK
    assert {row[0] for row in cells(baseline)[1:]} == {"'-cmd"}
    assert run(tmp_path, "b", "--baseline", str(baseline)) == EXIT_OK
    classes = pd.read_csv(tmp_path / "b" / "results.csv")["baseline"]
    assert set(classes) == {"unchanged"}, classes.tolist()  # the baseline read back matches
    assert {row[0] for row in cells(tmp_path / "b" / "baseline.csv")[1:]} == {"'-cmd"}
    page = (tmp_path / "b" / "report.html").read_text()
    assert "-cmd" in page and "'-cmd" not in page and "&#39;-cmd" not in page

    assert run(tmp_path, "c", "--baseline", "none", "--dt", "0.005") in (EXIT_OK, EXIT_FAILED)
    out = tmp_path / "compare"
    assert main(["compare", str(tmp_path / "a"), str(tmp_path / "c"), "--out", str(out)]) == 0
    compared = cells(out / "compare.csv")
    assert compared[1:] and {row[0] for row in compared[1:]} == {"'-cmd"}, compared
    assert "&#39;-cmd" not in (out / "compare.html").read_text()

    url = f"sqlite:///{tmp_path / 'history.sqlite'}"
    history.record_run(tmp_path / "a", url)
    with sqlite3.connect(tmp_path / "history.sqlite") as connection:
        names = {name for (name,) in connection.execute("select scenario from series")}
    assert names == {"-cmd"}  # the history holds the name, not its CSV spelling
    capsys.readouterr()


def test_a_hand_written_baseline_without_quotes_reads_as_it_is(tmp_path):
    """A baseline written by another tool (no quotes) is read as it stands: only a leading
    quote is taken off, so ``-cmd`` stays ``-cmd`` and numbers stay numbers."""
    from validation.nightly.baseline import BASELINE_COLUMNS, read_baseline

    row = dict.fromkeys(BASELINE_COLUMNS, "")
    row.update(scenario="-cmd", engine="mini", metric="m", value="-1.5", error="0.5")
    path = tmp_path / "b.csv"
    pd.DataFrame([row]).to_csv(path, index=False)
    table = read_baseline(path)
    assert table["scenario"].tolist() == ["-cmd"]
    assert table["value"].tolist() == [-1.5] and not math.isnan(table["error"].iat[0])


@pytest.mark.parametrize("cell", ATTACKS)
def test_the_sweep_and_stability_tables_are_neutralised(tmp_path, cell):
    """``files.write_table`` (sweep.csv, stability.csv) quotes a formula-looking message."""
    from validation.files import write_table

    path = tmp_path / "t.csv"
    write_table([{"scenario": "s", "message": cell, "value": -2.5}], path)
    row = cells(path)[1]
    assert row == ["s", f"'{cell}", "-2.5"], row
