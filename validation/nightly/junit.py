"""Result rows as JUnit XML, the format CI dashboards read (Jenkins, GitLab, GitHub reporters).

One ``<testcase>`` per (scene, engine spec): ``classname`` the scene, ``name`` the engine spec
label, ``time`` the run's wall time. A case with failed checks (or baseline rows the run
lacks, outcome ``missing``) carries one ``<failure>`` whose text has a line per failed row (metric, value, expected, error, tolerance, band, message); a
case whose engine was unstable, raised or built another model carries an ``<error>`` the same
way; a case whose every bad row is a known finding is ``<skipped message="reason">``. Known rows
of a case that also fails, and ``fixed`` rows (a known finding that now passes), are listed in
its ``<system-out>``. ``<testsuite>`` (and ``<testsuites>``) count the cases: ``tests``,
``failures`` and ``errors`` (cases carrying that element), ``skipped``.
"""

from __future__ import annotations

import xml.etree.ElementTree as ET
from pathlib import Path

import pandas as pd

from validation.files import Written, write_atomically
from validation.nightly.cases import (
    ERROR,
    FAILURE,
    SKIPPED,
    Case,
    describe,
    group_cases,
    outcome,
    reason,
)
from validation.nightly.known import FIXED, KNOWN

SUITE_NAME = "physval"
"""The ``<testsuite name>``: the harness, as pytest names its suite ``pytest``."""

PROBLEM_ELEMENTS = {FAILURE: "failure", ERROR: "error"}
"""Case verdict -> the JUnit element that carries its rows (JUnit's own two kinds of bad test)."""

NOTES = {
    KNOWN: "known (the case fails for other rows too): ",
    FIXED: "fixed (the known finding no longer fails; its entry can go): ",
}
"""Row outcome -> the prefix of its line in ``<system-out>``: rows a reader should see that do
not decide the case."""

XML_DECLARATION = '<?xml version="1.0" encoding="utf-8"?>\n'

JUNIT_WRITTEN = Written(
    "a physval JUnit file", f'{XML_DECLARATION}<testsuites name="{SUITE_NAME}"'.encode()
)
"""How the JUnit XML begins: ``--junit`` replaces only a file that does."""


def _summary(rows: list[dict]) -> str:
    outcomes = "/".join(dict.fromkeys(outcome(row) for row in rows))
    return f"{len(rows)} row(s) {outcomes}: " + ", ".join(str(row["metric"]) for row in rows)


def _problem(case: Case, kind: str) -> ET.Element | None:
    rows = case.rows_of(kind)
    if not rows:
        return None
    element = ET.Element(PROBLEM_ELEMENTS[kind], message=_summary(rows), type=outcome(rows[0]))
    element.text = "\n".join(describe(row) for row in rows)
    return element


def _skipped(case: Case) -> ET.Element:
    element = ET.Element("skipped", message="; ".join(case.known_reasons) or "known finding")
    element.text = "\n".join(describe(row) for row in case.rows_of(SKIPPED))
    return element


def _notes(case: Case, skipped: bool) -> ET.Element | None:
    shown = {FIXED} if skipped else set(NOTES)
    lines = [
        NOTES[outcome(row)] + describe(row) + (f" ({reason(row)})" if reason(row) else "")
        for row in case.rows
        if outcome(row) in shown
    ]
    if not lines:
        return None
    element = ET.Element("system-out")
    element.text = "\n".join(lines)
    return element


def case_element(case: Case) -> ET.Element:
    """The ``<testcase>`` of one (scene, engine spec)."""
    element = ET.Element(
        "testcase", classname=case.scenario, name=case.engine, time=f"{case.wall_time_s:.3f}"
    )
    children = [_problem(case, kind) for kind in PROBLEM_ELEMENTS]
    skipped = case.verdict == SKIPPED
    children += [_skipped(case) if skipped else None, _notes(case, skipped)]
    element.extend(child for child in children if child is not None)
    return element


def counts(cases: list[Case]) -> dict[str, int]:
    """``tests``, ``failures``, ``errors``, ``skipped`` as the suite reports them."""
    return {
        "tests": len(cases),
        "failures": sum(bool(case.rows_of(FAILURE)) for case in cases),
        "errors": sum(bool(case.rows_of(ERROR)) for case in cases),
        "skipped": sum(case.verdict == SKIPPED for case in cases),
    }


def junit_tree(cases: list[Case]) -> ET.Element:
    """``<testsuites>`` holding one ``<testsuite>`` of every case."""
    totals = {key: str(value) for key, value in counts(cases).items()}
    time = f"{sum(case.wall_time_s for case in cases):.3f}"
    root = ET.Element("testsuites", name=SUITE_NAME, time=time, **totals)
    suite = ET.SubElement(root, "testsuite", name=SUITE_NAME, time=time, **totals)
    suite.extend(case_element(case) for case in cases)
    return root


def write_junit(rows: list[dict] | pd.DataFrame, path: Path) -> None:
    """Write the JUnit XML of result rows (with ``apply_known``'s ``outcome`` and ``known``
    columns, or without: then every bad row counts) to ``path``, atomically."""
    records = rows.to_dict("records") if isinstance(rows, pd.DataFrame) else list(rows)
    root = junit_tree(group_cases(records))
    ET.indent(root)
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    write_atomically(path, XML_DECLARATION + ET.tostring(root, encoding="unicode") + "\n")
