"""``physval run --summary FILE``: the Markdown summary says what results.csv says, in the
terminal's words, and is written under the same rules as the run's other outputs."""

from __future__ import annotations

import json
import re
from pathlib import Path

import pandas as pd
import pytest
from markupsafe import escape
from report_fixtures import write_synthetic_run

from validation.cli import main
from validation.contract import EXIT_BAD_INPUT, EXIT_FAILED
from validation.jobs.summary import SUMMARY_MARK, summary_markdown
from validation.jobs.terminal import message_lines
from validation.nightly.known import outcome_of
from validation.report import render
from validation.report.outcomes import outcome_label

FAILING_SCENE = """\
dt: 0.001
duration: 0.5
bodies: [{name: b, shape: {type: sphere, radius: 0.1}, mass: 1.0}]
checks: {position_error: 1.0e-6, linear_momentum_drift: 1.0e-6}
"""
"""One failing check (semi-implicit Euler is off by g·dt·t/2 = 2.5 mm) and one passing."""

CLASS_ROW = re.compile(r"^\| ([a-z_ ]+) \| (\d+) \|$", re.MULTILINE)
FAILING_ROW = re.compile(r"^\| new failures \| ([^|]+ \|.+) \|$", re.MULTILINE)


def _run(tmp_path: Path, summary: Path, *extra: str) -> int:
    scene = tmp_path / "scene.yaml"
    scene.write_text(FAILING_SCENE)
    out = tmp_path / "out"
    return main(
        [
            "run",
            str(scene),
            "--engines",
            "mini",
            "--out",
            str(out),
            *extra,
            "--summary",
            str(summary),
        ]
    )


def test_summary_counts_and_failing_rows_equal_results_csv(tmp_path):
    summary = tmp_path / "new" / "folders" / "summary.md"  # parents created
    assert _run(tmp_path, summary) == EXIT_FAILED
    text = summary.read_text()
    results = pd.read_csv(tmp_path / "out" / "results.csv", keep_default_na=False)
    outcomes = [outcome_of(row) for row in results.to_dict("records")]
    expected = {outcome_label(o): outcomes.count(o) for o in set(outcomes)}
    said = {word: int(n) for word, n in CLASS_ROW.findall(text)}
    assert said.pop("total") == len(results)
    assert said.pop("new failures") == outcomes.count("failed") == 1
    assert said.pop("regressed") == 0
    assert said == expected, (said, expected)
    assert text.startswith(SUMMARY_MARK)
    assert "**1 row needs a look" in text
    (failing,) = FAILING_ROW.findall(text)
    cells = [cell.strip() for cell in failing.split("|")]
    row = results.set_index("metric").loc["position_error"]
    assert cells[:3] == [row["scenario"], "mini", "position_error"], cells
    assert cells[3] == f"{float(row['value']):.4g}" and cells[6] == f"{float(row['error']):.4g}"
    assert "```\nmatrix (1 scenes x 1 engines" in text


def test_summary_replaces_an_empty_file_and_its_own_and_refuses_any_other(tmp_path, capsys):
    summary = tmp_path / "step_summary.md"
    summary.write_text("")  # as $GITHUB_STEP_SUMMARY is before a step writes it
    assert _run(tmp_path, summary) == EXIT_FAILED
    assert summary.read_text().startswith(SUMMARY_MARK)
    assert _run(tmp_path, summary) == EXIT_FAILED  # its own summary is replaced
    notes = tmp_path / "notes.md"
    notes.write_text("my notes\n")
    assert _run(tmp_path, notes) == EXIT_BAD_INPUT
    assert notes.read_text() == "my notes\n"
    (line,) = message_lines(capsys.readouterr().err)
    assert line.startswith(f"--summary {notes}: ") and "physval did not write" in line, line


@pytest.mark.parametrize("outcome", ["known", "failed"])
def test_summary_headline_counts_known_rows_and_never_says_all_passed(outcome):
    rows = [
        {
            "scenario": "s",
            "engine": "mini",
            "metric": "m",
            "status": "failed",
            "passed": False,
            "outcome": outcome,
            "error": 2.0,
            "tolerance": 1.0,
            "value": 3.0,
            "expected": 1.0,
        },
        {
            "scenario": "s",
            "engine": "mini",
            "metric": "n",
            "status": "ok",
            "passed": True,
            "outcome": "passed",
            "error": 0.0,
            "tolerance": 1.0,
            "value": 1.0,
            "expected": 1.0,
        },
    ]
    text = summary_markdown(rows)
    assert "All " not in text
    assert f"| {outcome} | 1 |" in text and "| passed | 1 |" in text


RED = ("failed", "unstable", "model_mismatch")


def _page(run_dir: Path) -> str:
    assert render.report_command(run_dir) == 0
    return (run_dir / "report.html").read_text()


def _headline(page: str) -> str:
    start = page.index('id="headline">') + len('id="headline">')
    return page[start : page.index("</div>", start)]


def test_report_headline_counts_known_rows_instead_of_saying_all_passed(tmp_path):
    """Before: "All 6 runs passed or had nothing to judge" with 3 known failures."""
    run_dir = write_synthetic_run(tmp_path)
    results = pd.read_csv(run_dir / "results.csv", keep_default_na=False)
    known = results["status"].isin(RED)
    results.loc[known, "outcome"] = "known"
    results.to_csv(run_dir / "results.csv", index=False)
    page = _page(run_dir)
    said = _headline(page)
    assert not said.startswith("All"), said
    assert said == f"No new failures; {known.sum()} of {len(results)} rows are known failures"
    classes = page[page.index('id="summary-classes"') :]
    assert f"{known.sum()} known</span>" in classes[: classes.index("</div>")]


def test_report_regressions_table_shows_the_baseline_error_next_to_the_new_one(tmp_path):
    run_dir = write_synthetic_run(tmp_path)
    results = pd.read_csv(run_dir / "results.csv", keep_default_na=False)
    results["baseline"] = "unchanged"
    regressed = (results["engine"] == "mujoco") & (results["metric"] == "energy_drift")
    results.loc[regressed & (results["scenario"] == "bounce_ladder"), "baseline"] = "regressed"
    results.to_csv(run_dir / "results.csv", index=False)
    comparison = results[["scenario", "engine", "metric", "error", "baseline"]].assign(
        baseline_error=results["error"].astype(str)
    )
    comparison.loc[results["baseline"] == "regressed", "baseline_error"] = "1.5e-4"
    comparison.to_csv(run_dir / "baseline.csv", index=False)
    page = _page(run_dir)
    news = page[page.index("news-regressed") : page.index("news-changed")]
    assert "<th>baseline error</th><th>error</th>" in news, news
    assert '<td class="num baseline-error">0.00015</td><td class="num">0.004</td>' in news, news


def test_report_shows_an_engines_notes_in_its_scenes_runs(tmp_path):
    run_dir = write_synthetic_run(tmp_path)
    provenance = json.loads((run_dir / "provenance.json").read_text())
    note = "springs and applied loads: physval's own force law (applyExternalForce)"
    provenance["scenes"]["dzhanibekov_box"]["engine_notes"] = {"pybullet": [note]}
    (run_dir / "provenance.json").write_text(json.dumps(provenance))
    page = _page(run_dir)
    card = page[page.index('<section class="scene" id="scene-dzhanibekov_box') :]
    runs = card[: card.index("</table>")]
    pybullet = runs[runs.index("<tr><td>pybullet</td>") :]
    assert escape(note) in pybullet[: pybullet.index("</tr>")], runs
    assert escape(note) not in page[: page.index('id="scenes"')]  # near the rows, not the top


def test_a_run_records_each_scenes_engine_notes_and_its_report_shows_them(tmp_path):
    _run(tmp_path, tmp_path / "summary.md")
    provenance = json.loads((tmp_path / "out" / "provenance.json").read_text())
    notes = provenance["scenes"]["scene"]["engine_notes"]["mini"]
    assert notes and notes == provenance["engines"]["mini"]["notes"]
    page = (tmp_path / "out" / "report.html").read_text()
    assert f'<ul class="engine-notes"><li>{escape(notes[0])}</li>' in page


def test_a_summary_inside_out_is_refused_before_any_work(tmp_path, capsys):
    inside = tmp_path / "out" / "summary.md"
    assert _run(tmp_path, inside) == EXIT_BAD_INPUT
    (line,) = message_lines(capsys.readouterr().err)
    assert line.startswith(f"--summary {inside}: is inside --out"), line
    assert not (tmp_path / "out").exists()
