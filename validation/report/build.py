"""Phase 3 of report.html: the template's context, as plain strings, lists and dicts.

``build_context(run)`` judges the rows (``outcomes``) and builds, in the page's order:
the verdict and summary chips, the scene x engine matrix (``build_cell``), the worst
offenders (``build_rows``), one section per scene (``build_scene``: runs, the sim2sim card
from ``sim2sim``, the plot from ``plots``, impacts, checks), the legend (``build_legend``) and
the provenance (``build_provenance``).
"""

from __future__ import annotations

import dataclasses
import json
import math
import re
from typing import Any

import numpy as np
import pandas as pd
from markupsafe import Markup

from validation.contract import (
    NOT_JUDGED_STATUSES,
    RUN_FAILURE_STATUSES,
    SERIES_FILE,
    STATUS_DESCRIPTIONS,
)
from validation.measure.definitions import (
    BAND_DEFINITION,
    EXPECTATION_DEFINITIONS,
    EXPECTED_KINDS,
    INTERPOLATION_BOUND,
    METRIC_DEFINITIONS,
    SAMPLING_DEFINITION,
    SIGNED_ERROR_DEFINITION,
)
from validation.measure.noise import NOISE_RULE
from validation.measure.resolution import RESOLUTION_MARK
from validation.redact import shown_url
from validation.report.closed_form import closed_form_charts, read_expectations
from validation.report.news import (
    build_news,
    build_sweep_cards,
    class_counts,
    headline,
    news_selections,
)
from validation.report.outcomes import (
    OUTCOME_COLOURS,
    OUTCOME_ORDER,
    RED_OUTCOMES,
    RUN_FAILURES,
    classify_rows,
    outcome_label,
    worst_first,
)
from validation.report.palette import engine_colour
from validation.report.plots import (
    PLOT_LIMIT,
    PLOTTED_IMPACTS,
    PLOTTED_SERIES,
    drawable,
    plot_restitution,
    plot_scene_series,
)
from validation.report.read import RunData
from validation.report.sim2sim import build_sim2sim_card
from validation.report.svgchart import engine_legend, figure_html

# --- page size limits --------------------------------------------------------------------------

MAX_OFFENDERS = 20  # rows in the "worst offenders" table at the top
MAX_IMPACT_ROWS = 40  # impacts listed per scene; the rest stay in impacts.csv
IMPACTS_OPEN_UP_TO = 12  # an impacts table this short is shown expanded

SETTINGS_INLINE_UP_TO = 3
"""A run's settings that differ from its spec's (provenance.json) are listed inline up to this
many; more are folded under their count (they are long: one line of the table each)."""

REPORT_TEXT_CAP = 2_000
"""Characters of one text of an engine's (a row's message, a setting, a version, a note) the
report shows; the rest is counted and left to the run folder, whose results.csv and
provenance.json keep it whole. The library's longest message is 731 characters; an engine
that raised with a 20 MiB message made a 482 MB report.html (the text in every table that
shows the row)."""

CAPPED_COLUMNS = {
    "message": "results.csv",
    "settings": "results.csv",
    "engine_version": "results.csv",
    "known": "results.csv",
    "news_note": "results.csv",
}
"""The text columns of the rows the report shows, each capped at ``REPORT_TEXT_CAP``, and the
file that keeps the whole text."""


def capped(text: Any, kept_in: str) -> Any:
    """``text`` cut at ``REPORT_TEXT_CAP`` characters with how many more ``kept_in`` has; any
    other value as it is."""
    if not isinstance(text, str) or len(text) <= REPORT_TEXT_CAP:
        return text
    return (
        f"{text[:REPORT_TEXT_CAP]}… ({len(text) - REPORT_TEXT_CAP:,} more characters in {kept_in})"
    )


def capped_rows(table: pd.DataFrame) -> pd.DataFrame:
    """The rows with their engine texts capped (``CAPPED_COLUMNS``)."""
    present = {c: f for c, f in CAPPED_COLUMNS.items() if c in table}
    return table.assign(
        **{c: table[c].map(lambda v, f=f: capped(v, f)) for c, f in present.items()}
    )


def capped_values(value: Any, kept_in: str = "provenance.json") -> Any:
    """Every text in ``value`` (provenance.json's nested mappings and lists) capped."""
    if isinstance(value, dict):
        return {capped(k, kept_in): capped_values(v, kept_in) for k, v in value.items()}
    if isinstance(value, list):
        return [capped_values(v, kept_in) for v in value]
    return capped(value, kept_in)


OPEN_ROWS = (*RUN_FAILURE_STATUSES, "failed", "fixed")
"""A scene's rows table starts open when one of its rows has one of these outcomes (the rows a
reader comes for: news); otherwise, known findings included (listed with their reasons in the
news), it shows its summary line and opens on a click."""


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


@dataclasses.dataclass(frozen=True)
class CellRows:
    """What a matrix cell shows of a (scene, engine)'s rows (``cell_rows``).

    Attributes:
        worst: the worst row (``worst_first``'s first) as a dict of its columns.
        ratio: the largest error/tolerance of the judged rows (NaN when none is judged).
        failed: how many rows failed. judged: how many have a ratio.
    """

    worst: dict[str, Any]
    ratio: float
    failed: int
    judged: int


def cell_rows(table: pd.DataFrame) -> dict[tuple[str, str], CellRows]:
    """(scene, engine) -> its ``CellRows``, for every pair that has rows: the table ranked
    once (``worst_first``, stable, so a cell's worst row is the one ranking its rows alone
    would put first) and grouped once, instead of once per cell."""
    keys = ["scenario", "engine"]
    worst = worst_first(table).drop_duplicates(keys)
    groups = table.assign(
        _failed=table["outcome"] == "failed", _judged=table["ratio"].notna()
    ).groupby(keys, sort=False, dropna=False)
    ratio, failed, judged = (
        groups[column].agg(how).to_dict()
        for column, how in (("ratio", "max"), ("_failed", "sum"), ("_judged", "sum"))
    )
    cells = {}
    for row in worst.to_dict("records"):
        key = (row["scenario"], row["engine"])
        cells[key] = CellRows(row, float(ratio[key]), int(failed[key]), int(judged[key]))
    return cells


def build_cell(rows: CellRows | None, anchor: str) -> dict[str, Any]:
    """One matrix cell: the worst outcome of a (scene, engine)'s rows, shown as a ratio or word."""
    if rows is None:
        return {"outcome": "not_run", "text": "–", "title": "not run", "anchor": anchor}
    worst, ratio = rows.worst, rows.ratio
    outcome = worst["outcome"]
    if outcome in (*RUN_FAILURES, *NOT_JUDGED_STATUSES, "no_tolerance") or math.isnan(ratio):
        text = outcome_label(outcome)
    else:
        text = format_ratio(ratio)
    title = f"{outcome_label(outcome)}: {worst['metric']}"
    if not math.isnan(worst["ratio"]):
        title += f" at {format_ratio(worst['ratio'])} its tolerance"
    if rows.judged:
        title += f"; {rows.failed} of {rows.judged} checks failed"
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
            "resolution": str(row["message"]).startswith(RESOLUTION_MARK),
            "known": str(row.get("known", "") or "")
            if row["outcome"] in ("known", "fixed")
            else "",
        }
        for row in worst_first(rows).to_dict("records")
    ]


def is_zero_unjudged(rows: pd.DataFrame) -> pd.Series:
    """Rows with no tolerance whose value is exactly zero (a quantity the scene cannot move in
    that engine): listed in one line, not one row each."""
    return (rows["outcome"] == "no_tolerance") & (rows["value"] == 0.0)


def zero_line(rows: pd.DataFrame) -> list[dict[str, Any]]:
    """The collapsed rows (``is_zero_unjudged``) as metric -> the engines it is zero in."""
    return [
        {"metric": metric, "engines": ", ".join(dict.fromkeys(group["engine"]))}
        for metric, group in rows.groupby("metric", sort=False)
    ]


def _pretty_settings(text: str, common: Any = None) -> tuple[str, int, int]:
    """The settings JSON of a row as ``k=v, ...`` (those that differ from ``common``, the
    engine spec's settings in provenance.json), the number of settings, and how many of them
    are as in provenance (listed there once, not in every scene)."""
    try:
        settings = json.loads(text) if text else {}
    except json.JSONDecodeError:
        return text, 1, 0
    if not isinstance(settings, dict):
        return text, 1, 0
    common = common if isinstance(common, dict) else {}
    own = {k: v for k, v in settings.items() if k not in common or str(common[k]) != str(v)}
    shown = ", ".join(f"{k}={v}" for k, v in own.items())
    return shown, len(settings), len(settings) - len(own)


def build_runs(
    rows: pd.DataFrame, engines: list[str], provenance: dict | None = None
) -> list[dict[str, Any]]:
    """One line per engine of a scene: outcome, version, dt, steps, wall time, and the
    settings that differ from the spec's in provenance.json (the others are counted)."""
    specs = (provenance or {}).get("engines")
    specs = specs if isinstance(specs, dict) else {}
    notes = _scene_engine_notes(provenance, str(rows["scenario"].iloc[0]) if len(rows) else "")
    runs = []
    # each engine's first row, its worst outcome and its status messages, the table ranked
    # and grouped once (ranking is stable: an engine's worst is the one its rows alone give)
    firsts = {row["engine"]: row for row in rows.drop_duplicates("engine").to_dict("records")}
    ranked = worst_first(rows).drop_duplicates("engine")
    worst_of = dict(zip(ranked["engine"], ranked["outcome"], strict=True))
    status = rows[rows["metric"] == "status"]
    status_messages: dict[str, list] = {}
    for engine, message in zip(status["engine"], status["message"], strict=True):
        status_messages.setdefault(engine, []).append(message)
    for engine in engines:
        first = firsts.get(engine)
        if first is None:
            continue
        worst = worst_of[engine]
        spec = specs.get(engine)
        common = spec.get("settings") if isinstance(spec, dict) else None
        settings, count, same = _pretty_settings(first["settings"], common)
        own = count - same
        messages = [m for m in dict.fromkeys(status_messages.get(engine, [])) if m]
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
                "settings_common": same,
                "settings_folded": own > SETTINGS_INLINE_UP_TO,
                "settings_own": own,
                "message": "; ".join(messages),
                "notes": notes.get(engine, []),
            }
        )
    return runs


def _scene_engine_notes(provenance: dict | None, scene: str) -> dict[str, list[str]]:
    """Engine spec -> the notes its adapter recorded for the scene (provenance.json's
    ``scenes.<scene>.engine_notes``; empty for a run recorded before it had them)."""
    scenes = (provenance or {}).get("scenes")
    entry = scenes.get(scene) if isinstance(scenes, dict) else None
    found = entry.get("engine_notes") if isinstance(entry, dict) else None
    if not isinstance(found, dict):
        return {}
    return {
        str(e): [str(n) for n in notes] for e, notes in found.items() if isinstance(notes, list)
    }


def build_impacts(impacts: pd.DataFrame | None, scene: str) -> dict[str, Any]:
    """A scene's impacts: rows (engine, then time), the largest |Δe| per engine, truncation."""
    if impacts is None:
        return {"available": False, "rows": [], "total": 0, "hidden": 0, "worst": []}
    mine = impacts[impacts["scenario"] == scene].copy()
    mine["delta_e"] = (mine["e_measured"] - mine["e_requested"]).abs()
    band = pd.to_numeric(mine["band"], errors="coerce") if "band" in mine else math.nan
    mine["band"] = band
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
            "band": format_number(row["band"]),
            "beyond": bool(row["delta_e"] > row["band"]) if row["band"] == row["band"] else False,
            "v_before": format_number(row["normal_velocity_before"]),
            "v_after": format_number(row["normal_velocity_after"]),
        }
        for row in shown.to_dict("records")
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
            "conserved": "a conserved quantity: value and error its drift, expected 0 (the "
            "scale it is divided by is in the message)",
            "engine": "another engine's result on the same scene, written engine:<spec>",
        },
        "kinds_known": EXPECTED_KINDS,
        "noise_rule": NOISE_RULE,
        "signed_error": SIGNED_ERROR_DEFINITION,
        "band": BAND_DEFINITION,
        "interpolation": INTERPOLATION_BOUND,
        "sampling": SAMPLING_DEFINITION,
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
                else ", ".join(f"{k}={v}" for k, v in sorted(settings.items()))
                if isinstance(settings, dict)
                else json.dumps(settings, default=str),
                "notes": [str(n) for n in info.get("notes", []) or []],
            }
        )
    machine = provenance.get("machine", {})
    return {
        "command": shown_url(provenance.get("command", "")),  # a foreign folder's too
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
    if series is not None:  # pd.unique keeps the order of first appearance
        engines += [e for e in pd.unique(series["engine"]) if e not in engines]
    return engines


DRIFT_METRICS = ("energy_drift", "linear_momentum_drift", "angular_momentum_drift")
"""The conserved quantities charted over time when a row of the scene measures their drift."""


def _judged_drifts(rows: pd.DataFrame) -> set[str]:
    """The drift metrics of a scene worth a chart (``plots.PLOT_QUANTITIES``): measured in
    some engine with an outcome other than ``passed`` (a failure, a known finding, a drift
    without tolerance that is not identically zero). A drift that passed everywhere is a flat
    line that says no more than its rows."""
    mine = rows[
        rows["metric"].isin(DRIFT_METRICS)
        & rows["value"].notna()
        & ~is_zero_unjudged(rows)
        & (rows["outcome"] != "passed")
    ]
    return set(mine["metric"])


def _scene_source(provenance: dict | None, scene: str) -> tuple[str, str]:
    """The scene's description and file, as the run recorded them (empty when absent)."""
    scenes = (provenance or {}).get("scenes")
    entry = scenes.get(scene) if isinstance(scenes, dict) else None
    if not isinstance(entry, dict):
        return "", ""
    description, source = entry.get("description", ""), entry.get("file", "")
    return (
        description if isinstance(description, str) else "",
        source if isinstance(source, str) else "",
    )


def build_scene(
    scene: str,
    anchor: str,
    rows: pd.DataFrame,
    run: RunData,
    engines: list[str],
) -> dict[str, Any]:
    """One scene's section: description and file, runs, the charts (the quantities under test
    against their closed forms, the conserved quantities judged, e against impact speed),
    the sweep charts, the impacts, the sim2sim card of a scene with model tiers
    (``sim2sim``) and the rows."""
    notes = []
    charts = []
    scene_engines = [e for e in engines if e in set(rows["engine"])]
    expectations = read_expectations(run.provenance, scene, run.warnings)
    closed, left_out = closed_form_charts(scene, run.trace, expectations, scene_engines, rows)
    charts += closed
    if left_out:
        notes.append(f"{left_out} more closed-form charts not drawn (the rows list every check)")
    clipped = 0
    if run.series is None:
        notes.append(f"no {SERIES_FILE} in this run")
    else:
        series, clipped = drawable(run.series[run.series["scenario"] == scene], PLOTTED_SERIES)
        judged = _judged_drifts(rows)
        if not series.empty and judged:
            charts += plot_scene_series(scene, series, scene_engines, judged)
    if run.impacts is not None:
        mine, clipped_impacts = drawable(
            run.impacts[run.impacts["scenario"] == scene], PLOTTED_IMPACTS
        )
        clipped += clipped_impacts
        if not mine.empty:
            charts.append(plot_restitution(scene, mine, scene_engines))
    if clipped:
        notes.append(
            f"{clipped} values non-finite or beyond ±{PLOT_LIMIT:g} not drawn (gaps); the CSV "
            "files keep them"
        )
    description, source = _scene_source(run.provenance, scene)
    zero = is_zero_unjudged(rows)
    shown = rows[~zero]
    return {
        "name": scene,
        "anchor": anchor,
        "description": description,
        "source": source,
        "runs": build_runs(rows, engines, run.provenance),
        "sim2sim": build_sim2sim_card(build_rows(rows), list(dict.fromkeys(rows["engine"]))),
        "engine_legend": Markup(engine_legend(scene_engines)),
        "charts": [Markup(figure_html(chart, set(scene_engines))) for chart in charts],
        "plot_note": "; ".join(notes),
        "impacts": build_impacts(run.impacts, scene),
        "rows": build_rows(shown),
        "rows_open": bool(rows["outcome"].isin(OPEN_ROWS).any()),
        "row_chips": count_chips(list(shown["outcome"])),
        "zero_rows": zero_line(rows[zero]),
        "zero_count": int(zero.sum()),
        "sweeps": build_sweep_cards(run.sweep, scene),
    }


PER_SCENE = ("series", "impacts", "trace", "sweep")
"""The record tables of a run that a scene card reads its own rows of."""


def split_by_scene(run: RunData) -> dict[str, RunData]:
    """Scene -> the run with only that scene's rows in its per-scene tables (``PER_SCENE``),
    each table grouped once: filtering the library's 200,000 series rows per scene was half
    the report's time."""
    scenes = set(run.results["scenario"])
    empty = {name: getattr(run, name) for name in PER_SCENE}
    groups = {
        name: dict(tuple(frame.groupby("scenario", sort=False)))
        for name, frame in empty.items()
        if frame is not None and "scenario" in frame
    }
    for name in groups:
        empty[name] = empty[name].iloc[0:0]
    return {
        scene: dataclasses.replace(
            run, **{name: groups[name].get(scene, empty[name]) for name in groups}
        )
        for scene in scenes
    }


def build_context(run: RunData) -> dict[str, Any]:
    """Everything the template prints, as plain strings, lists and dicts."""
    table = capped_rows(classify_rows(run.results, run.warnings))
    run = dataclasses.replace(run, provenance=capped_values(run.provenance))
    engines = _engine_order(table, run.series)
    scenes = scene_order(table)
    taken: set[str] = set()
    anchors = {scene: slug(scene, taken) for scene in scenes}
    cells = cell_rows(table)
    matrix = [
        {
            "scene": scene,
            "anchor": anchors[scene],
            "cells": [build_cell(cells.get((scene, engine)), anchors[scene]) for engine in engines],
        }
        for scene in scenes
    ]
    by_scene = dict(tuple(table.groupby("scenario", sort=False)))
    scene_runs = split_by_scene(run)
    cell_outcomes = [cell["outcome"] for row in matrix for cell in row["cells"]]
    red_runs = sum(o in RED_OUTCOMES for o in cell_outcomes)
    offenders = table[table["outcome"].isin(RED_OUTCOMES)]
    provenance = build_provenance(run.provenance, table)
    selected = news_selections(table, run.baseline)
    return {
        "title": f"physval report {provenance['created']}".strip(),
        "run_dir": str(run.run_dir),
        "warnings": run.warnings,
        "verdict": {
            "bad": red_runs > 0,
            "runs": sum(o != "not_run" for o in cell_outcomes),
            "red_runs": red_runs,
            "headline": headline(table, selected),
            "classes": class_counts(table, selected),
        },
        "scene_count": len(scenes),
        "engines": engines,
        "engine_colours": {e: engine_colour(e) for e in engines},
        "run_chips": count_chips([o for o in cell_outcomes if o != "not_run"]),
        "row_chips": count_chips(list(table["outcome"])),
        "row_count": len(table),
        "news": build_news(table, run.baseline, anchors),
        "matrix": matrix,
        "offenders": build_rows(offenders, anchors)[:MAX_OFFENDERS],
        "offenders_hidden": max(0, len(offenders) - MAX_OFFENDERS),
        "scenes": [
            build_scene(scene, anchors[scene], by_scene[scene], scene_runs[scene], engines)
            for scene in scenes
        ],
        "legend": build_legend(table),
        "provenance": provenance,
        "outcome_colours": OUTCOME_COLOURS,
        "outcome_labels": {o: outcome_label(o) for o in OUTCOME_ORDER},
        "red_outcomes": RED_OUTCOMES,
    }
