"""sweep.html: error against wall time and against dt, per scene, one line per engine spec
(its colour on every page: ``palette``), drawn by ``svgchart`` into the shared page frame
(``templates/base.html.j2``, ``templates/sweep.html.j2``).

Failed points (unstable, error) are drawn as red crosses along the top of each chart at
their dt or run time, never dropped; the legend gives each engine's fitted convergence
order. Points the order fit left out (sweep.csv's ``fit_role``) stay on their engine's line
but are drawn hollow, one marker per reason (``ROLE_DRAWN``), named in the legend;
under each chart, each engine's order with the range it was fitted over, or why there is
none. One self-contained page (inline SVG, no network), written atomically.
"""

from __future__ import annotations

import html
import math
from pathlib import Path

import numpy as np
import pandas as pd
from markupsafe import Markup

from validation.files import write_atomically
from validation.report.palette import engine_style
from validation.report.svgchart import (
    Chart,
    Trace,
    engine_legend,
    legend_html,
    legend_items,
    render_chart,
)
from validation.report.templating import ENVIRONMENT, render_page

FITTED, FLOOR, SATURATED, OUTSIDE, UNMEASURED = FIT_ROLES = (
    "fitted",
    "floor",
    "saturated",
    "outside",
    "unmeasured",
)
"""A sweep point's ``fit_role`` in sweep.csv (``validation.jobs.sweep.fit_order`` gives it):
in the order fit; floor-bound (its error within ten times its round-off, sweep.csv's
``round_off``: the measured size of the quantity x epsilon x steps, or at the reference's own
accuracy); saturated
(its error near the largest it can be); usable but outside the asymptotic range (or in one
too short to fit); no error to fit (status not ok, NaN, infinite or zero)."""

ROLE_LABELS = {
    FITTED: "filled: in the order fit",
    FLOOR: "floor-bound: left out of the order fit",
    SATURATED: "saturated: left out of the order fit",
    OUTSIDE: "outside the asymptotic range",
}
"""The legend entry of each marker of ``ROLE_DRAWN``."""

LEGEND_GREY = "#555555"
"""The colour of the legend's marker samples (each point is drawn in its engine's colour)."""

UNITS = {"position_error": "m", "orientation_error": "rad"}
"""Unit of each sweep metric, for the axis labels."""

DEFINITIONS = {
    "position_error": "max over t and bodies of the centre-of-mass distance to the reference (m)",
    "orientation_error": "max over t and bodies of the rotation angle |log(R_refᵀ R)| between "
    "the body's orientation and the reference's (rad)",
}
"""The one-line definition of each sweep metric, printed on the page."""

IDENTICALLY_ZERO_PREFIX = "identically zero"
"""How the sweep's note of a metric zero at every dt begins (``jobs.sweep.IDENTICALLY_ZERO``)."""


FAILED_COLOUR = "#c0392b"
"""A failed (unstable, error) point: a red cross along the top of the chart at its dt."""

ROLE_DRAWN = {
    FITTED: {"marker": "o", "hollow": False},
    FLOOR: {"marker": "s", "hollow": True},
    SATURATED: {"marker": "^", "hollow": True},
    OUTSIDE: {"marker": "o", "hollow": True},
}
"""How a point is drawn by its role in the order fit (``svgchart`` markers), in its
engine's colour: filled dot in the fit, hollow square floor-bound,
hollow triangle saturated, hollow dot outside the asymptotic range."""


def _engine_traces(points: pd.DataFrame, label: str, column: str, top: float) -> list[Trace]:
    """One engine's curve on one chart: a line through its measured points in its colour,
    each point marked by its role in the fit, failed ones as red crosses at ``top``."""
    good = points[(points["status"].isin(["ok", "failed"])) & (points["error"] > 0)]
    good = good.sort_values(column, kind="stable")
    bad = points[~points["status"].isin(["ok", "failed", "unsupported"])]
    roles = good["fit_role"].fillna(FITTED) if "fit_role" in good else pd.Series(FITTED, good.index)
    style = engine_style(str(points["engine"].iloc[0]))
    x, y = good[column].to_numpy(float), good["error"].to_numpy(float)
    traces = [Trace(label, x, y, style.colour, style.dash)]
    for role, drawn in ROLE_DRAWN.items():
        mine = roles.to_numpy() == role
        if mine.any():
            traces.append(
                Trace(
                    ROLE_LABELS[role],
                    x[mine],
                    y[mine],
                    style.colour,
                    line=False,
                    legend=False,
                    **drawn,
                )
            )
    if len(bad):
        traces.append(
            Trace(
                "failed (unstable, error)",
                bad[column].fillna(1.0).to_numpy(float),
                np.full(len(bad), top),
                FAILED_COLOUR,
                line=False,
                marker="x",
            )
        )
    return traces


def _legend_label(engine: str, order: float) -> str:
    return f"{engine} (order {order:.2f})" if math.isfinite(order) else f"{engine} (no order)"


def sweep_chart(scene: pd.DataFrame, orders: dict[str, float], unit: str) -> str:
    """Error against stepping time and against dt, log-log, one line per engine spec in its
    colour (HTML: two charts and one legend naming each engine's order and the marker of each
    role in the fit drawn)."""
    measured = scene["error"][(scene["error"] > 0) & np.isfinite(scene["error"])]
    top = float(measured.max()) if len(measured) else 1.0
    charts = {
        "wall_time_s": Chart(
            "error vs run time (down-left is better)",
            "wall time of stepping (s)",
            f"error ({unit})",
            xlog=True,
            ylog=True,
        ),
        "dt": Chart(
            "error vs dt (failed points: red x)", "dt (s)", f"error ({unit})", xlog=True, ylog=True
        ),
    }
    roles: set[str] = set()
    for engine, points in scene.groupby("engine", sort=False):
        label = _legend_label(str(engine), orders.get(engine, math.nan))
        for column, chart in charts.items():
            chart.traces += _engine_traces(points, label, column, top)
        if "fit_role" in points:
            roles |= set(points["fit_role"].dropna())
    items = legend_items(charts["dt"]) + [
        {
            "label": ROLE_LABELS[role],
            "colour": LEGEND_GREY,
            "dash": "",
            "marker": drawn["marker"],
            "hollow": "1" if drawn["hollow"] else "",
        }
        for role, drawn in ROLE_DRAWN.items()
        if role in roles or (role == FITTED and not roles)
    ]
    figures = "".join(f'<figure class="chart">{render_chart(c)}</figure>' for c in charts.values())
    return f'<div class="charts">{figures}</div><p class="legend">{legend_html(items)}</p>'


def sweep_orders(table: pd.DataFrame, scene: str, metric: str) -> dict[str, float]:
    """Engine -> the fitted convergence order of ``metric`` on ``scene``."""
    mine = table[
        (table["metric"] == "convergence_order")
        & (table["scenario"] == scene)
        & (table.get("of", metric) == metric)
    ]
    return dict(zip(mine["engine"], mine["value"], strict=True))


def order_notes(table: pd.DataFrame, scene: str, metric: str) -> str:
    """HTML list: each engine's fitted order of ``metric`` on ``scene`` with the range it was
    fitted over, or the note saying why there is none (the order rows' messages)."""
    mine = table[
        (table["metric"] == "convergence_order")
        & (table["scenario"] == scene)
        & (table["of"] == metric)
    ]
    items = [
        f"<li>{html.escape(str(r['engine']))}: "
        + (f"order {r['value']:.2f}, " if pd.notna(r["value"]) else "")
        + f"{html.escape(str(r['message']) if pd.notna(r['message']) else '')}</li>"
        for _, r in mine.iterrows()
    ]
    return f"<ul class='orders'>{''.join(items)}</ul>" if items else ""


SWEEP_TEMPLATE = "sweep.html.j2"

POINT_COLUMNS = (
    "engine",
    "dt",
    "steps",
    "error",
    "round_off",
    "fit_role",
    "status",
    "wall_time_s",
    "real_time_factor",
    "message",
)
"""The columns of a sweep point listed under its charts (``round_off``: the round-off its
error carries, what a floor-bound point and an ``at round-off`` curve are judged against)."""


def _point_rows(curve: pd.DataFrame) -> list[dict[str, str]]:
    """A metric's points as display strings, each with its role's mark (``ROLE_LABELS``)."""
    columns = [c for c in POINT_COLUMNS if c in curve]
    rows = []
    for _, point in curve.iterrows():
        row = {c: format_value(point[c]) for c in columns}
        role = str(point.get("fit_role", "") or "")
        row["mark"] = ROLE_LABELS.get(role, "") if role in (FLOOR, SATURATED) else ""
        rows.append(row)
    return rows


def format_value(value) -> str:
    """A point's cell: 4 significant digits for a number, the text otherwise, empty for NaN."""
    if isinstance(value, float | np.floating):
        return "" if math.isnan(value) else f"{value:.4g}"
    return "" if value is None else str(value)


def _metric_view(table: pd.DataFrame, scene: str, group: pd.DataFrame, metric: str, unit: str):
    """One sweep metric of a scene: its charts (or the note why there are none), its order
    notes and its points; ``zero`` when the metric is identically zero in every engine."""
    curve = group[group["metric"] == metric]
    if curve.empty:
        return None
    zero = curve["message"].fillna("").astype(str).str.startswith(IDENTICALLY_ZERO_PREFIX)
    measured = curve[curve["error"].notna()] if "error" in curve else curve.iloc[0:0]
    view = {"metric": metric, "zero": bool(zero.all()), "note": "", "chart": "", "orders": ""}
    if view["zero"]:
        view["note"] = str(curve["message"].iloc[0])
    elif measured.empty:
        view["note"] = (
            f"{metric}: no values (out of range, not run, or not constrained by the reference); "
            "the points are listed."
        )
    else:
        view["chart"] = Markup(sweep_chart(curve, sweep_orders(table, scene, metric), unit))
        view["orders"] = Markup(order_notes(table, scene, metric))
    columns = [c for c in POINT_COLUMNS if c in curve]
    view["columns"], view["points"] = columns, _point_rows(curve)
    view["floor_bound"] = sum(1 for r in view["points"] if r["mark"])
    return view


def render_sweep(rows: list[dict], path: Path, fit_rule: str = "") -> Path:
    """Write sweep.html for the sweep ``rows`` (sweep.csv's rows) to ``path``; ``fit_rule``:
    the order fit's rule in one paragraph, printed under the definitions. The page leads with
    each scene's charts; a metric identically zero in every engine is one line; floor-bound
    and saturated points are marked on the charts and in the point tables."""
    table = pd.DataFrame(rows)
    if "of" not in table:
        table["of"] = ""
    if "message" not in table:
        table["message"] = ""
    points = table[table["metric"].isin(list(DEFINITIONS))]
    scenes = []
    for scene, group in points.groupby("scenario", sort=False):
        check = table[(table["metric"] == "reference_cross_check") & (table["scenario"] == scene)]
        views = [_metric_view(table, scene, group, m, u) for m, u in UNITS.items()]
        views = [v for v in views if v is not None]
        scenes.append(
            {
                "name": str(scene),
                "reference": str(group["expected_kind"].iloc[0]),
                "cross_check": ", ".join(
                    f"{r['of']} {r['value']:.3g}" for _, r in check.iterrows()
                ),
                "metrics": [v for v in views if not v["zero"]],
                "zero": [v for v in views if v["zero"]],
            }
        )
    html = render_page(
        ENVIRONMENT,
        SWEEP_TEMPLATE,
        {
            "definitions": DEFINITIONS,
            "fit_rule": fit_rule,
            "scenes": scenes,
            "engine_legend": Markup(engine_legend(list(dict.fromkeys(points.get("engine", []))))),
            "roles": ROLE_LABELS,
        },
    )
    write_atomically(path, html)
    return path
