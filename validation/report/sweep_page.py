"""sweep.html: error against wall time and against dt, per scene, one line per engine spec.

Failed points (unstable, error) are drawn as red crosses along the top of each chart at
their dt or run time, never dropped; the legend gives each engine's fitted convergence
order. Points the order fit left out (sweep.csv's ``fit_role``) stay on their engine's line
but are drawn hollow, one marker per reason (``ROLE_MARKERS``), named in the legend;
under each chart, each engine's order with the range it was fitted over, or why there is
none. One self-contained page (inline SVG, no network), written atomically.
"""

from __future__ import annotations

import html
import io
import math
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt
import pandas as pd
from matplotlib.lines import Line2D

from validation.files import write_atomically
from validation.report.plots import plain_text, svg_for_html

FIGURE_SIZE = (11.0, 3.6)
"""inches: two charts side by side, readable at a laptop's width."""

FAILED_MARKER = {"marker": "x", "color": "#c0392b", "linestyle": "none", "markersize": 8}
"""How a failed (unstable, error) point is drawn: a red cross pinned to the top of the axis."""


FITTED, FLOOR, SATURATED, OUTSIDE, UNMEASURED = FIT_ROLES = (
    "fitted",
    "floor",
    "saturated",
    "outside",
    "unmeasured",
)
"""A sweep point's ``fit_role`` in sweep.csv (``validation.jobs.sweep.fit_order`` gives it):
in the order fit; floor-bound (at round-off or at the reference's own accuracy); saturated
(its error near the largest it can be); usable but outside the asymptotic range (or in one
too short to fit); no error to fit (status not ok, NaN, infinite or zero)."""

ROLE_MARKERS = {
    FITTED: {"marker": "o", "linestyle": "none", "markersize": 6},
    FLOOR: {"marker": "s", "fillstyle": "none", "linestyle": "none", "markersize": 9},
    SATURATED: {"marker": "^", "fillstyle": "none", "linestyle": "none", "markersize": 9},
    OUTSIDE: {"marker": "o", "fillstyle": "none", "linestyle": "none", "markersize": 7},
}
"""How a point is drawn by its role in the order fit, in its engine's colour: a filled dot in
the fit (also a point of a sweep.csv without roles), a hollow square at a floor, a hollow
triangle saturated, a hollow dot outside the asymptotic range."""

ROLE_LABELS = {
    FITTED: "filled: in the order fit",
    FLOOR: "floor-bound: left out of the order fit",
    SATURATED: "saturated: left out of the order fit",
    OUTSIDE: "outside the asymptotic range",
}
"""The legend entry of each marker of ``ROLE_MARKERS``."""

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


def _draw_engine(by_time, by_dt, points: pd.DataFrame, label: str) -> set[str]:
    """One engine's curve on both charts: a line through its measured points, each point
    marked by its role in the fit (``ROLE_MARKERS``), failed ones as red crosses at the top.
    Returns the roles it drew."""
    good = points[(points["status"].isin(["ok", "failed"])) & (points["error"] > 0)]
    bad = points[~points["status"].isin(["ok", "failed", "unsupported"])]
    roles = good["fit_role"].fillna(FITTED) if "fit_role" in good else pd.Series(FITTED, good.index)
    (line,) = by_time.loglog(good["wall_time_s"], good["error"], "-", label=plain_text(label))
    by_dt.loglog(good["dt"], good["error"], "-", color=line.get_color(), label=plain_text(label))
    for axis, column in ((by_time, "wall_time_s"), (by_dt, "dt")):
        for role, marker in ROLE_MARKERS.items():
            mine = good[roles == role]
            axis.plot(mine[column], mine["error"], color=line.get_color(), **marker)
        top = axis.get_ylim()[1] if len(good) else 1.0
        axis.plot(bad[column].fillna(1.0), [top] * len(bad), **FAILED_MARKER)
    return set(roles)


def _legend_label(engine: str, order: float) -> str:
    return f"{engine} (order {order:.2f})" if math.isfinite(order) else f"{engine} (no order)"


def sweep_chart(scene: pd.DataFrame, orders: dict[str, float], unit: str) -> str:
    """Error against stepping time and against dt, log-log, one line per engine (inline SVG);
    the legend names each engine's order and the marker of each role in the fit drawn."""
    figure, (by_time, by_dt) = plt.subplots(1, 2, figsize=FIGURE_SIZE)
    drawn = set()
    for engine, points in scene.groupby("engine", sort=False):
        label = _legend_label(str(engine), orders.get(engine, math.nan))
        drawn |= _draw_engine(by_time, by_dt, points, label)
    by_time.set(
        xlabel="wall time of stepping (s)",
        ylabel=f"error ({unit})",
        title="error vs run time (down-left is better)",
    )
    by_dt.set(xlabel="dt (s)", ylabel=f"error ({unit})", title="error vs dt (failed points: red x)")
    samples = [
        Line2D([], [], color=LEGEND_GREY, label=ROLE_LABELS[role], **marker)
        for role, marker in ROLE_MARKERS.items()
        if role in drawn
    ]
    handles, _ = by_dt.get_legend_handles_labels()
    by_dt.legend(handles=handles + samples, fontsize=7)
    figure.tight_layout()
    buffer = io.StringIO()
    with matplotlib.rc_context({"svg.hashsalt": "physval-sweep"}):
        figure.savefig(buffer, format="svg", metadata={"Date": None})
    plt.close(figure)
    return svg_for_html(buffer.getvalue())


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


def render_sweep(rows: list[dict], path: Path, fit_rule: str = "") -> Path:
    """Write sweep.html for the sweep ``rows`` (sweep.csv's rows) to ``path``; ``fit_rule``:
    the order fit's rule in one paragraph, printed under the definitions."""
    table = pd.DataFrame(rows)
    if "of" not in table:
        table["of"] = ""
    if "message" not in table:
        table["message"] = ""
    parts = [
        "<!doctype html><meta charset='utf-8'><title>physval sweep</title>",
        "<style>body{font-family:sans-serif;margin:2em}td,th{padding:2px 8px;border-bottom:1px solid #ddd}"
        ".note{color:#a05a00}</style>",
        "<h1>physval sweep: error against run time</h1>",
        "<dl>"
        + "".join(
            f"<dt>{html.escape(m)}</dt><dd>{html.escape(d)}</dd>" for m, d in DEFINITIONS.items()
        )
        + "</dl>",
        f"<p>{html.escape(fit_rule)}</p>" if fit_rule else "",
    ]
    points = table[table["metric"].isin(list(DEFINITIONS))]
    for scene, group in points.groupby("scenario", sort=False):
        reference = html.escape(str(group["expected_kind"].iloc[0]))
        parts.append(f"<h2>{html.escape(str(scene))}</h2><p>reference: {reference}</p>")
        check = table[(table["metric"] == "reference_cross_check") & (table["scenario"] == scene)]
        if not check.empty:
            found = ", ".join(
                f"{html.escape(str(r['of']))} {r['value']:.3g}" for _, r in check.iterrows()
            )
            parts.append(f"<p>cross-check, MuJoCo RK4 against the reference: {found}</p>")
        for metric, unit in UNITS.items():
            curve = group[group["metric"] == metric]
            if curve.empty:
                continue
            parts.append(f"<h3>{html.escape(metric)}</h3>")
            zero = curve["message"].fillna("").astype(str).str.startswith(IDENTICALLY_ZERO_PREFIX)
            measured = curve[curve["error"].notna()] if "error" in curve else curve.iloc[0:0]
            if measured.empty:
                parts.append(
                    f"<p class='note'>{html.escape(metric)}: no values (out of range, not run, "
                    "or not constrained by the reference); the points are listed.</p>"
                )
            elif zero.all():
                note = html.escape(str(curve["message"].iloc[0]))
                parts.append(f"<p class='note'>{note}; not drawn.</p>")
            else:
                parts.append(sweep_chart(curve, sweep_orders(table, scene, metric), unit))
                parts.append(order_notes(table, scene, metric))
            columns = [
                c
                for c in (
                    "engine",
                    "dt",
                    "steps",
                    "error",
                    "fit_role",
                    "status",
                    "wall_time_s",
                    "real_time_factor",
                    "message",
                )
                if c in curve
            ]
            parts.append(
                curve[columns].to_html(
                    index=False, na_rep="", float_format=lambda v: f"{v:.4g}", escape=True
                )
            )
    write_atomically(path, "\n".join(parts))
    return path
