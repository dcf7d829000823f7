"""What report.html leads with: the news since the baseline, and a scene's own sweep.

The news, in the page's order: regressions since the baseline, rows without an error whose
value changed, large improvements (``noise.LARGE_IMPROVEMENT``: unexplained until someone
explains them), new failures, fixed findings, then the divergence rows that moved with their
reference engine, the missing and unchanged rows and the known findings (collapsed). Each entry links to its scene's
card. A scene that declares ``sweep:`` gets its error-against-run-time plots in its card.
"""

from __future__ import annotations

from typing import Any

import pandas as pd
from markupsafe import Markup

from validation.contract import RUN_FAILURE_STATUSES
from validation.measure.noise import (
    FAILS_A_RUN,
    LARGE_IMPROVEMENT,
    REFERENCE_MOVED,
    large_improvement,
)
from validation.report.outcomes import OUTCOME_ORDER, outcome_label
from validation.report.sweep_page import UNITS, sweep_chart, sweep_orders

FAILING = (*RUN_FAILURE_STATUSES, "failed")
"""Outcomes that are a failure unless the baseline had them failing too."""

NEWS_SECTIONS = (
    ("regressed", "Regressions since the baseline", True),
    (
        "changed",
        "Changed (a row without an error whose value moved, an error that appeared, or a "
        "verdict that changed within its rank: fails the run)",
        True,
    ),
    (
        "large_improvements",
        f"Large improvements (error {LARGE_IMPROVEMENT:g}x smaller or more, or no longer "
        "infinite: explain them before saving the baseline again)",
        True,
    ),
    ("new_failures", "New failures", True),
    ("fixed", "Fixed (a known finding that passes: its entry can go)", True),
    (
        REFERENCE_MOVED,
        "Moved with the reference engine (divergence rows whose scene's reference engine "
        "moved and whose own engine did not: not a failure)",
        False,
    ),
    ("missing", "Missing (in the baseline, not in this run)", False),
    ("unchanged", "Unchanged since the baseline", False),
    ("known", "Known findings", False),
)
"""(key, heading, open): the news sections in order; the last ones start collapsed."""

NEWS_WORDS = {
    "regressed": "regressed",
    "changed": "changed",
    "large_improvements": "large improvements",
    "new_failures": "new failures",
    "fixed": "fixed",
    REFERENCE_MOVED: "moved with the reference",
    "missing": "missing",
    "unchanged": "unchanged",
    "known": "known",
}
"""The news sections' short words, for the terminal's news line (the same sections and counts
as the page's news: ``news_selections``)."""

MAX_NEWS_ROWS = 200
"""Rows listed per section; the rest are counted (every row is in the scene cards)."""


def _shown_error(value: Any) -> str:
    """A row's error as the news shows it: 4 significant digits, empty when it has none (a
    baseline's missing row arrives as text, an empty cell as NaN)."""
    error = pd.to_numeric(pd.Series([value]), errors="coerce").iloc[0]
    return "" if pd.isna(error) else f"{error:.4g}"


KEYS = ["scenario", "engine", "metric"]
"""The columns that name a row in results.csv and baseline.csv."""


def with_baseline_error(rows: pd.DataFrame, baseline: pd.DataFrame | None) -> pd.DataFrame:
    """``rows`` with ``baseline_error``: the error the baseline's row had (from the run's
    baseline.csv; NaN without one), so a regression shows before and after."""
    rows = rows.drop(columns=["baseline_error"], errors="ignore")
    if baseline is None or "baseline_error" not in baseline or rows.empty:
        return rows.assign(baseline_error=float("nan"))
    before = baseline[[*KEYS, "baseline_error"]].drop_duplicates(KEYS)
    joined = rows.reset_index().merge(before, on=KEYS, how="left").set_index("index")
    joined.index.name = rows.index.name
    return joined


def _entries(rows: pd.DataFrame, anchors: dict[str, str]) -> list[dict[str, Any]]:
    return [
        {
            "scene": r["scenario"],
            "anchor": anchors.get(r["scenario"], ""),
            "engine": r["engine"],
            "metric": r["metric"],
            "outcome": r.get("outcome", ""),
            "error": _shown_error(r.get("error")),
            "before": _shown_error(r.get("baseline_error")),
            "note": str(r.get("news_note", "") or r.get("known", "") or r.get("message", "") or ""),
        }
        for _, r in rows.head(MAX_NEWS_ROWS).iterrows()
    ]


def _numbers(table: pd.DataFrame, column: str) -> pd.Series:
    """A column as numbers (NaN where absent or not a number: baseline.csv is read as text)."""
    if column not in table:
        return pd.Series(float("nan"), index=table.index)
    return pd.to_numeric(table[column], errors="coerce")


def large_improvements(baseline: pd.DataFrame | None) -> pd.DataFrame:
    """The ``improved`` rows of a run's baseline.csv whose error shrank at least
    ``LARGE_IMPROVEMENT`` times (or from inf to finite), each with a note of both errors."""
    if baseline is None or "baseline" not in baseline:
        return pd.DataFrame(columns=["scenario", "engine", "metric"])
    before, now = _numbers(baseline, "baseline_error"), _numbers(baseline, "error")
    large = [
        cls == "improved" and large_improvement(a, b)
        for cls, a, b in zip(baseline["baseline"], before, now, strict=True)
    ]
    found = baseline[large].copy()
    found["news_note"] = [
        f"error {a:.4g} in the baseline, {b:.4g} now; the engine's version and the scene file "
        "are the baseline's"
        for a, b in zip(before[large], now[large], strict=True)
    ]
    return found


def news_selections(table: pd.DataFrame, baseline: pd.DataFrame | None) -> dict[str, pd.DataFrame]:
    """The rows of each news section (``NEWS_SECTIONS``) of a judged results table (an
    ``outcome`` column, a ``baseline`` class when run against one) and the run's baseline.csv:
    what the page and the terminal both count."""
    classes = table["baseline"].fillna("") if "baseline" in table else pd.Series("", table.index)
    failing = table["outcome"].isin(FAILING)
    missing = (
        baseline[baseline["baseline"] == "missing"] if baseline is not None else table.iloc[0:0]
    )
    return {
        "regressed": with_baseline_error(table[classes == "regressed"], baseline),
        "changed": with_baseline_error(table[classes == "changed"], baseline),
        "large_improvements": large_improvements(baseline),
        "new_failures": table[failing & (classes != "unchanged") & ~classes.isin(FAILS_A_RUN)],
        "fixed": table[table["outcome"] == "fixed"],
        REFERENCE_MOVED: table[classes == REFERENCE_MOVED],
        "missing": missing,
        "unchanged": table[classes == "unchanged"],
        "known": table[table["outcome"] == "known"],
    }


HEADLINE_NEWS = ("new_failures", "regressed", "changed", "missing")
"""The news counted in every headline next to the outcomes (what fails a run), in the same
words in the terminal, the ``--summary`` file and report.html."""


def class_counts(table: pd.DataFrame, selected: dict[str, pd.DataFrame]) -> dict[str, int]:
    """Rows per outcome that occurs (worst first, ``OUTCOME_ORDER``), then the news counts
    (``HEADLINE_NEWS``: new failures and regressions always, changed and missing when there
    are any), keyed by the words every headline uses."""
    found = table["outcome"].value_counts()
    counts = {outcome_label(o): int(found[o]) for o in OUTCOME_ORDER if found.get(o, 0)}
    for key in HEADLINE_NEWS:
        if len(selected[key]) or key in ("new_failures", "regressed"):
            counts[NEWS_WORDS[key]] = len(selected[key])
    return counts


def headline(table: pd.DataFrame, selected: dict[str, pd.DataFrame]) -> str:
    """The run's verdict in one sentence, never "all passed" while a row fails: the new
    failures and regressions that need a look, else the known failures that remain, else
    that every run passed or had nothing to judge."""
    new = sum(len(selected[key]) for key in HEADLINE_NEWS)
    known = int((table["outcome"] == "known").sum())
    if new:
        rows = "1 row needs" if new == 1 else f"{new} rows need"
        return f"{rows} a look (new failures, regressions, changed or missing)"
    if known:
        return f"No new failures; {known} of {len(table)} rows are known failures"
    return f"All {len(table)} rows passed or had nothing to judge"


def build_news(
    table: pd.DataFrame, baseline: pd.DataFrame | None, anchors: dict[str, str]
) -> dict[str, Any]:
    """The news sections (``NEWS_SECTIONS``) of a judged results table, each with its count,
    listed rows and how many more there are; ``against_baseline`` says whether it had one."""
    selected = news_selections(table, baseline)
    sections = []
    for key, heading, is_open in NEWS_SECTIONS:
        rows = selected[key]
        sections.append(
            {
                "key": key,
                "heading": heading,
                "open": is_open and len(rows) > 0,
                "count": len(rows),
                "rows": _entries(rows, anchors),
                "hidden": max(0, len(rows) - MAX_NEWS_ROWS),
            }
        )
    against = "baseline" in table and table["baseline"].fillna("").astype(bool).any()
    return {"sections": sections, "against_baseline": bool(against)}


def build_sweep_cards(sweep: pd.DataFrame | None, scene: str) -> list[dict[str, Any]]:
    """The scene's sweep (a run's sweep.csv), one chart per sweep metric with its fitted
    orders; empty when the scene declares none."""
    if sweep is None or sweep.empty:
        return []
    mine = sweep[sweep["scenario"] == scene]
    cards = []
    for metric, unit in UNITS.items():
        curve = mine[(mine["metric"] == metric) & mine["error"].notna()]
        if curve.empty or not (curve["error"] > 0).any():
            continue
        orders = sweep_orders(sweep.assign(of=sweep.get("of", "")), scene, metric)
        cards.append(
            {
                "metric": metric,
                "reference": str(curve["expected_kind"].iloc[0])
                if "expected_kind" in curve
                else "",
                "orders": {e: f"{o:.2f}" for e, o in orders.items() if pd.notna(o)},
                "svg": Markup(sweep_chart(curve, orders, unit)),
            }
        )
    return cards
