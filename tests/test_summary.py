"""``physval run --summary FILE``: the Markdown summary says what results.csv says, in the
terminal's words, and is written under the same rules as the run's other outputs."""

from __future__ import annotations

import re
from pathlib import Path

import pandas as pd
import pytest

from validation.cli import main
from validation.contract import EXIT_BAD_INPUT, EXIT_FAILED
from validation.jobs.summary import SUMMARY_MARK, summary_markdown
from validation.jobs.terminal import message_lines
from validation.nightly.known import outcome_of
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
    assert "**1 rows need a look" in text
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
