"""The HTML report of one run folder: ``report.html``, one self-contained page.

``render_report(run_dir)`` reads the record files that ``physval run`` writes

- ``results.csv`` (required): one row per (scenario, engine spec, metric);
- ``series.csv`` (optional): energy, linear and angular momentum over time;
- ``impacts.csv`` (optional): every impact with its requested and measured restitution;
- ``provenance.json`` (optional here, always written by the run): command, commit, machine,
  engine versions and settings;

and writes ``run_dir/report.html`` atomically (a temporary file in the same folder, then
``os.replace``), so a failed rendering never damages an older report. The page has no
scripts and fetches nothing: the styles are inline and the plots are inline SVG, so it
works offline and can be attached to a CI run as one file.

Phases: read (``load_run``) -> judge each row (``classify_rows``) -> build the matrix,
summary, offenders and scene sections (``build_context``) -> plot (``plot_scene_series``)
-> template (``templates/report.html.j2``) -> write (``write_atomically``).
"""

from __future__ import annotations

import io
import itertools
import json
import math
import re
import sys
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import matplotlib
import numpy as np
import pandas as pd
from jinja2 import Environment, FileSystemLoader, StrictUndefined
from markupsafe import Markup
from matplotlib.figure import Figure

from validation.contract import (
    EXIT_BAD_INPUT,
    EXIT_OK,
    IMPACTS_COLUMNS,
    IMPACTS_FILE,
    PROVENANCE_FILE,
    REPORT_FILE,
    RESULTS_COLUMNS,
    RESULTS_FILE,
    SERIES_COLUMNS,
    SERIES_FILE,
    STATUS_DESCRIPTIONS,
)
from validation.files import write_atomically
from validation.measure.definitions import (
    EXPECTATION_DEFINITIONS,
    EXPECTED_KINDS,
    METRIC_DEFINITIONS,
)

matplotlib.use("Agg")  # headless: rendering must never need a display

# --- the run folder's files and their columns (the producer's contract) ---------------------

TEMPLATE_DIR = Path(__file__).resolve().parent / "templates"
TEMPLATE_NAME = "report.html.j2"

NUMERIC_RESULTS_COLUMNS = ("value", "expected", "error", "tolerance", "dt", "steps", "wall_time_s")

# --- outcomes: what a row, a (scene, engine) cell and a summary chip can be -----------------

"""Every status of results.csv -> its meaning, printed in the legend."""

OUTCOME_ORDER = (
    "error",
    "model_mismatch",
    "unstable",
    "failed",
    "passed",
    "no_tolerance",
    "unsupported",
    "not_run",
)
"""Outcomes worst first; a cell shows the worst outcome of its rows."""

RUN_FAILURES = ("error", "model_mismatch", "unstable")
"""Outcomes that mean the engine produced no trustworthy numbers (the cell shows the word)."""

RED_OUTCOMES = (*RUN_FAILURES, "failed")
"""Outcomes that need a person's look (red, counted as offenders)."""

OUTCOME_LABELS = {"no_tolerance": "no tolerance", "not_run": "not run"}
"""Display words for outcomes that are not statuses of results.csv."""

# Cell and chip backgrounds: red needs a look, green passed, grey nothing was judged,
# near-white means the engine was not run on the scene. Pale so that black text stays legible.
RED, GREEN, GREY, BLANK = "#f3b3b0", "#b7e3bf", "#dedede", "#f7f7f7"
OUTCOME_COLOURS = {
    "error": RED,
    "model_mismatch": RED,
    "unstable": RED,
    "failed": RED,
    "passed": GREEN,
    "no_tolerance": GREY,
    "unsupported": GREY,
    "not_run": BLANK,
}

# --- plots ------------------------------------------------------------------------------------

# Inches: three side-by-side axes that fill a ~1100 px column at the SVG's 72 px per inch.
FIGURE_SIZE_IN = (15.0, 3.6)
# Okabe–Ito colours (readable with colour-blindness), one per engine, same engine same colour
# in every scene; engines beyond eight cycle.
ENGINE_COLOURS = (
    "#0072B2",
    "#D55E00",
    "#009E73",
    "#CC79A7",
    "#E69F00",
    "#56B4E9",
    "#000000",
    "#F0E442",
)
# Line styles cycle too, so engines whose lines coincide (the usual case) stay distinguishable.
ENGINE_LINE_STYLES = ("-", "--", ":", "-.")
LINE_WIDTH = 1.4  # points
PLOT_FONT_SIZE = 9  # points
MAX_POINTS_PER_LINE = 1200
"""Longer lines are thinned to per-bucket min/max pairs: spikes stay visible, the page small."""
PLOT_QUANTITIES = (
    ("energy", "energy E (J)"),
    ("p_norm", "|p| linear momentum (kg·m/s)"),
    ("L_norm", "|L| about the COM (kg·m²/s)"),
)
"""Series column -> axis title, one axis each."""

# --- page size limits --------------------------------------------------------------------------

MAX_OFFENDERS = 20  # rows in the "worst offenders" table at the top
MAX_IMPACT_ROWS = 40  # impacts listed per scene; the rest stay in impacts.csv
IMPACTS_OPEN_UP_TO = 12  # an impacts table this short is shown expanded
SETTINGS_INLINE_UP_TO = 6  # more settings than this are folded in the scene's runs table


class ReportInputError(ValueError):
    """The run folder cannot be rendered (no or unreadable results.csv); exit code 2."""


@dataclass
class RunData:
    """The record files of one run folder, read and checked."""

    run_dir: Path
    results: pd.DataFrame
    series: pd.DataFrame | None = None
    impacts: pd.DataFrame | None = None
    provenance: dict[str, Any] | None = None
    warnings: list[str] = field(default_factory=list)


# ============================================================================ phase 1: read


def _read_csv(path: Path, **options) -> pd.DataFrame:
    try:
        return pd.read_csv(path, **options)
    except (pd.errors.ParserError, pd.errors.EmptyDataError, UnicodeDecodeError) as error:
        raise ReportInputError(f"{path.name}: cannot be read as CSV ({error})") from error


def _parse_passed(text: str) -> bool | None:
    word = text.strip().lower()
    return True if word in ("true", "1") else False if word in ("false", "0") else None


def read_results(path: Path) -> pd.DataFrame:
    """results.csv with numeric columns parsed, ``passed`` as True/False/None, and the raw
    text of value/expected/error/tolerance kept in ``<column>_text`` for display."""
    table = _read_csv(path, dtype=str, keep_default_na=False)
    missing = [c for c in RESULTS_COLUMNS if c not in table.columns]
    if missing:
        raise ReportInputError(f"{path.name}: missing columns {', '.join(missing)}")
    table = table.astype(object)
    for column in NUMERIC_RESULTS_COLUMNS:
        table[f"{column}_text"] = table[column].str.strip()
        table[column] = pd.to_numeric(table[column].str.strip(), errors="coerce")
    table["passed"] = [_parse_passed(text) for text in table["passed"]]
    table["status"] = table["status"].str.strip()
    return table


def _read_optional_table(
    path: Path, columns: tuple[str, ...], text_columns: tuple[str, ...], warnings: list[str]
) -> pd.DataFrame | None:
    """A table that may be absent; a malformed one becomes a warning on the page, not a crash."""
    if not path.is_file():
        return None
    try:
        table = _read_csv(path, dtype=dict.fromkeys(text_columns, str), keep_default_na=False)
    except ReportInputError as error:
        warnings.append(str(error))
        return None
    missing = [c for c in columns if c not in table.columns]
    if missing:
        warnings.append(f"{path.name}: missing columns {', '.join(missing)}; not shown")
        return None
    for column in columns:
        if column not in text_columns:
            table[column] = pd.to_numeric(table[column], errors="coerce")
    return table


def read_provenance(path: Path, warnings: list[str]) -> dict[str, Any] | None:
    """provenance.json as a dict, or None with a warning when absent or malformed."""
    if not path.is_file():
        warnings.append(f"{path.name}: missing; engine versions and settings come from results.csv")
        return None
    try:
        provenance = json.loads(path.read_text(encoding="utf-8"))
    except (json.JSONDecodeError, UnicodeDecodeError) as error:
        warnings.append(f"{path.name}: not valid JSON ({error})")
        return None
    if not isinstance(provenance, dict):
        warnings.append(f"{path.name}: expected a JSON object")
        return None
    return provenance


def load_run(run_dir: Path) -> RunData:
    """Read every record file of ``run_dir``; only a missing or broken results.csv raises."""
    results_path = run_dir / RESULTS_FILE
    if not results_path.is_file():
        raise ReportInputError(f"no {RESULTS_FILE} (not a physval run folder)")
    run = RunData(run_dir, read_results(results_path))
    run.series = _read_optional_table(
        run_dir / SERIES_FILE, SERIES_COLUMNS, ("scenario", "engine"), run.warnings
    )
    run.impacts = _read_optional_table(
        run_dir / IMPACTS_FILE,
        IMPACTS_COLUMNS,
        ("scenario", "engine", "body_a", "body_b"),
        run.warnings,
    )
    run.provenance = read_provenance(run_dir / PROVENANCE_FILE, run.warnings)
    return run


# ============================================================================ phase 2: judge


def row_outcome(status: str, passed: bool | None) -> str:
    """One row's outcome: a run failure or ``unsupported`` as such, else the check's verdict."""
    if status in (*RUN_FAILURES, "unsupported"):
        return status
    if status == "failed" or passed is False:
        return "failed"
    if passed is True:
        return "passed"
    return "no_tolerance" if status in ("ok", "") else "error"


def error_ratio(error: float, tolerance: float) -> float:
    """|error| / tolerance (NaN when either is missing; a zero tolerance gives 0 or inf)."""
    if not (math.isfinite(tolerance) and not math.isnan(error)):
        return math.nan
    if tolerance <= 0:
        return 0.0 if error == 0 else math.inf
    return abs(error) / tolerance


def classify_rows(results: pd.DataFrame, warnings: list[str]) -> pd.DataFrame:
    """Adds ``outcome``, ``ratio`` (error/tolerance) and ``severity`` (0 = worst) per row."""
    table = results.copy()
    unknown = sorted(set(table["status"]) - set(STATUS_DESCRIPTIONS) - {""})
    if unknown:
        warnings.append(f"{RESULTS_FILE}: unknown status {', '.join(unknown)} (shown as error)")
    table["outcome"] = [
        row_outcome(s, p) for s, p in zip(table["status"], table["passed"], strict=True)
    ]
    table["ratio"] = [
        error_ratio(e, t) for e, t in zip(table["error"], table["tolerance"], strict=True)
    ]
    table["severity"] = [OUTCOME_ORDER.index(o) for o in table["outcome"]]
    return table


def worst_first(rows: pd.DataFrame) -> pd.DataFrame:
    """Rows sorted worst outcome first, then largest error/tolerance first."""
    key = rows.assign(_neg_ratio=-rows["ratio"].fillna(-math.inf))
    return rows.loc[key.sort_values(["severity", "_neg_ratio"], kind="stable").index]


# ============================================================================ phase 3: build


def format_number(value: Any, raw: str = "") -> str:
    """A compact number (4 significant digits); raw text when it is not a number."""
    if isinstance(value, (int, float, np.floating, np.integer)) and not isinstance(value, bool):
        if math.isnan(value):
            return raw
        return f"{value:.4g}"
    return raw or ("" if value is None else str(value))


def format_ratio(ratio: float) -> str:
    """error/tolerance as shown in a cell: ``0.42×``, ``12×``, ``inf×``."""
    if math.isnan(ratio):
        return ""
    return "inf×" if math.isinf(ratio) else f"{ratio:.2g}×"


def outcome_label(outcome: str) -> str:
    return OUTCOME_LABELS.get(outcome, outcome)


def slug(text: str, taken: set[str]) -> str:
    """An HTML id for a scene: letters, digits, ``-`` and ``_`` only, unique in ``taken``."""
    base = "scene-" + (re.sub(r"[^A-Za-z0-9_-]+", "-", text).strip("-") or "unnamed")
    candidate, n = base, 1
    while candidate in taken:
        n += 1
        candidate = f"{base}-{n}"
    taken.add(candidate)
    return candidate


def metric_anchor(metric: str) -> str | None:
    """The legend anchor that defines ``metric`` (``<kind>.<body>`` -> the kind), if any."""
    if metric in METRIC_DEFINITIONS:
        return f"metric-{metric}"
    kind = metric.split(".", 1)[0]
    return f"expectation-{kind}" if kind in EXPECTATION_DEFINITIONS and "." in metric else None


def build_cell(rows: pd.DataFrame, anchor: str) -> dict[str, Any]:
    """One matrix cell: the worst outcome of a (scene, engine)'s rows, shown as a ratio or word."""
    if rows.empty:
        return {"outcome": "not_run", "text": "–", "title": "not run", "anchor": anchor}
    ordered = worst_first(rows)
    worst = ordered.iloc[0]
    outcome = worst["outcome"]
    judged = rows[rows["ratio"].notna()]
    ratio = judged["ratio"].max() if not judged.empty else math.nan
    if outcome in (*RUN_FAILURES, "unsupported", "no_tolerance") or math.isnan(ratio):
        text = outcome_label(outcome)
    else:
        text = format_ratio(ratio)
    failed = int((rows["outcome"] == "failed").sum())
    title = f"{outcome_label(outcome)}: {worst['metric']}"
    if not math.isnan(worst["ratio"]):
        title += f" at {format_ratio(worst['ratio'])} its tolerance"
    if len(judged):
        title += f"; {failed} of {len(judged)} checks failed"
    if worst["message"]:
        title += f" — {worst['message']}"
    return {"outcome": outcome, "text": text, "title": title, "anchor": anchor}


def scene_order(table: pd.DataFrame) -> list[str]:
    """Scenes worst first (worst outcome, then largest error/tolerance), then by name."""
    keys = {}
    for scene, rows in table.groupby("scenario", sort=False):
        ratio = rows.loc[rows["outcome"].isin(RED_OUTCOMES), "ratio"].max()
        keys[scene] = (rows["severity"].min(), -(0 if math.isnan(ratio) else ratio), scene)
    return sorted(keys, key=keys.get)


def count_chips(outcomes: list[str]) -> list[dict[str, Any]]:
    """Counts per outcome, worst first, only the outcomes that occur."""
    return [
        {"outcome": o, "label": outcome_label(o), "count": outcomes.count(o)}
        for o in OUTCOME_ORDER
        if o in outcomes
    ]


def build_rows(rows: pd.DataFrame, anchors: dict[str, str] | None = None) -> list[dict[str, Any]]:
    """Result rows as display strings (worst first)."""
    return [
        {
            "scenario": row["scenario"],
            "anchor": (anchors or {}).get(row["scenario"], ""),
            "engine": row["engine"],
            "metric": row["metric"],
            "metric_anchor": metric_anchor(row["metric"]),
            "value": format_number(row["value"], row["value_text"]),
            "expected": format_number(row["expected"], row["expected_text"]),
            "expected_kind": row["expected_kind"],
            "error": format_number(row["error"], row["error_text"]),
            "tolerance": format_number(row["tolerance"], row["tolerance_text"]),
            "ratio": format_ratio(row["ratio"]),
            "outcome": row["outcome"],
            "outcome_label": outcome_label(row["outcome"]),
            "message": row["message"],
        }
        for _, row in worst_first(rows).iterrows()
    ]


def _pretty_settings(text: str) -> tuple[str, int]:
    """The settings JSON of a row as ``k=v, ...`` and the number of settings."""
    try:
        settings = json.loads(text) if text else {}
    except json.JSONDecodeError:
        return text, 1
    if isinstance(settings, dict):
        return ", ".join(f"{k}={v}" for k, v in settings.items()), len(settings)
    return text, 1


def build_runs(rows: pd.DataFrame, engines: list[str]) -> list[dict[str, Any]]:
    """One line per engine of a scene: outcome, version, dt, steps, wall time, settings."""
    runs = []
    for engine in engines:
        mine = rows[rows["engine"] == engine]
        if mine.empty:
            continue
        first = mine.iloc[0]
        worst = worst_first(mine).iloc[0]["outcome"]
        settings, count = _pretty_settings(first["settings"])
        messages = [m for m in dict.fromkeys(mine.loc[mine["metric"] == "status", "message"]) if m]
        runs.append(
            {
                "engine": engine,
                "outcome": worst,
                "outcome_label": outcome_label(worst),
                "version": first["engine_version"],
                "dt": format_number(first["dt"], first["dt_text"]),
                "steps": format_number(first["steps"], first["steps_text"]),
                "wall_time_s": format_number(first["wall_time_s"], first["wall_time_s_text"]),
                "settings": settings,
                "settings_count": count,
                "message": "; ".join(messages),
            }
        )
    return runs


def build_impacts(impacts: pd.DataFrame | None, scene: str) -> dict[str, Any]:
    """A scene's impacts: rows (engine, then time), the largest |Δe| per engine, truncation."""
    if impacts is None:
        return {"available": False, "rows": [], "total": 0, "hidden": 0, "worst": []}
    mine = impacts[impacts["scenario"] == scene].copy()
    mine["delta_e"] = (mine["e_measured"] - mine["e_requested"]).abs()
    mine = mine.sort_values(["engine", "time"], kind="stable")
    worst = [
        {"engine": engine, "count": len(group), "max_delta": format_number(group["delta_e"].max())}
        for engine, group in mine.groupby("engine", sort=False)
    ]
    shown = mine.head(MAX_IMPACT_ROWS)
    rows = [
        {
            "engine": row["engine"],
            "bodies": f"{row['body_a']} – {row['body_b']}",
            "time": format_number(row["time"]),
            "e_requested": format_number(row["e_requested"]),
            "e_measured": format_number(row["e_measured"]),
            "delta_e": format_number(row["delta_e"]),
            "v_before": format_number(row["normal_velocity_before"]),
            "v_after": format_number(row["normal_velocity_after"]),
        }
        for _, row in shown.iterrows()
    ]
    return {
        "available": True,
        "rows": rows,
        "total": len(mine),
        "hidden": len(mine) - len(shown),
        "worst": worst,
        "open": len(mine) <= IMPACTS_OPEN_UP_TO,
    }


def build_legend(table: pd.DataFrame) -> dict[str, Any]:
    """Every metric and expectation definition, the expected kinds, statuses and colours."""
    metrics = set(table["metric"]) - {"status"}
    undefined = sorted(m for m in metrics if metric_anchor(m) is None)
    return {
        "metrics": list(METRIC_DEFINITIONS.items()),
        "expectations": list(EXPECTATION_DEFINITIONS.items()),
        "expected_kinds": {
            "analytic": "a closed form (the expected value printed in the row)",
            "conserved": "the conserved quantity's initial value",
            "engine": "another engine's result on the same scene, written engine:<spec>",
        },
        "kinds_known": EXPECTED_KINDS,
        "statuses": list(STATUS_DESCRIPTIONS.items()),
        "undefined": undefined,
    }


def build_provenance(provenance: dict[str, Any] | None, table: pd.DataFrame) -> dict[str, Any]:
    """Command, commit, time, machine and one line per engine spec (from results.csv if absent)."""
    provenance = provenance or {}
    engines = provenance.get("engines")
    if not isinstance(engines, dict) or not engines:
        firsts = table.drop_duplicates("engine")
        engines = {
            row["engine"]: {"version": row["engine_version"], "settings": row["settings"]}
            for _, row in firsts.iterrows()
        }
    engine_rows = []
    for label, info in engines.items():
        info = info if isinstance(info, dict) else {}
        settings = info.get("settings", {})
        engine_rows.append(
            {
                "label": label,
                "engine": str(info.get("engine", "")),
                "version": str(info.get("version", "")),
                "settings": settings
                if isinstance(settings, str)
                else json.dumps(settings, indent=1, sort_keys=True, default=str),
                "notes": [str(n) for n in info.get("notes", []) or []],
            }
        )
    machine = provenance.get("machine", {})
    return {
        "command": str(provenance.get("command", "")),
        "git_commit": str(provenance.get("git_commit", "")),
        "created": str(provenance.get("created", "")),
        "machine": [(str(k), str(v)) for k, v in machine.items()]
        if isinstance(machine, dict)
        else [("machine", str(machine))],
        "engines": engine_rows,
    }


def _engine_order(table: pd.DataFrame, series: pd.DataFrame | None) -> list[str]:
    """Engines in the order of first appearance (the reference engine, listed first, leads)."""
    engines = list(dict.fromkeys(table["engine"]))
    if series is not None:
        engines += [e for e in dict.fromkeys(series["engine"]) if e not in engines]
    return engines


def build_scene(
    scene: str,
    anchor: str,
    rows: pd.DataFrame,
    run: RunData,
    engines: list[str],
    colours: dict[str, tuple[str, str]],
) -> dict[str, Any]:
    """One scene's section: runs, the plot, the impacts and the checks."""
    plot_note = ""
    svg = None
    if run.series is None:
        plot_note = f"no {SERIES_FILE} in this run"
    else:
        series = run.series[run.series["scenario"] == scene]
        if series.empty:
            plot_note = "no time series recorded for this scene"
        else:
            svg = Markup(plot_scene_series(scene, series, engines, colours))
    return {
        "name": scene,
        "anchor": anchor,
        "runs": build_runs(rows, engines),
        "svg": svg,
        "plot_note": plot_note,
        "impacts": build_impacts(run.impacts, scene),
        "rows": build_rows(rows),
    }


def build_context(run: RunData) -> dict[str, Any]:
    """Everything the template prints, as plain strings, lists and dicts."""
    table = classify_rows(run.results, run.warnings)
    engines = _engine_order(table, run.series)
    colours = {
        engine: (
            ENGINE_COLOURS[i % len(ENGINE_COLOURS)],
            ENGINE_LINE_STYLES[i % len(ENGINE_LINE_STYLES)],
        )
        for i, engine in enumerate(engines)
    }
    scenes = scene_order(table)
    taken: set[str] = set()
    anchors = {scene: slug(scene, taken) for scene in scenes}
    matrix = [
        {
            "scene": scene,
            "anchor": anchors[scene],
            "cells": [
                build_cell(
                    table[(table["scenario"] == scene) & (table["engine"] == engine)],
                    anchors[scene],
                )
                for engine in engines
            ],
        }
        for scene in scenes
    ]
    cell_outcomes = [cell["outcome"] for row in matrix for cell in row["cells"]]
    red_runs = sum(o in RED_OUTCOMES for o in cell_outcomes)
    offenders = table[table["outcome"].isin(RED_OUTCOMES)]
    provenance = build_provenance(run.provenance, table)
    return {
        "title": f"physval report {provenance['created']}".strip(),
        "run_dir": str(run.run_dir),
        "warnings": run.warnings,
        "verdict": {
            "bad": red_runs > 0,
            "runs": sum(o != "not_run" for o in cell_outcomes),
            "red_runs": red_runs,
        },
        "scene_count": len(scenes),
        "engines": engines,
        "engine_colours": {e: c for e, (c, _) in colours.items()},
        "run_chips": count_chips([o for o in cell_outcomes if o != "not_run"]),
        "row_chips": count_chips(list(table["outcome"])),
        "row_count": len(table),
        "matrix": matrix,
        "offenders": build_rows(offenders, anchors)[:MAX_OFFENDERS],
        "offenders_hidden": max(0, len(offenders) - MAX_OFFENDERS),
        "scenes": [
            build_scene(
                scene, anchors[scene], table[table["scenario"] == scene], run, engines, colours
            )
            for scene in scenes
        ],
        "legend": build_legend(table),
        "provenance": provenance,
        "outcome_colours": OUTCOME_COLOURS,
        "outcome_labels": {o: outcome_label(o) for o in OUTCOME_ORDER},
        "red_outcomes": RED_OUTCOMES,
        "settings_inline_up_to": SETTINGS_INLINE_UP_TO,
    }


# ============================================================================ phase 4: plot


def thin_line(t: np.ndarray, y: np.ndarray, max_points: int = MAX_POINTS_PER_LINE):
    """At most ``max_points`` points: each of ``max_points // 2`` buckets keeps its min and
    max (in time order), so spikes and explosions survive; non-finite values become gaps."""
    y = np.where(np.isfinite(y), y, np.nan)
    if t.size <= max_points:
        return t, y
    edges = np.linspace(0, t.size, max_points // 2 + 1).astype(int)
    keep = []
    for start, stop in itertools.pairwise(edges):
        chunk = y[start:stop]
        if np.isnan(chunk).all():
            keep.append(start)
            continue
        keep += sorted({start + int(np.nanargmin(chunk)), start + int(np.nanargmax(chunk))})
    index = np.asarray(keep)
    return t[index], y[index]


def _norm(series: pd.DataFrame, columns: tuple[str, str, str]) -> np.ndarray:
    return np.sqrt(sum(series[c].to_numpy(float) ** 2 for c in columns))


def _svg_for_html(svg: str) -> str:
    """matplotlib's SVG file as an element to inline: no XML prolog, DOCTYPE or metadata."""
    svg = re.sub(r"<\?xml[^>]*\?>\s*", "", svg)
    svg = re.sub(r"<!DOCTYPE[^>]*>\s*", "", svg)
    svg = re.sub(r"<metadata>.*?</metadata>\s*", "", svg, flags=re.DOTALL)
    return svg.replace("<svg ", '<svg class="plot" role="img" ', 1).strip()


def plot_scene_series(
    scene: str,
    series: pd.DataFrame,
    engines: list[str],
    colours: dict[str, tuple[str, str]],
) -> str:
    """Energy, |p| and |L| over time, one line per engine, as an inline ``<svg>`` element."""
    figure = Figure(figsize=FIGURE_SIZE_IN, layout="constrained")
    axes = figure.subplots(1, len(PLOT_QUANTITIES), sharex=True)
    series = series.assign(
        p_norm=_norm(series, ("px", "py", "pz")), L_norm=_norm(series, ("Lx", "Ly", "Lz"))
    )
    for engine in engines:
        mine = series[series["engine"] == engine].sort_values("t", kind="stable")
        if mine.empty:
            continue
        colour, style = colours[engine]
        t = mine["t"].to_numpy(float)
        for axis, (column, _) in zip(axes, PLOT_QUANTITIES, strict=True):
            axis.plot(
                *thin_line(t, mine[column].to_numpy(float)),
                color=colour,
                linestyle=style,
                linewidth=LINE_WIDTH,
                label=engine,
            )
    for axis, (_, title) in zip(axes, PLOT_QUANTITIES, strict=True):
        axis.set_title(title, fontsize=PLOT_FONT_SIZE + 1)
        axis.set_xlabel("t (s)", fontsize=PLOT_FONT_SIZE)
        axis.tick_params(labelsize=PLOT_FONT_SIZE)
        axis.grid(True, color="#e6e6e6", linewidth=0.6)
    handles, labels = axes[0].get_legend_handles_labels()
    if handles:
        figure.legend(
            handles,
            labels,
            loc="outside upper center",
            ncols=min(len(labels), 4),
            fontsize=PLOT_FONT_SIZE,
            frameon=False,
        )
    buffer = io.StringIO()
    # Text stays text (small, searchable); the salt makes element ids deterministic and
    # distinct between the page's figures.
    with matplotlib.rc_context({"svg.fonttype": "none", "svg.hashsalt": f"physval-{scene}"}):
        figure.savefig(buffer, format="svg", metadata={"Date": None})
    return _svg_for_html(buffer.getvalue())


# ============================================================================ phase 5: write


def render_html(context: dict[str, Any]) -> str:
    """The page: ``templates/report.html.j2`` with autoescaping on."""
    environment = Environment(
        loader=FileSystemLoader(TEMPLATE_DIR),
        autoescape=True,
        undefined=StrictUndefined,
        trim_blocks=True,
        lstrip_blocks=True,
    )
    return environment.get_template(TEMPLATE_NAME).render(**context)


def render_report(run_dir: Path) -> Path:
    """Render ``run_dir/report.html`` from the run's record files; returns its path.

    Raises ``ReportInputError`` when results.csv is absent or unreadable. Any exception
    leaves an existing report.html as it was.
    """
    run_dir = Path(run_dir)
    run = load_run(run_dir)
    html = render_html(build_context(run))
    target = run_dir / REPORT_FILE
    write_atomically(target, html)
    return target


def report_command(run_dir: Path | str) -> int:
    """``physval report DIR``: 0 and the report's path on stdout, or 2 and one line on stderr."""
    run_dir = Path(run_dir)
    try:
        path = render_report(run_dir)
    except ReportInputError as error:
        print(f"{run_dir}: {error}", file=sys.stderr)
        return EXIT_BAD_INPUT
    print(path)
    return EXIT_OK
