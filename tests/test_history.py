"""The history store, step detection, history.html and ``physval compare``.

Run folders are tiny and synthetic (results.csv and provenance.json written with pandas); no
engine runs. Each test names what it checks; the failure it was seen to give on a broken
implementation is in the commit note.
"""

from __future__ import annotations

import json
import re
import signal
import sqlite3
import subprocess
import sys
import textwrap
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from validation.cli import main
from validation.contract import EXIT_BAD_INPUT, EXIT_OK, PROVENANCE_FILE, RESULTS_COLUMNS
from validation.jobs.terminal import message_lines
from validation.measure.noise import RELATIVE_NOISE
from validation.nightly import history
from validation.nightly.compare import COMPARE_COLUMNS
from validation.nightly.steps import detect_steps

ENGINE_VERSIONS = {"mini": "0.1.0", "mujoco": "3.3.7"}


def row(scenario, engine, metric, error, tolerance=0.01, **extra) -> dict:
    """One results.csv row; ``value`` = 1 + error, expected 1 (error NaN: no expected value)."""
    no_expected = isinstance(error, float) and np.isnan(error)
    passed = None if tolerance is None or no_expected else bool(error <= tolerance)
    return {
        "scenario": scenario,
        "engine": engine,
        "metric": metric,
        "value": extra.pop("value", 1.0 + (0.0 if no_expected else error)),
        "expected": np.nan if no_expected else 1.0,
        "expected_kind": "" if no_expected else "analytic",
        "error": error,
        "tolerance": tolerance,
        "passed": passed,
        "status": "ok" if passed is not False else "failed",
        "dt": 0.001,
        "steps": 1000,
        "wall_time_s": 0.1,
        "engine_version": ENGINE_VERSIONS.get(engine, "1.0"),
        "settings": "{}",
        "message": "",
        "band": 0.0,
        **extra,
    }


def write_run(
    folder: Path,
    rows: list[dict],
    created: str,
    versions=None,
    selection=None,
    command="physval run",
) -> Path:
    """A run folder as ``physval run`` writes it (the columns the tests need); ``selection``
    provenance.json's (none: as a run of an earlier version wrote it)."""
    folder.mkdir(parents=True)
    versions = versions or ENGINE_VERSIONS
    table = pd.DataFrame(rows)
    table["engine_version"] = table["engine"].map(versions)
    table = table.reindex(columns=[*RESULTS_COLUMNS, *table.columns.difference(RESULTS_COLUMNS)])
    table.to_csv(folder / "results.csv", index=False)
    engines = {label: {"engine": label, "version": v} for label, v in versions.items()}
    provenance = {
        "command": command,
        "git_commit": f"c0ffee{created[:10]}",
        "created": created,
        "machine": {"platform": "test", "cpus": 2},
        "engines": engines,
    }
    if selection is not None:
        provenance["selection"] = selection
    (folder / PROVENANCE_FILE).write_text(json.dumps(provenance))
    return folder


def night(day: int) -> str:
    return f"2025-01-{day:02d}T02:00:00+00:00"


def table_counts(database: Path) -> dict[str, int]:
    with sqlite3.connect(database) as connection:
        return {
            name: connection.execute(f"select count(*) from {name}").fetchone()[0]
            for name in ("runs", "series", "results")
        }


# --- the store ----------------------------------------------------------------------------


def test_two_recorded_runs_read_back(tmp_path):
    first = [
        row("bounce", "mini", "energy_drift", 1e-4),
        row("bounce", "mujoco", "energy_drift", 2e-3),
    ]
    second = [
        row("bounce", "mini", "energy_drift", 1e-4, outcome="passed"),
        row("bounce", "mujoco", "energy_drift", 0.02, outcome="known", baseline="regressed"),
        row(
            "spin",
            "mini",
            "precession_rate",
            np.nan,
            tolerance=None,
            value=3.5,
            outcome="no_tolerance",
        ),
    ]
    url = f"sqlite:///{tmp_path / 'history.sqlite'}"
    ids = [
        history.record_run(write_run(tmp_path / "a", first, night(1)), url),
        history.record_run(
            write_run(tmp_path / "b", second, night(2), {"mini": "0.1.0", "mujoco": "4.0.0"}), url
        ),
    ]
    assert ids == [1, 2]

    found = history.load_history(url)
    assert list(found.runs["id"]) == [1, 2]
    assert found.runs["engine_versions"].iloc[1] == {"mini": "0.1.0", "mujoco": "4.0.0"}
    assert found.runs["commit"].iloc[0] == "c0ffee2025-01-01"
    assert found.runs["folder"].iloc[0] == str((tmp_path / "a").resolve())
    trend = found.trend.set_index(["run_id", "scenario", "engine", "metric"])
    assert len(trend) == 5
    assert trend.loc[(2, "bounce", "mujoco", "energy_drift"), "error"] == pytest.approx(0.02)
    assert np.isnan(trend.loc[(2, "spin", "mini", "precession_rate"), "error"])
    assert trend.loc[(2, "spin", "mini", "precession_rate"), "value"] == 3.5

    latest = found.latest.set_index(["scenario", "engine", "metric"])
    assert list(latest["outcome"]) == ["passed", "known", "no_tolerance"]
    assert latest.loc[("bounce", "mujoco", "energy_drift"), "baseline"] == "regressed"
    assert latest.loc[("bounce", "mujoco", "energy_drift"), "status"] == "failed"
    assert latest.loc[("bounce", "mujoco", "energy_drift"), "passed"] is False
    assert latest.loc[("spin", "mini", "precession_rate"), "passed"] is None

    one = history.load_run(url, 1).latest
    assert list(one["error"]) == pytest.approx([1e-4, 2e-3])
    assert one["outcome"].isna().all()  # the first run wrote no outcome column
    assert len(history.load_history(url, last=1).runs) == 1
    assert set(history.load_history(url, only="sp*").trend["scenario"]) == {"spin"}


KILLED_WRITER = textwrap.dedent(
    """
    import os, signal, sys
    import sqlalchemy as sa
    from validation.nightly import history

    @sa.event.listens_for(sa.Engine, "connect")
    def small_cache(connection, _):  # spill the transaction to the file early
        connection.execute("PRAGMA cache_size = 8")

    def killed(connection, run_id):
        os.kill(os.getpid(), signal.SIGKILL)  # after every row is inserted, before commit

    history.finish_run = killed
    history.record_run(sys.argv[1], sys.argv[2])
    """
)


def test_writer_killed_mid_transaction_leaves_no_partial_run(tmp_path):
    database = tmp_path / "history.sqlite"
    url = f"sqlite:///{database}"
    history.record_run(write_run(tmp_path / "a", [row("s", "mini", "m", 1e-3)], night(1)), url)
    before = table_counts(database)
    big = [row(f"scene_{i // 50}", "mini", f"metric_{i % 50}", 1e-3) for i in range(3000)]
    write_run(tmp_path / "big", big, night(2))

    killed = subprocess.run(
        [sys.executable, "-c", KILLED_WRITER, str(tmp_path / "big"), url],
        capture_output=True,
        text=True,
        timeout=120,
        check=False,
    )
    assert killed.returncode == -signal.SIGKILL, killed.stderr
    journal = database.with_name(database.name + "-journal")
    died_mid_write = journal.is_file() and journal.stat().st_size > 0  # before a reader rolls back

    with sqlite3.connect(database) as connection:  # the first reader rolls the journal back
        assert connection.execute("PRAGMA integrity_check").fetchone()[0] == "ok"
    assert table_counts(database) == before
    assert list(history.load_history(url).runs["id"]) == [1]
    assert died_mid_write, "the writer died before writing to the file: the test proves nothing"


# --- step detection -----------------------------------------------------------------------


def test_step_detection_finds_an_injected_step_at_its_run():
    rng = np.random.default_rng(7)
    noisy = 1e-3 * (1 + 0.01 * rng.standard_normal(120))
    noisy[105:] += 5e-5  # 5 σ of the scatter, held by the last 15 runs
    bit_identical = np.full(120, 4e-6)
    bit_identical[50:] = 4.1e-6  # +2.5 %: 33 noise floors, on a series with no scatter at all
    steps = detect_steps(np.vstack([noisy, bit_identical]))
    assert [(s.at, s.direction) for s in steps[0]] == [(105, 1)], steps[0]
    assert [(s.at, s.direction) for s in steps[1]] == [(50, 1)], steps[1]
    assert steps[0][0].before == pytest.approx(1e-3, rel=0.01)
    assert steps[0][0].after == pytest.approx(1.05e-3, rel=0.01)


def test_step_detection_finds_none_on_constant_or_noisy_series():
    rng = np.random.default_rng(3)
    noisy = 1e-3 * (1 + 0.01 * rng.standard_normal((50, 120)))  # 50 pure-noise series
    within_floor = 1e-3 * (1 + 0.5 * RELATIVE_NOISE * rng.standard_normal(120))
    constant = np.full(120, 0.25)
    with_gaps = constant.copy()
    with_gaps[::5] = np.nan
    values = np.vstack([noisy, within_floor, constant, with_gaps])
    steps = detect_steps(values)
    assert [i for i, found in enumerate(steps) if found] == []


def test_a_step_is_placed_at_a_run_that_measured_the_series():
    # runs 4 and 5 did not measure the series (another selection, NaN): the level changes
    # between run 3 and run 6, and the run that measured the new level first is run 6
    values = np.array([[1e-3] * 4 + [np.nan] * 2 + [1.2e-3] * 4])
    steps = detect_steps(values)
    assert [(s.at, s.direction) for s in steps[0]] == [(6, 1)], steps[0]
    three_runs = detect_steps(np.array([[1e-3, np.nan, 1.1e-3]]))[0]
    assert [(s.at, s.direction) for s in three_runs] == [(2, 1)], three_runs
    assert steps[0][0].before == pytest.approx(1e-3) and steps[0][0].after == pytest.approx(1.2e-3)


def test_an_infinite_error_is_a_step_there_and_back():
    finite = 2e-3
    values = np.array(
        [
            [finite] * 4 + [np.inf] + [np.nan] + [finite] * 3,  # overflowed at run 4, back at 6
            [finite] * 6 + [np.inf] * 3,  # a regression to an infinite error, held
            [np.inf] * 9,  # never finite: no step to place
        ]
    )
    steps = detect_steps(values)
    assert [(s.at, s.direction, s.after) for s in steps[0]] == [(4, 1, np.inf), (6, -1, finite)]
    assert steps[0][0].before == pytest.approx(finite)
    assert [(s.at, s.direction) for s in steps[1]] == [(6, 1)]
    assert steps[2] == []


# --- the pages ----------------------------------------------------------------------------


def recorded_history(tmp_path: Path) -> str:
    """Five nights: mujoco's energy drift doubles at night 4 with its version change; the last
    night carries baseline classes."""
    url = f"sqlite:///{tmp_path / 'reports' / 'history.sqlite'}"
    for day in range(1, 6):
        mujoco = 2e-3 if day < 4 else 4e-3
        rows = [
            row("bounce", "mini", "energy_drift", 1e-4),
            row("bounce", "mujoco", "energy_drift", mujoco),
            row("spin", "mini", "precession_rate", np.nan, tolerance=None, value=3.5),
        ]
        if day == 5:
            for r, baseline in zip(rows, ("unchanged", "regressed", "new"), strict=True):
                r["baseline"] = baseline
        versions = {"mini": "0.1.0", "mujoco": "3.3.7" if day < 4 else "4.0.0"}
        history.record_run(write_run(tmp_path / f"run{day}", rows, night(day), versions), url)
    return url


def test_history_page_shows_the_step_the_version_change_and_the_regression(tmp_path, capsys):
    url = recorded_history(tmp_path)
    assert main(["history", "--db", url]) == EXIT_OK
    page = tmp_path / "reports" / "history.html"  # next to the database
    printed = capsys.readouterr().out.splitlines()
    assert printed[-1] == str(page)
    assert printed[0].startswith("drew runs 1-5 (selection unrecorded: ")
    html = page.read_text()
    moved = html[html.index('id="moved"') : html.index('id="scenes"')]
    assert moved.count("<tr><td><a href=") == 1 and "mujoco" in moved
    assert "3.3.7 → 4.0.0" in moved  # the version change at the run that moved
    assert "error 0.002 → 0.004 (grew)" in moved
    regressions = html[html.index('id="baseline"') : html.index('id="moved"')]
    assert "regressed <b>1</b>" in regressions and "mujoco" in regressions
    assert html.count("<svg") == 3 + 1 + 1 + 1  # 3 sparklines + in moved + in regressions + 1 plot
    assert "<script" not in html and "http" not in html.replace("http://www.w3.org", "")
    main(["history", "--db", url])
    assert page.read_text() == html  # deterministic


NIGHTLY = {"paths": ["scenarios"], "only": None, "engines": None, "dt": None, "sweeps": True}
"""The selection of a bare ``physval run`` in a checkout (the nightly's)."""

BOUNCE_ONLY = {**NIGHTLY, "only": "*bounce*"}
"""A scene author's ``physval run --only "*bounce*"`` into the same history."""


def moved_at(html: str) -> dict[str, str]:
    """Scene -> the "moved at run" cell of its (one) moved series, tags stripped."""
    moved = html[html.index('id="moved"') : html.index('id="scenes"')]
    found = {}
    for line in moved.split("<tr><td><a href=")[1:]:
        scene = line.split(">", 1)[1].split("<", 1)[0]
        cells = re.findall(r"<td[^>]*>(.*?)</td>", line, re.DOTALL)  # engine, metric, trend, ..
        found[scene] = re.sub(r"<[^>]+>", " ", cells[3]).split()
    return found


def test_the_step_is_at_the_run_that_measured_the_series(tmp_path, capsys):
    """Run 1 ran everything, run 2 only the bounce, run 3 everything with the projectile's
    error grown: the projectile moved at run 3, and run 2 (which never ran it) is not blamed."""
    url = f"sqlite:///{tmp_path / 'history.sqlite'}"
    nights = [
        (NIGHTLY, {"projectile": 1e-3, "bounce": 5e-4}),
        (BOUNCE_ONLY, {"bounce": 5e-4}),
        (NIGHTLY, {"projectile": 1.5e-3, "bounce": 5e-4}),
    ]
    for day, (selection, errors) in enumerate(nights, start=1):
        rows = [row(scene, "mini", "energy_drift", error) for scene, error in errors.items()]
        command = f"physval run --history postgresql://ci:hunter2@db/physval --only {day}"
        folder = write_run(tmp_path / f"r{day}", rows, night(day), None, selection, command)
        history.record_run(folder, url)

    assert main(["history", "--db", url, "--out", str(tmp_path / "default.html")]) == EXIT_OK
    html = (tmp_path / "default.html").read_text()
    assert moved_at(html) == {"projectile": ["3", "·", "2025-01-03", "02:00:00", "·", "c0ffee2025"]}
    printed = capsys.readouterr().out.splitlines()
    nightly = history.selection_key(NIGHTLY)
    assert printed[0] == f"drew runs 1, 3 (selection {nightly}: scenarios with sweeps)"
    assert printed[1].startswith(f"not drawn: {history.selection_key(BOUNCE_ONLY)} (1 runs: 2)")

    every = tmp_path / "all.html"
    assert main(["history", "--db", url, "--selection", "all", "--out", str(every)]) == EXIT_OK
    cell = moved_at(every.read_text())["projectile"]
    assert cell[:2] == ["3", nightly], cell  # the run id and, with two selections drawn, its key
    assert cell[-5:] == ["last", "measured", "before:", "run", "1"], cell
    assert "postgresql://ci:***@db/physval --only 2" in every.read_text()
    assert "hunter2" not in every.read_text() + html  # a password is never shown
    assert "drew runs 2 (selection" in capsys.readouterr().out


def spark_of(html: str, anchor: str) -> str:
    """The scene table row of one series (its sparkline) and its plot row, if any."""
    start = html.index(f'<tr id="{anchor}">')
    stop = html.find("<tr id=", start + 1)
    return html[start : stop if stop > 0 else len(html)]


def test_infinite_and_missing_values_are_drawn_as_marks(tmp_path):
    """The mujoco drift overflows at night 4 (a regression to an infinite error), the
    pybullet drift was never finite, mini's position has no value at night 2 (a row without
    a number) and mini's velocity no row at night 3 (the scene ran without it)."""
    url = f"sqlite:///{tmp_path / 'history.sqlite'}"
    for day in range(1, 5):
        rows = [
            row("fall", "mujoco", "energy_drift", 2e-3 if day < 4 else np.inf),
            row("fall", "pybullet", "energy_drift", np.inf),
            row("fall", "mini", "position", np.nan if day == 2 else 1e-3, value=np.nan),
        ]
        if day != 3:
            rows.append(row("fall", "mini", "velocity", 4e-3))
        rows[0]["baseline"] = "regressed" if day == 4 else "unchanged"
        history.record_run(write_run(tmp_path / f"r{day}", rows, night(day), None, NIGHTLY), url)
    assert main(["history", "--db", url]) == EXIT_OK
    html = (tmp_path / "history.html").read_text()

    mujoco = spark_of(html, "scene-fall-mujoco-energy_drift")
    assert mujoco.count('<g class="mark inf"><title>run 4: inf</title>') == 1
    assert mujoco.count('class="mark') == 1  # the finite nights are points, not marks
    assert mujoco.count("<polyline") == 1 and "<circle" in mujoco  # line and dots of nights 1-3
    plot = mujoco[mujoco.index('<tr class="plot">') :]
    assert ">inf<" in plot or ">inf (1 runs)<" in plot  # the plot's mark is labelled
    assert "2025-01-04" in plot and "c0ffee2" in plot  # the axis names dates and commits
    assert moved_at(html)["fall"][:3] == ["4", "·", "2025-01-04"]
    assert "error 0.002 → inf (grew)" in html

    pybullet = spark_of(html, "scene-fall-pybullet-energy_drift")
    assert pybullet.count('class="mark inf"') == 4  # never finite: still drawn, not empty
    assert ">inf</span>" in pybullet

    position = spark_of(html, "scene-fall-mini-position")
    assert position.count('<g class="mark gap"><title>run 2: no value</title>') == 1
    assert position.count("<polyline") == 2  # the line breaks at the gap
    velocity = spark_of(html, "scene-fall-mini-velocity")
    assert "<title>run 3: missing (the scene ran without this row)</title>" in velocity


def test_compare_lists_exactly_the_moved_rows(tmp_path, capsys):
    tolerance = 0.01
    before = [
        row("s", "mini", "grew", 1e-3),
        row("s", "mini", "shrank", 1e-3),
        row("s", "mini", "within_noise", 1e-3),
        row("s", "mini", "now_fails", 0.0099995),
        row("s", "mini", "gone", 1e-3),
        row("s", "mini", "unjudged", np.nan, tolerance=None, value=2.0),
        row("s", "mujoco", "same", 5e-3),
    ]
    after = [
        row("s", "mini", "grew", 1.1e-3),
        row("s", "mini", "shrank", 0.9e-3),
        row("s", "mini", "within_noise", 1e-3 * (1 + 0.5 * RELATIVE_NOISE)),
        row("s", "mini", "now_fails", 0.0100005),  # Δ below the floor, but the verdict changed
        row("s", "mini", "arrived", 1e-3),
        row("s", "mini", "unjudged", np.nan, tolerance=None, value=2.5),
        row("s", "mujoco", "same", 5e-3),
    ]
    assert tolerance == before[0]["tolerance"]
    a = write_run(tmp_path / "a", before, night(1))
    b = write_run(tmp_path / "b", after, night(2), {"mini": "0.2.0", "mujoco": "3.3.7"})
    out = tmp_path / "cmp"
    assert main(["compare", str(a), str(b), "--out", str(out)]) == EXIT_OK
    assert "6 rows moved" in capsys.readouterr().out
    table = pd.read_csv(out / "compare.csv")
    assert tuple(table.columns) == COMPARE_COLUMNS
    assert dict(zip(table["metric"], table["change"], strict=True)) == {
        "grew": "regressed",
        "now_fails": "regressed",
        "shrank": "improved",
        "unjudged": "changed",
        "arrived": "new",
        "gone": "missing",
    }
    grew = table[table["metric"] == "grew"].iloc[0]
    assert (grew["error_a"], grew["error_b"]) == pytest.approx((1e-3, 1.1e-3))
    assert (grew["verdict_a"], grew["verdict_b"]) == ("passed", "passed")
    assert grew["engine_version_a"] == "0.1.0" and grew["engine_version_b"] == "0.2.0"
    html = (out / "compare.html").read_text()
    assert html.count('<td class="regressed">') == 2 and "0.1.0 → 0.2.0" in html

    url = f"sqlite:///{tmp_path / 'h.sqlite'}"
    ids = [history.record_run(folder, url) for folder in (a, b)]
    by_id = tmp_path / "by_id"
    assert main(["compare", str(ids[0]), str(ids[1]), "--db", url, "--out", str(by_id)]) == EXIT_OK
    pd.testing.assert_frame_equal(pd.read_csv(by_id / "compare.csv"), table)


def test_compare_of_two_selections_compares_what_both_ran(tmp_path, capsys):
    """The nightly (projectile and bounce) against a run of the bounce alone: the bounce is
    compared, the projectile is not reported missing; against a nightly that lost the
    projectile it is."""
    url = f"sqlite:///{tmp_path / 'h.sqlite'}"
    nightly = [row("projectile", "mini", "energy_drift", 1e-3), row("bounce", "mini", "e", 1e-3)]
    ad_hoc = [row("bounce", "mini", "e", 2e-3)]
    runs = ((nightly, NIGHTLY), (ad_hoc, BOUNCE_ONLY), (ad_hoc, NIGHTLY))
    for day, (rows, selection) in enumerate(runs, start=1):
        history.record_run(write_run(tmp_path / f"r{day}", rows, night(day), None, selection), url)

    def changes(*flags: str) -> dict[str, str]:
        out = tmp_path / "cmp"
        assert main(["compare", *flags, "--db", url, "--out", str(out)]) == EXIT_OK
        table = pd.read_csv(out / "compare.csv")
        return dict(zip(table["scenario"], table["change"], strict=True))

    assert changes("1", "2") == {"bounce": "regressed"}
    printed = capsys.readouterr().out
    assert "1 rows of 1 (scene, engine) pairs only one run ran left out" in printed
    page = (tmp_path / "cmp" / "compare.html").read_text()
    assert (
        history.selection_key(BOUNCE_ONLY) in page and "projectile · mini (run A, 1 rows)" in page
    )
    assert changes("1", "2", "--selection", "all") == {
        "bounce": "regressed",
        "projectile": "missing",
    }
    assert changes("1", "3") == {"bounce": "regressed", "projectile": "missing"}  # one selection
    assert changes(str(tmp_path / "r1"), str(tmp_path / "r2")) == {"bounce": "regressed"}
    assert "left out" in capsys.readouterr().out  # folders carry their selection too


@pytest.mark.parametrize(
    ("arguments", "says"),
    [
        (
            ["compare", "{tmp}/nowhere", "{tmp}/run"],
            "nowhere: no such run folder, and not a run id",
        ),
        (["compare", "{tmp}/run", "7", "--db", "{url}"], "run 7: no such run"),
        (
            ["compare", "1", "2", "--db", "{tmp}/missing.sqlite"],
            "missing.sqlite: no history database",
        ),
        (["compare", "{tmp}/empty", "{tmp}/run"], "results.csv: cannot be read"),
        (["history", "--db", "{tmp}/missing.sqlite"], "missing.sqlite: no history database"),
        (["history", "--db", "nosuchdialect://x"], "not a usable database URL"),
        (
            ["history", "--db", "{url}", "--selection", "nightly"],
            "expected latest, all, unrecorded",
        ),
        (["history", "--db", "{url}", "--selection", "0123abcd"], "no recorded run has it"),
        (["compare", "1", "1", "--db", "{url}", "--selection", "latest"], "expected shared or all"),
        (["history", "--db", "postgresql+nosuchdriver://u:hunter2@h/d"], "u:***@h/d"),
        (["history", "--db", "{tmp}/run/results.csv"], "cannot open (file is not a database)"),
    ],
)
def test_bad_input_exits_2_with_one_line(tmp_path, capsys, arguments, says):
    folder = write_run(tmp_path / "run", [row("s", "mini", "m", 1e-3)], night(1))
    (tmp_path / "empty").mkdir()
    url = f"sqlite:///{tmp_path / 'h.sqlite'}"
    history.record_run(folder, url)
    argv = [a.format(tmp=tmp_path, url=url) for a in arguments]
    assert main(argv) == EXIT_BAD_INPUT
    captured = capsys.readouterr()
    assert captured.out == ""
    assert len(message_lines(captured.err)) == 1, captured.err
    assert says in captured.err and "Traceback" not in captured.err
    assert "hunter2" not in captured.err  # a password is never printed
    assert not (tmp_path / "missing.sqlite").exists()  # reading never creates a database
