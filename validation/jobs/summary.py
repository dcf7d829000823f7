"""``physval run --summary FILE``: the run's summary in Markdown, for ``$GITHUB_STEP_SUMMARY``
and merge-request notes.

The same content as the CI log (``terminal.log_summary``) in the same words: the headline, the
count of every class, the new failures and regressions with the baseline's error before the
new one, the failing rows' table, the compact matrix and the engines not installed.
"""

from __future__ import annotations

import os
from pathlib import Path

import pandas as pd

from validation.files import Written, file_target_problem
from validation.jobs.plan import BadInputError
from validation.jobs.terminal import (
    NAMED_NEWS,
    compact_matrix,
    install_lines,
    judged_table,
    shown_value,
)
from validation.report.news import NEWS_WORDS, class_counts, headline, news_selections

SUMMARY_MARK = "<!-- physval run summary -->"
"""The summary's first line: ``--summary`` replaces only a file that begins with it (or an
empty one, as ``$GITHUB_STEP_SUMMARY`` is before a step writes it)."""

SUMMARY_WRITTEN = Written("a physval summary", SUMMARY_MARK.encode())
"""How a summary physval wrote begins (``files.Written``)."""

ROW_COLUMNS = (
    "news",
    "scene",
    "engine",
    "metric",
    "value",
    "expected",
    "tolerance",
    "error",
    "baseline error",
)
"""The failing rows' table's columns: the baseline's error is filled for a regression and a
changed row."""


def check_summary_target(path: Path | None) -> None:
    """Refuse ``--summary FILE`` before any work when it is a folder, below a file, or a
    non-empty file physval did not write as a summary (``files.file_target_problem``)."""
    if path is None:
        return
    if path.is_file() and not path.is_symlink() and os.path.getsize(path) == 0:
        return
    problem = file_target_problem(path, SUMMARY_WRITTEN)
    if problem:
        raise BadInputError(f"--summary {path}: {problem}")


def _cell(text: object) -> str:
    """A Markdown table cell: pipes escaped, one line."""
    return str(text).replace("|", "\\|").replace("\n", " ")


def summary_markdown(rows: list[dict], comparison: pd.DataFrame | None = None) -> str:
    """The run's Markdown summary (the module's docstring says what it holds)."""
    table = judged_table(rows)
    selected = news_selections(table, comparison)
    counts = class_counts(table, selected)
    lines = [
        SUMMARY_MARK,
        "## physval run",
        "",
        f"**{headline(table, selected)}**",
        "",
        "| class | rows |",
        "| --- | ---: |",
        *(f"| {word} | {n} |" for word, n in counts.items()),
        f"| total | {len(table)} |",
        "",
        *(f"- {line}" for line in install_lines(rows)),
    ]
    failing = [(key, row) for key in NAMED_NEWS for _, row in selected[key].iterrows()]
    lines += [f"### Failing or new rows ({len(failing)})", ""]
    if failing:
        lines += ["| " + " | ".join(ROW_COLUMNS) + " |", "|" + " --- |" * len(ROW_COLUMNS)]
        for key, row in failing:
            cells = [NEWS_WORDS[key], row["scenario"], row["engine"], row["metric"]]
            cells += [shown_value(row.get(c)) for c in ("value", "expected", "tolerance", "error")]
            cells.append(shown_value(row.get("baseline_error")))
            lines.append("| " + " | ".join(map(_cell, cells)) + " |")
    else:
        lines.append("None.")
    lines += ["", "### Matrix", "", "```", *compact_matrix(rows), "```", ""]
    return "\n".join(lines)
