"""Known findings (a scene's ``known:`` list) applied to result rows.

A row whose (engine spec, metric) a scene declares known reads outcome ``known`` when it
fails (a bad status: failed, unstable, model_mismatch, error) and ``fixed`` when it passes:
the finding is gone and its entry can be removed. Every other row keeps its verdict. The
outcome and the finding's reason are written next to the row (``outcome``, ``known``).
"""

from __future__ import annotations

from collections.abc import Iterable
from fnmatch import fnmatchcase

from validation.contract import BAD_STATUSES, NOT_JUDGED_STATUSES
from validation.scenario.engine_spec import parse_engine_spec
from validation.scenario.schema import ANY_METRIC, KnownFinding, Scenario

KNOWN, FIXED = "known", "fixed"
"""The two outcomes a known finding gives a row (CI jobs and scene files depend on the names)."""


def row_verdict(status: str, passed: object) -> str:
    """A row's own outcome before known findings: its bad status, ``failed``, ``passed``,
    ``no_tolerance`` (measured, not judged), ``unsupported`` or ``not_installed``."""
    if status in BAD_STATUSES:
        return status
    if status in NOT_JUDGED_STATUSES:
        return status
    if passed is True or passed == "True":
        return "passed"
    if passed is False or passed == "False":
        return "failed"
    return "no_tolerance"


def outcome_of(row: dict) -> str:
    """A row's outcome: its ``outcome`` column when ``apply_known`` wrote one, else its own
    verdict (``row_verdict``)."""
    outcome = row.get("outcome")
    if isinstance(outcome, str) and outcome:
        return outcome
    status = row.get("status")
    return row_verdict(status if isinstance(status, str) else "", row.get("passed"))


def _label(spec: str) -> str:
    return parse_engine_spec(spec).label


def covers(pattern: str, metric: str) -> bool:
    """Whether a finding's ``metric`` covers a row's: the name itself, ``*`` (every row), or a
    shell-style pattern (``velocity_after_impact.*``: every body's)."""
    return pattern == ANY_METRIC or fnmatchcase(metric, pattern)


def matching_finding(
    findings: Iterable[KnownFinding], engine: str, metric: str
) -> KnownFinding | None:
    """The first finding of ``findings`` that covers the row (``engine`` a spec label)."""
    for finding in findings:
        if _label(finding.engine) == engine and covers(finding.metric, metric):
            return finding
    return None


def apply_known(rows: list[dict], scenario: Scenario) -> list[dict]:
    """The rows of one scene with ``outcome`` and ``known`` (the matching finding's reason,
    empty when none) added."""
    judged = []
    for row in rows:
        verdict = row_verdict(str(row.get("status", "")), row.get("passed"))
        finding = matching_finding(scenario.known, str(row["engine"]), str(row["metric"]))
        if finding is not None and verdict in (*BAD_STATUSES, "passed"):
            verdict = FIXED if verdict == "passed" else KNOWN
        judged.append({**row, "outcome": verdict, "known": finding.reason if finding else ""})
    return judged
