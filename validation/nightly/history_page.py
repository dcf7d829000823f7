"""``physval history``: history.html, the trend of every (scene, engine, metric) over the runs.

Phases: read the history (``history.load_history``) -> one array per quantity, series x runs
(``series_arrays``) -> steps per series (``steps.detect_steps``, batched) -> views of the series,
the moved ones, the regressions since the baseline (``build_context``) -> sparklines and trend
plots -> template (``templates/history.html.j2``) -> write atomically.

Each series is judged on its ``error`` (the quantity the noise rule judges), or on its
``value`` when it never had an expected value. The page stays usable with hundreds of series:
every series is one row with a small SVG sparkline, grouped by scene in folded sections; only
the scenes with a moved or regressed series are open, and only those series get a full plot.
"""

from __future__ import annotations

import math
import sys
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd
from matplotlib.figure import Figure
from matplotlib.ticker import MaxNLocator

from validation.contract import EXIT_BAD_INPUT, EXIT_OK
from validation.files import write_atomically
from validation.measure.noise import NOISE_RULE
from validation.nightly.history import (
    KEY_COLUMNS,
    TREND_COLUMNS,
    History,
    HistoryInputError,
    database_url,
    load_history,
    sqlite_file,
)
from validation.nightly.known import row_verdict
from validation.nightly.pages import figure_svg, render_page
from validation.nightly.steps import PENALTY_PER_LOG_RUN, Step, detect_steps, segment_levels
from validation.report.build import format_number, slug

HISTORY_PAGE = "history.html"
TEMPLATE = "history.html.j2"

SPARK_WIDTH, SPARK_HEIGHT, SPARK_PAD = 160, 26, 3
"""Sparkline size in px (one short table row) and the margin that keeps end dots whole. A
sparkline is a polyline the template draws, not a matplotlib figure: the smallest figure costs
6 ms to save as SVG (measured), 6 s for 1,000 series; matplotlib draws the full trend plots."""

SPARK_POINTS = SPARK_WIDTH
"""At most this many points per sparkline (each bucket of runs keeps its min and max, as
``plots.thin_line`` does, but batched over all series): spikes survive, the page stays small."""

MAX_TREND_PLOTS = 24
"""Full trend plots per page (regressed first, then the latest steps): one matplotlib figure
costs 45-90 ms here (measured, idle to loaded 2-core machine), so 24 keep a year of history
within its 5 s budget; the other expanded series keep their sparkline and step verdict."""

TREND_FIGURE_IN = (9.0, 2.4)
"""One wide, low plot per expanded series."""

TICKS_PER_AXIS = 5
"""Labelled ticks per axis (as report.html's plots)."""

COMMIT_DIGITS = 10
"""A commit is shown by its first digits."""

BASELINE_CLASSES = ("regressed", "improved", "new", "missing", "scene_changed", "unchanged")
"""The baseline classes of a run's ``baseline`` column (issue 12), news first."""

VERSION_COLOUR, STEP_COLOUR, LINE_COLOUR, LEVEL_COLOUR = "#999999", "#c0392b", "#0072B2", "#D55E00"
"""Engine-version change marks (grey), a detected step (red), the trend (blue), fitted levels."""


@dataclass
class SeriesView:
    """One (scenario, engine, metric) over the runs, as the page shows it."""

    scenario: str
    engine: str
    metric: str
    anchor: str
    quantity: str
    """``error`` or ``value``: what the trend line and the step detection use."""
    values: np.ndarray
    """(runs,) the quantity per run, NaN where the run has no such row."""
    tolerance: float
    steps: list[Step]
    version_changes: list[tuple[int, str, str]]
    """(run position, old version, new version) of this series' engine."""
    last: dict[str, Any] = field(default_factory=dict)
    """The last run's row (verdict, baseline class, value, error), empty if absent there."""
    spark_at: np.ndarray = field(default_factory=lambda: np.zeros(0, dtype=int))
    """The run positions its sparkline draws (``spark_positions``)."""
    plot: str = ""

    @property
    def regressed(self) -> bool:
        return self.last.get("baseline") == "regressed"

    @property
    def expanded(self) -> bool:
        return bool(self.steps) or self.regressed


# --- phase 2: arrays ----------------------------------------------------------------------


def series_arrays(history: History) -> tuple[pd.DataFrame, dict[str, np.ndarray]]:
    """The series keys (sorted by scene, engine, metric) and, per trend column, an array
    (series, runs) of it (NaN where a run lacks the row)."""
    rows = history.trend
    positions = pd.Index(history.runs["id"]).get_indexer(rows["run_id"])
    codes, keys = pd.factorize(pd.MultiIndex.from_frame(rows[list(KEY_COLUMNS)]), sort=True)
    shape = (len(keys), len(history.runs))
    arrays = {}
    for column in TREND_COLUMNS:
        arrays[column] = np.full(shape, np.nan)
        arrays[column][codes, positions] = rows[column].to_numpy(float)
    return keys.to_frame(index=False), arrays


def version_changes(runs: pd.DataFrame) -> dict[str, list[tuple[int, str, str]]]:
    """Engine label -> (run position, old version, new version) wherever the version differs
    from the previous run that ran the engine (``runs.engine_versions``, from provenance)."""
    found: dict[str, list[tuple[int, str, str]]] = {}
    previous: dict[str, str] = {}
    for position, versions in enumerate(runs["engine_versions"]):
        for label, version in (versions or {}).items():
            if label in previous and previous[label] != version:
                found.setdefault(label, []).append((position, previous[label], version))
            previous[label] = version
    return found


def spark_positions(values: np.ndarray, max_points: int = SPARK_POINTS) -> np.ndarray:
    """Per series (rows of ``values``), the run positions a sparkline draws, in order: all of
    them for a short history, else each bucket's min and max (NaN buckets keep a gap)."""
    count, n = values.shape
    if n <= max_points:
        return np.broadcast_to(np.arange(n), (count, n))
    per = -(-n // (max_points // 2))
    buckets = -(-n // per)
    blocks = np.full((count, buckets * per), np.nan)
    blocks[:, :n] = values
    blocks = blocks.reshape(count, buckets, per)
    finite = np.isfinite(blocks)
    low = np.where(finite, blocks, np.inf).argmin(axis=2)
    high = np.where(finite, blocks, -np.inf).argmax(axis=2)
    offsets = np.arange(buckets) * per
    pairs = np.stack([np.minimum(low, high), np.maximum(low, high)], axis=2) + offsets[:, None]
    return pairs.reshape(count, -1)


def last_finite(array: np.ndarray) -> np.ndarray:
    """Per row, its last finite entry (NaN when none)."""
    return pd.DataFrame(array).ffill(axis=1).iloc[:, -1].to_numpy(float) if array.size else array


# --- phase 3: views -----------------------------------------------------------------------


def latest_rows(history: History) -> dict[tuple[str, str, str], Any]:
    """(scenario, engine, metric) -> the latest run's row."""
    latest = history.latest
    keys = zip(*(latest[c] for c in KEY_COLUMNS), strict=True)
    return {key: row for key, (_, row) in zip(keys, latest.iterrows(), strict=True)}


def _last_row(row: pd.Series | None) -> dict[str, Any]:
    if row is None:
        return {}
    verdict = row_verdict(str(row["status"]), row["passed"])
    outcome = row.get("outcome")
    baseline = row.get("baseline")
    return {
        "verdict": outcome if isinstance(outcome, str) and outcome else verdict,
        "baseline": baseline if isinstance(baseline, str) and baseline else "",
        "value": format_number(row["value"]),
        "error": format_number(row["error"]),
        "tolerance": format_number(row["tolerance"]),
        "engine_version": row["engine_version"],
    }


def build_series(history: History) -> list[SeriesView]:
    """Every series of the history with its steps and engine-version changes."""
    if history.trend.empty or history.runs.empty:
        return []
    keys, arrays = series_arrays(history)
    latest = latest_rows(history)
    use_error = np.isfinite(arrays["error"]).any(axis=1)
    quantity = np.where(use_error[:, None], arrays["error"], arrays["value"])
    tolerance = last_finite(arrays["tolerance"])
    steps = detect_steps(quantity, tolerance)
    changes = version_changes(history.runs)
    spark_at = spark_positions(quantity)
    taken: set[str] = set()
    return [
        SeriesView(
            scenario=scenario,
            engine=engine,
            metric=metric,
            anchor=slug(f"{scenario}-{engine}-{metric}", taken),
            quantity="error" if use_error[i] else "value",
            values=quantity[i],
            tolerance=float(tolerance[i]),
            steps=steps[i],
            version_changes=changes.get(engine, []),
            last=_last_row(latest.get((scenario, engine, metric))),
            spark_at=spark_at[i],
        )
        for i, (scenario, engine, metric) in enumerate(keys.itertuples(index=False))
    ]


# --- phase 4: sparklines and plots ------------------------------------------------------


def sparkline(view: SeriesView) -> dict[str, Any]:
    """The geometry of one sparkline (px): polylines (split at missing runs), the version marks
    (x), the step dots and the last point; the template draws them."""
    n = view.values.size
    finite = view.values[np.isfinite(view.values)]
    if finite.size == 0:
        return {"lines": [], "marks": [], "steps": [], "last": None}
    low, high = float(finite.min()), float(finite.max())
    span = high - low if high > low else 1.0
    width, height = SPARK_WIDTH - 2 * SPARK_PAD, SPARK_HEIGHT - 2 * SPARK_PAD

    def x(position: float) -> float:
        return SPARK_PAD + width * (position / (n - 1) if n > 1 else 0.5)

    def y(value: float) -> float:
        fraction = (value - low) / span if high > low else 0.5
        return SPARK_PAD + height * (1.0 - fraction)

    lines, current = [], []
    for position, value in zip(view.spark_at, view.values[view.spark_at], strict=True):
        if math.isnan(value):
            lines, current = ([*lines, current] if current else lines), []
            continue
        current.append(f"{x(position):.1f},{y(value):.1f}")
    lines = [" ".join(line) for line in ([*lines, current] if current else lines)]
    present = np.nonzero(np.isfinite(view.values))[0]
    return {
        "lines": lines,
        "marks": [round(x(p), 1) for p, _, _ in view.version_changes],
        "steps": [
            (round(x(s.at), 1), round(y(view.values[s.at]), 1))
            for s in view.steps
            if math.isfinite(view.values[s.at])
        ],
        "last": (round(x(present[-1]), 1), round(y(view.values[present[-1]]), 1)),
    }


def trend_plot(view: SeriesView, run_ids: np.ndarray) -> str:
    """The series against run id: the trend, its fitted levels, the steps (red) and the
    engine-version changes (grey, labelled), and the tolerance when it is within sight."""
    figure = Figure(figsize=TREND_FIGURE_IN)
    axis = figure.subplots()
    axis.plot(run_ids, view.values, color=LINE_COLOUR, linewidth=1.2)
    starts = [0, *(s.at for s in view.steps)]
    stops = [*starts[1:], view.values.size]
    for start, stop, level in zip(starts, stops, segment_levels(view.values, starts), strict=True):
        axis.hlines(level, run_ids[start], run_ids[stop - 1], color=LEVEL_COLOUR, linewidth=1)
    for step in view.steps:
        axis.axvline(run_ids[step.at], color=STEP_COLOUR, linewidth=1.2)
    for position, old, new in view.version_changes:
        axis.axvline(run_ids[position], color=VERSION_COLOUR, linestyle="--", linewidth=1)
        axis.annotate(
            f"{old} → {new}",
            (run_ids[position], 1.0),
            xycoords=("data", "axes fraction"),
            fontsize=7,
            color="#555555",
            rotation=90,
            va="top",
            ha="right",
        )
    finite = view.values[np.isfinite(view.values)]
    if view.quantity == "error" and finite.size and 0 < view.tolerance <= 2 * finite.max():
        axis.axhline(view.tolerance, color="#333333", linestyle=":", linewidth=1)
    axis.xaxis.set_major_locator(MaxNLocator(TICKS_PER_AXIS, integer=True))
    axis.yaxis.set_major_locator(MaxNLocator(TICKS_PER_AXIS))
    axis.set_xlabel("run id", fontsize=8)
    axis.set_ylabel(view.quantity, fontsize=8)
    axis.tick_params(labelsize=8)
    axis.grid(True, color="#e6e6e6", linewidth=0.6)
    figure.subplots_adjust(left=0.09, right=0.99, bottom=0.2, top=0.95)
    return figure_svg(figure, f"history-{view.anchor}")


# --- phase 3 (continued): the page's context ------------------------------------------


def _run_label(runs: pd.DataFrame, position: int) -> dict[str, str]:
    run = runs.iloc[position]
    created = run["created"]
    return {
        "id": str(run["id"]),
        "created": "" if pd.isna(created) else str(created)[:19],
        "commit": str(run["commit"] or "")[:COMMIT_DIGITS],
    }


def _step_text(view: SeriesView, step: Step) -> str:
    grew = "grew" if step.direction > 0 else "shrank"
    return f"{view.quantity} {format_number(step.before)} → {format_number(step.after)} ({grew})"


def moved_rows(series: list[SeriesView], runs: pd.DataFrame) -> list[dict[str, Any]]:
    """One row per series with a step: its latest step, the run it happened at and the engine
    version change at that run (the usual explanation), latest steps first."""
    found = []
    for view in series:
        if not view.steps:
            continue
        step = view.steps[-1]
        change = [f"{old} → {new}" for p, old, new in view.version_changes if p == step.at]
        found.append(
            {
                "view": view,
                "at": step.at,
                "run": _run_label(runs, step.at),
                "change": _step_text(view, step),
                "worse": step.direction > 0,
                "steps": len(view.steps),
                "version_change": change[0] if change else "",
            }
        )
    return sorted(found, key=lambda row: (-row["at"], row["view"].anchor))


def baseline_summary(history: History, series: list[SeriesView]) -> dict[str, Any] | None:
    """The last run's baseline classes (counts, and the regressed series); None when the last
    run carries none."""
    classes = history.latest["baseline"].dropna()
    classes = classes[classes != ""]
    if classes.empty:
        return None
    counts = classes.value_counts()
    return {
        "counts": [(name, int(counts.get(name, 0))) for name in BASELINE_CLASSES],
        "regressed": [view for view in series if view.regressed],
    }


def attach_plots(series: list[SeriesView], runs: pd.DataFrame) -> int:
    """Full trend plots for the expanded series, regressed first then latest steps, at most
    ``MAX_TREND_PLOTS``; returns how many expanded series went without one."""
    expanded = [view for view in series if view.expanded]
    expanded.sort(key=lambda v: (not v.regressed, -(v.steps[-1].at if v.steps else -1), v.anchor))
    run_ids = runs["id"].to_numpy()
    for view in expanded[:MAX_TREND_PLOTS]:
        view.plot = trend_plot(view, run_ids)
    return max(0, len(expanded) - MAX_TREND_PLOTS)


def build_context(history: History, source: str) -> dict[str, Any]:
    """Everything history.html shows."""
    series = build_series(history)
    unplotted = attach_plots(series, history.runs)
    scenes: dict[str, list[SeriesView]] = {}
    for view in series:
        scenes.setdefault(view.scenario, []).append(view)
    runs = history.runs
    taken = {view.anchor for view in series}
    return {
        "source": source,
        "run_count": len(runs),
        "first": _run_label(runs, 0) if len(runs) else None,
        "latest": _run_label(runs, len(runs) - 1) if len(runs) else None,
        "runs": [
            {
                **_run_label(runs, i),
                "versions": runs["engine_versions"].iloc[i],
                "command": runs["command"].iloc[i],
                "folder": runs["folder"].iloc[i],
            }
            for i in range(len(runs) - 1, -1, -1)
        ],
        "series_count": len(series),
        "moved": moved_rows(series, runs),
        "baseline": baseline_summary(history, series),
        "unplotted": unplotted,
        "max_plots": MAX_TREND_PLOTS,
        "run_ids": [str(i) for i in runs["id"]],
        "scenes": [
            {
                "name": name,
                "anchor": slug(name, taken),
                "series": views,
                "open": any(v.expanded for v in views),
                "moved": sum(bool(v.steps) for v in views),
            }
            for name, views in scenes.items()
        ],
        "sparklines": {view.anchor: sparkline(view) for view in series},
        "spark_size": {"width": SPARK_WIDTH, "height": SPARK_HEIGHT},
        "noise_rule": NOISE_RULE,
        "penalty": PENALTY_PER_LOG_RUN,
        "colours": {"version": VERSION_COLOUR, "step": STEP_COLOUR, "line": LINE_COLOUR},
    }


# --- phase 5: the command -------------------------------------------------------------


def default_page(url: str) -> Path:
    """history.html next to an SQLite database, else ``reports/history.html``."""
    path = sqlite_file(url)
    return (path.parent if path is not None else Path("reports")) / HISTORY_PAGE


def render_history(url: str, out: Path, last: int | None = None, only: str | None = None) -> Path:
    """Write history.html of the database at ``url`` to ``out``; returns ``out``."""
    history = load_history(url, last, only)
    html = render_page(TEMPLATE, build_context(history, url))
    out.parent.mkdir(parents=True, exist_ok=True)
    write_atomically(out, html)
    return out


def history_main(db: str | None, last: int | None, only: str | None, out: Path | None) -> int:
    """``physval history``: 0 and the page's path on stdout, or 2 and one line on stderr."""
    try:
        url = database_url(db)
        path = render_history(url, out or default_page(url), last, only)
    except HistoryInputError as error:
        print(error, file=sys.stderr)
        return EXIT_BAD_INPUT
    print(path)
    return EXIT_OK
