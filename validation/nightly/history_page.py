"""``physval history``: history.html, the trend of every (scene, engine, metric) over the runs.

Phases: read the history (``history.load_history``) -> one array per quantity, series x runs
(``series_arrays``) -> steps per series (``steps.detect_steps``, batched) -> views of the series,
the moved ones, the regressions since the baseline (``build_context``) -> sparklines and trend
plots -> template (``templates/history.html.j2``) -> write atomically.

Each series is judged on its ``error`` (the quantity the noise rule judges), or on its
``value`` when it never had an expected value. A series' points are the runs that measured it
(had its row): a run that did not run its scene in its engine is no point of it, neither drawn
nor counted by the step detection; a run that ran the scene but has no number for the series
(no row, or a row without a value) is drawn as a gap mark, and an infinite value as a mark at
the plot's edge labelled ``inf``.

The page draws the runs of one selection (``history.load_history``: by default the selection of
the latest run), so that a scene author's runs of one scene at another dt do not move the
nightly's series; ``--selection all`` draws every run. The page is usable with hundreds of series:
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
from matplotlib.ticker import FuncFormatter, MaxNLocator, ScalarFormatter

from validation.contract import BASELINE_CLASSES, EXIT_BAD_INPUT, EXIT_OK
from validation.files import file_target_problem, page_written, write_atomically
from validation.measure.noise import FAILS_A_RUN, NOISE_RULE, floor_for
from validation.nightly.history import (
    KEY_COLUMNS,
    SELECTION_RULES,
    TREND_COLUMNS,
    UNRECORDED,
    History,
    HistoryInputError,
    database_url,
    describe_selection,
    load_history,
    shown_url,
    sqlite_file,
)
from validation.nightly.known import row_verdict
from validation.nightly.pages import figure_svg, render_page
from validation.nightly.steps import PENALTY_PER_LOG_RUN, Step, detect_steps, segment_levels
from validation.report.build import format_number, slug
from validation.report.palette import engine_colour

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

AXIS_COMMIT_DIGITS = 7
"""... and by fewer under a trend plot's tick (git's own short form)."""

SPARK_MARKER_MAX = 40
"""A sparkline marks each of its points when it has at most this many: 154 px / 40 = 3.9 px
apart, so dots of radius 1.2 stay apart; longer sparklines are lines (their points touch)."""

PLOT_MARKER_MAX = 150
"""A trend plot marks each point (3 pt dots) when the series has at most this many: its axes
span 0.9 x 9 in = 583 pt, so 150 points are 3.9 pt apart; more would touch and only thicken
the line."""

MARKER_PT = 3.0
"""A trend plot's point marker (points, its diameter)."""

GAP_MARK = "x"
"""matplotlib's marker for a run without a number for the series (the sparkline draws a ×)."""

VERSION_COLOUR, STEP_COLOUR, LEVEL_COLOUR = "#999999", "#c0392b", "#555555"
"""Engine-version change marks (grey), a detected step (red), fitted levels (dark grey); the
trend itself is drawn in its engine spec's colour (``palette``), as on every page."""

INFINITE_COLOUR, GAP_COLOUR = "#c0392b", "#777777"
"""An infinite value's mark (red, as a regression) and a gap mark (grey)."""

POINT, INFINITE, MINUS_INFINITE, NO_VALUE, MISSING, UNMEASURED = range(6)
"""What a run is to a series (``point_kinds``): a finite number; +inf; -inf; a row without a
number (NaN: the engine errored); no row although the run ran the scene in the engine; no row
and no run of the scene in the engine (not a point of the series at all)."""

KIND_WORDS = {
    INFINITE: "inf",
    MINUS_INFINITE: "-inf",
    NO_VALUE: "no value",
    MISSING: "missing (the scene ran without this row)",
}
"""A mark's words, in its tooltip and the plot's legend."""


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
    kinds: np.ndarray
    """(runs,) what each run is to the series: ``POINT`` ... ``UNMEASURED``."""
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
        """The latest run's row fails the run against its baseline (``noise.FAILS_A_RUN``)."""
        return self.last.get("baseline") in FAILS_A_RUN

    @property
    def expanded(self) -> bool:
        return bool(self.steps) or self.regressed


# --- phase 2: arrays ----------------------------------------------------------------------


def series_arrays(history: History) -> tuple[pd.DataFrame, dict[str, np.ndarray]]:
    """The series keys (sorted by scene, engine, metric) and, per trend column, an array
    (series, runs) of it (NaN where a run lacks the row); ``present`` (series, runs): the run
    has the row; ``ran`` (series, runs): the run has a row of the series' scene and engine."""
    rows = history.trend
    positions = pd.Index(history.runs["id"]).get_indexer(rows["run_id"])
    codes, keys = pd.factorize(pd.MultiIndex.from_frame(rows[list(KEY_COLUMNS)]), sort=True)
    shape = (len(keys), len(history.runs))
    arrays = {}
    for column in TREND_COLUMNS:
        arrays[column] = np.full(shape, np.nan)
        arrays[column][codes, positions] = rows[column].to_numpy(float)
    arrays["present"] = np.zeros(shape, dtype=bool)
    arrays["present"][codes, positions] = True
    frame = keys.to_frame(index=False)
    frame.columns = list(KEY_COLUMNS)  # factorize drops the names
    pairs, _ = pd.factorize(pd.MultiIndex.from_frame(frame[["scenario", "engine"]]))
    ran = np.zeros((int(pairs.max()) + 1 if pairs.size else 0, shape[1]), dtype=bool)
    np.logical_or.at(ran, pairs, arrays["present"])
    arrays["ran"] = ran[pairs]
    return frame, arrays


def point_kinds(values: np.ndarray, present: np.ndarray, ran: np.ndarray) -> np.ndarray:
    """(series, runs) of ``POINT`` ... ``UNMEASURED``, from the quantity and the presence."""
    kinds = np.full(values.shape, UNMEASURED)
    kinds[ran & ~present] = MISSING
    kinds[present & np.isnan(values)] = NO_VALUE
    kinds[present & (values == np.inf)] = INFINITE
    kinds[present & (values == -np.inf)] = MINUS_INFINITE
    kinds[present & np.isfinite(values)] = POINT
    return kinds


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
    use_error = (~np.isnan(arrays["error"])).any(axis=1)  # an error of inf is an error
    quantity = np.where(use_error[:, None], arrays["error"], arrays["value"])
    kinds = point_kinds(quantity, arrays["present"], arrays["ran"])
    tolerance = last_finite(arrays["tolerance"])
    pairs = zip(keys["scenario"], keys["metric"], strict=True)
    floors = [floor_for(scene, metric) for scene, metric in pairs]
    steps = detect_steps(quantity, floors)  # NaN: no number at that run, not counted
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
            kinds=kinds[i],
            tolerance=float(tolerance[i]),
            steps=steps[i],
            version_changes=changes.get(engine, []),
            last=_last_row(latest.get((scenario, engine, metric))),
            spark_at=spark_at[i],
        )
        for i, (scenario, engine, metric) in enumerate(keys.itertuples(index=False))
    ]


# --- phase 4: sparklines and plots ------------------------------------------------------


def sparkline(view: SeriesView, runs: pd.DataFrame) -> dict[str, Any]:
    """The geometry of one sparkline (px): polylines through the points (split where a run has
    no finite number but ran the scene; runs that did not measure the series are passed
    over), the points' dots when there are few (``SPARK_MARKER_MAX``), the marks of infinite
    values (at the top edge, -inf at the bottom) and of gaps (a × at the bottom), the version
    marks, the step dots and the last point; the template draws them. Every run's x and y are
    computed at once (a year of 1,000 series is 365,000 of them)."""
    n, kinds = view.values.size, view.kinds
    point = kinds == POINT
    finite = view.values[point]
    low, high = (float(finite.min()), float(finite.max())) if finite.size else (0.0, 0.0)
    width, height = SPARK_WIDTH - 2 * SPARK_PAD, SPARK_HEIGHT - 2 * SPARK_PAD
    top, bottom = SPARK_PAD, SPARK_HEIGHT - SPARK_PAD
    at = np.arange(n) / (n - 1) if n > 1 else np.full(n, 0.5)
    x = np.round(SPARK_PAD + width * at, 1).tolist()
    with np.errstate(invalid="ignore"):
        fraction = (view.values - low) / (high - low) if high > low else np.full(n, 0.5)
    y = np.where(point, SPARK_PAD + height * (1.0 - fraction), bottom)
    y = np.round(np.where(kinds == INFINITE, top, y), 1).tolist()
    kind = kinds.tolist()

    lines, current = [], []
    for position in view.spark_at.tolist():
        if kind[position] == UNMEASURED:
            continue  # not a point of this series: the line goes on to its next point
        if kind[position] != POINT:
            lines, current = ([*lines, current] if current else lines), []
            continue
        current.append(f"{x[position]:.1f},{y[position]:.1f}")
    lines = [" ".join(line) for line in ([*lines, current] if current else lines)]
    points = np.nonzero(point)[0].tolist()
    measured = np.nonzero(kinds != UNMEASURED)[0]

    def marks(*shown: int) -> list[dict[str, Any]]:
        found: dict[float, dict[str, Any]] = {}
        for position in np.nonzero(np.isin(kinds, shown))[0].tolist():
            found.setdefault(
                x[position],
                {
                    "x": x[position],
                    "y": y[position],
                    "down": kind[position] == MINUS_INFINITE,
                    "title": f"run {runs['id'].iloc[position]}: {KIND_WORDS[kind[position]]}",
                },
            )
        return list(found.values())

    last = int(measured[-1]) if measured.size else None
    return {
        "colour": engine_colour(view.engine),
        "lines": lines,
        "dots": [(x[p], y[p]) for p in points] if len(points) <= SPARK_MARKER_MAX else [],
        "infinite": marks(INFINITE, MINUS_INFINITE),
        "gaps": marks(NO_VALUE, MISSING),
        "marks": [x[p] for p, _, _ in view.version_changes],
        "steps": [(x[s.at], y[s.at]) for s in view.steps],
        "last": None if last is None or kind[last] > MINUS_INFINITE else (x[last], y[last]),
    }


def axis_labels(runs: pd.DataFrame) -> list[str]:
    """Under each run of a trend plot: its id, its date and its commit (short)."""
    return [
        "\n".join(
            part
            for part in (
                str(run_id),
                "" if created is None or pd.isna(created) else str(created)[:10],
                str(commit or "")[:AXIS_COMMIT_DIGITS],
            )
            if part
        )
        for run_id, created, commit in zip(runs["id"], runs["created"], runs["commit"], strict=True)
    ]


def _segments(kinds: np.ndarray) -> list[np.ndarray]:
    """The positions of the runs of finite points joined by one line: split at every run that
    ran the scene without a finite number, runs that did not measure the series passed over."""
    found, current = [], []
    for position, kind in enumerate(kinds):
        if kind == POINT:
            current.append(position)
        elif kind != UNMEASURED and current:
            found, current = [*found, np.array(current)], []
    return [*found, np.array(current)] if current else found


def trend_plot(view: SeriesView, runs: pd.DataFrame) -> str:
    """The series against its runs (ticks: run id, date, commit): the points (dots) and the
    line through them, its fitted levels, the steps (red) and the engine-version changes (grey,
    labelled), infinite values as red triangles on the top edge labelled ``inf``, runs without a
    number as grey × on the bottom edge, and the tolerance when it is within sight."""
    figure = Figure(figsize=TREND_FIGURE_IN)
    axis = figure.subplots()
    at = np.arange(view.values.size)
    marker = "o" if (view.kinds == POINT).sum() <= PLOT_MARKER_MAX else None
    colour = engine_colour(view.engine)
    for segment in _segments(view.kinds):
        axis.plot(segment, view.values[segment], color=colour, lw=1.2, marker=marker, ms=MARKER_PT)
    finite_row = np.where(view.kinds == POINT, view.values, np.nan)
    starts = [0, *(s.at for s in view.steps)]
    stops = [*starts[1:], view.values.size]
    for start, stop, level in zip(starts, stops, segment_levels(finite_row, starts), strict=True):
        if math.isfinite(level):
            axis.hlines(level, start, stop - 1, color=LEVEL_COLOUR, linewidth=1)
    edge = axis.get_xaxis_transform()  # x in data, y in axes fraction: 1 the top edge
    for kinds, y, marker, colour, label in (
        ((INFINITE,), 1.0, "^", INFINITE_COLOUR, "inf"),
        ((MINUS_INFINITE,), 0.0, "v", INFINITE_COLOUR, "-inf"),
        ((NO_VALUE, MISSING), 0.0, GAP_MARK, GAP_COLOUR, "missing"),
    ):
        marked = at[np.isin(view.kinds, kinds)]
        if not marked.size:
            continue
        axis.plot(
            marked,
            np.full(marked.size, y),
            transform=edge,
            linestyle="none",
            marker=marker,
            ms=6,
            color=colour,
            clip_on=False,
            label=f"{label} ({marked.size} runs)",
        )
        for position in marked[-1:]:  # one label per kind: the latest mark
            axis.annotate(
                label,
                (position, y),
                xycoords=edge,
                xytext=(4, -9 if y else 3),
                textcoords="offset points",
                fontsize=7,
                color=colour,
            )
    for step in view.steps:
        axis.axvline(step.at, color=STEP_COLOUR, linewidth=1.2)
    for position, old, new in view.version_changes:
        axis.axvline(position, color=VERSION_COLOUR, linestyle="--", linewidth=1)
        axis.annotate(
            f"{old} → {new}",
            (position, 1.0),
            xycoords=("data", "axes fraction"),
            fontsize=7,
            color="#555555",
            rotation=90,
            va="top",
            ha="right",
        )
    finite = view.values[view.kinds == POINT]
    if view.quantity == "error" and finite.size and 0 < view.tolerance <= 2 * finite.max():
        axis.axhline(view.tolerance, color="#333333", linestyle=":", linewidth=1)
    if not finite.size:
        axis.set_yticks([])  # nothing finite to scale: the marks alone
    labels = axis_labels(runs)
    axis.set_xlim(-0.5, max(view.values.size - 0.5, 0.5))
    axis.xaxis.set_major_locator(MaxNLocator(TICKS_PER_AXIS, integer=True))
    axis.xaxis.set_major_formatter(
        FuncFormatter(lambda p, _: labels[int(p)] if p == int(p) and 0 <= p < len(labels) else "")
    )
    axis.yaxis.set_major_locator(MaxNLocator(TICKS_PER_AXIS))
    axis.yaxis.set_major_formatter(ScalarFormatter(useOffset=False))  # the values, no offset
    axis.set_xlabel("run · date · commit", fontsize=8)
    axis.set_ylabel(view.quantity, fontsize=8)
    axis.tick_params(labelsize=7)
    axis.grid(True, color="#e6e6e6", linewidth=0.6)
    if np.isin(view.kinds, (INFINITE, MINUS_INFINITE, NO_VALUE, MISSING)).any():
        axis.legend(loc="upper left", fontsize=7, frameon=False)  # what the marks mean
    figure.subplots_adjust(left=0.09, right=0.99, bottom=0.3, top=0.92)
    return figure_svg(figure, f"history-{view.anchor}")


# --- phase 3 (continued): the page's context ------------------------------------------


def _run_label(runs: pd.DataFrame, position: int) -> dict[str, str]:
    run = runs.iloc[position]
    created = run["created"]
    return {
        "id": str(run["id"]),
        "created": "" if created is None or pd.isna(created) else str(created)[:19],
        "commit": str(run["commit"] or "")[:COMMIT_DIGITS],
        "key": str(run["selection_key"]),
    }


def id_ranges(ids: list[int]) -> str:
    """Run ids as ranges: ``1-3, 5, 7-9``."""
    found: list[list[int]] = []
    for run_id in ids:
        if found and run_id == found[-1][-1] + 1:
            found[-1].append(run_id)
        else:
            found.append([run_id])
    return ", ".join(str(g[0]) if len(g) == 1 else f"{g[0]}-{g[-1]}" for g in found) or "none"


def selections(history: History) -> list[dict[str, Any]]:
    """Every selection of the history's complete runs, latest first: key, description, run
    count and ids, the latest run's time, whether the page draws it, and the runs it drew."""
    recorded = history.recorded if history.recorded is not None else history.runs
    drawn = set(history.runs["id"])
    found = []
    for key, runs in recorded.groupby("selection_key", sort=False):
        ids = [int(i) for i in runs["id"]]
        found.append(
            {
                "key": str(key),
                "description": describe_selection(runs["selection"].iloc[-1]),
                "count": len(ids),
                "ids": id_ranges(ids),
                "drawn": id_ranges([i for i in ids if i in drawn]),
                "shown": any(i in drawn for i in ids),
                "latest": max(ids),
                "created": _run_label(runs, len(runs) - 1)["created"],
            }
        )
    return sorted(found, key=lambda s: -s["latest"])


def _step_text(view: SeriesView, step: Step) -> str:
    grew = "grew" if step.direction > 0 else "shrank"
    return f"{view.quantity} {format_number(step.before)} → {format_number(step.after)} ({grew})"


def _previous_measured(view: SeriesView, at: int, runs: pd.DataFrame) -> str:
    """The id of the last run before ``at`` with a number for the series when runs drawn in
    between had none (the step lies between that run and ``at``), else ''."""
    before = np.nonzero(np.isin(view.kinds[:at], (POINT, INFINITE, MINUS_INFINITE)))[0]
    return str(runs["id"].iloc[before[-1]]) if before.size and before[-1] < at - 1 else ""


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
                "measured_before": _previous_measured(view, step.at, runs),
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
    for view in expanded[:MAX_TREND_PLOTS]:
        view.plot = trend_plot(view, runs)
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
    found = selections(history)
    drawn = [s for s in found if s["shown"]]
    return {
        "source": shown_url(source),
        "selection": history.selection,
        "selection_drawn": drawn,
        "selections": found,
        "other_selections": [s for s in found if not s["shown"]],
        "mixed": len(drawn) > 1,
        "rules": SELECTION_RULES,
        "unrecorded": UNRECORDED,
        "run_count": len(runs),
        "first": _run_label(runs, 0) if len(runs) else None,
        "latest": _run_label(runs, len(runs) - 1) if len(runs) else None,
        "runs": [
            {
                **_run_label(runs, i),
                "versions": runs["engine_versions"].iloc[i],
                "command": shown_url(runs["command"].iloc[i]),
                "folder": runs["folder"].iloc[i],
            }
            for i in range(len(runs) - 1, -1, -1)
        ],
        "series_count": len(series),
        "moved": moved_rows(series, runs),
        "baseline": baseline_summary(history, series),
        "unplotted": unplotted,
        "max_plots": MAX_TREND_PLOTS,
        "run_labels": [_run_label(runs, i) for i in range(len(runs))],
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
        "sparklines": {view.anchor: sparkline(view, runs) for view in series},
        "spark_size": {"width": SPARK_WIDTH, "height": SPARK_HEIGHT},
        "noise_rule": NOISE_RULE,
        "penalty": PENALTY_PER_LOG_RUN,
        "colours": {
            "version": VERSION_COLOUR,
            "step": STEP_COLOUR,
            "infinite": INFINITE_COLOUR,
            "gap": GAP_COLOUR,
        },
    }


# --- phase 5: the command -------------------------------------------------------------


HISTORY_WRITTEN = page_written("a physval history page", "physval history")
"""How history.html begins: a file at ``--out`` that physval did not write is refused."""


def default_page(url: str) -> Path:
    """history.html next to an SQLite database, else ``reports/history.html``."""
    path = sqlite_file(url)
    return (path.parent if path is not None else Path("reports")) / HISTORY_PAGE


def render_history(
    url: str,
    out: Path,
    last: int | None = None,
    only: str | None = None,
    selection: str | None = None,
) -> tuple[Path, History]:
    """Write history.html of the database at ``url`` to ``out``; returns ``out`` and the
    history it drew."""
    history = load_history(url, last, only, selection)
    html = render_page(TEMPLATE, build_context(history, url))
    out.parent.mkdir(parents=True, exist_ok=True)
    write_atomically(out, html)
    return out, history


def drawn_lines(history: History) -> list[str]:
    """What ``physval history`` prints before the page's path: the runs it drew, per
    selection, and the selections it did not draw."""
    found = selections(history)
    lines = [
        f"drew runs {s['drawn']} (selection {s['key']}: {s['description']})"
        for s in found
        if s["shown"]
    ] or ["drew no runs (the history has no complete run)"]
    others = [f"{s['key']} ({s['count']} runs: {s['ids']})" for s in found if not s["shown"]]
    if others:
        lines.append(
            f"not drawn: {', '.join(others)}; --selection KEY draws one, --selection all every run"
        )
    return lines


def history_main(
    db: str | None,
    last: int | None,
    only: str | None,
    out: Path | None,
    selection: str | None = None,
) -> int:
    """``physval history``: 0, the runs drawn and the page's path on stdout, or 2 and one line
    on stderr."""
    try:
        url = database_url(db)
        page = out or default_page(url)
        database = sqlite_file(url)  # never overwritten by the page
        inputs = () if database is None else (database,)
        problem = file_target_problem(page, HISTORY_WRITTEN, inputs)  # before it is read
        if problem:
            raise HistoryInputError(f"--out: {problem}")
        path, history = render_history(url, page, last, only, selection)
    except HistoryInputError as error:
        print(error, file=sys.stderr)
        return EXIT_BAD_INPUT
    print("\n".join([*drawn_lines(history), str(path)]))
    return EXIT_OK
