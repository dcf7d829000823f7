"""Result rows grouped into cases: one per (scene, engine spec), as CI tools count tests.

A case is what a CI dashboard or a pytest item shows as one test. Its rows keep their own
outcomes (``known.apply_known``'s, or the row's own verdict when none was applied); the case
reads ``error`` when a row is unstable, errored, crashed, timed out or built another model, else ``failure`` when
a check failed, else ``skipped`` when every bad row is a known finding, else ``passed``.
"""

from __future__ import annotations

import math
from collections.abc import Iterable
from dataclasses import dataclass
from numbers import Real

from validation.contract import RUN_FAILURE_STATUSES
from validation.nightly.known import KNOWN, outcome_of

FAILURE, ERROR, SKIPPED, PASSED = "failure", "error", "skipped", "passed"
"""A case's verdicts, in the words of JUnit XML (its elements) and pytest."""

MISSING = "missing"
"""The outcome of a baseline row the run lacks, as a row of its case (the baseline class)."""

OUTCOME_KINDS: dict[str, str] = {
    "failed": FAILURE,
    "unstable": ERROR,
    "model_mismatch": ERROR,
    **dict.fromkeys(RUN_FAILURE_STATUSES, ERROR),
    KNOWN: SKIPPED,
    MISSING: FAILURE,
}
"""Row outcome -> what it makes of its case. An engine that could not run the scene (unstable,
an exception, another model) is an error of the test, not a wrong answer; a known finding
that still fails is skipped; a baseline row the run lacks (``baseline.missing_case_rows``)
fails. Every other outcome (passed, no_tolerance, unsupported, fixed) passes."""

VERDICT_ORDER = (ERROR, FAILURE, SKIPPED)
"""The case's verdict is the first of these that one of its rows gives (an error hides a
failure: the engine's numbers after an instability mean nothing)."""

SHOWN_NUMBERS = ("value", "expected", "error", "tolerance", "band")
"""The numbers of a row a failure text shows, in order: what was measured against what."""


def _present(value: object) -> bool:
    return value is not None and not (isinstance(value, float) and math.isnan(value))


def _text(value: object) -> str:
    return str(value) if _present(value) else ""


def outcome(row: dict) -> str:
    """The row's outcome: ``apply_known``'s when applied, else its own verdict."""
    return outcome_of(row)


def reason(row: dict) -> str:
    """The reason of the known finding that matched the row, empty when none did."""
    return _text(row.get("known"))


def describe(row: dict) -> str:
    """One line: ``metric [outcome]: value=…, expected=…, error=…, tolerance=…, band=…; message``."""
    numbers = ", ".join(
        f"{name}={row[name]:.6g}" if isinstance(row[name], Real) else f"{name}={row[name]}"
        for name in SHOWN_NUMBERS
        if _present(row.get(name))
    )
    message = _text(row.get("message"))
    tail = "; ".join(part for part in (numbers, message) if part)
    return f"{row['metric']} [{outcome(row)}]" + (f": {tail}" if tail else "")


@dataclass(frozen=True)
class Case:
    """The rows of one (scene, engine spec)."""

    scenario: str
    engine: str
    rows: tuple[dict, ...]

    def rows_of(self, kind: str) -> list[dict]:
        """The rows whose outcome makes the case ``kind`` (FAILURE, ERROR or SKIPPED)."""
        return [row for row in self.rows if OUTCOME_KINDS.get(outcome(row)) == kind]

    @property
    def bad_rows(self) -> list[dict]:
        """The rows that fail the case: errors, then failed checks (known findings excluded)."""
        return self.rows_of(ERROR) + self.rows_of(FAILURE)

    @property
    def verdict(self) -> str:
        return next((kind for kind in VERDICT_ORDER if self.rows_of(kind)), PASSED)

    @property
    def known_reasons(self) -> list[str]:
        """The reasons of the known findings among its rows, each once, in row order."""
        reasons = (reason(row) for row in self.rows_of(SKIPPED))
        return list(dict.fromkeys(reason for reason in reasons if reason))

    @property
    def wall_time_s(self) -> float:
        times = [float(row["wall_time_s"]) for row in self.rows if _present(row.get("wall_time_s"))]
        return max(times, default=0.0)


def group_cases(rows: Iterable[dict]) -> list[Case]:
    """One case per (scenario, engine) in order of first appearance."""
    grouped: dict[tuple[str, str], list[dict]] = {}
    for row in rows:
        grouped.setdefault((str(row["scenario"]), str(row["engine"])), []).append(row)
    return [Case(scenario, engine, tuple(found)) for (scenario, engine), found in grouped.items()]
