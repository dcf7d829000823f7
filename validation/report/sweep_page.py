"""sweep.html: error against wall time and against dt, per scene, one line per engine spec.

Failed points (unstable, error) are drawn as red crosses along the top of each chart at
their dt or run time, never dropped; the legend gives each engine's fitted convergence
order. One self-contained page (inline SVG, no network), written atomically.
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

from validation.files import write_atomically
from validation.report.plots import svg_for_html

FIGURE_SIZE = (11.0, 3.6)
"""inches: two charts side by side, readable at a laptop's width."""

FAILED_MARKER = {"marker": "x", "color": "#c0392b", "linestyle": "none", "markersize": 8}
"""How a failed (unstable, error) point is drawn: a red cross pinned to the top of the axis."""


def _chart(scene: pd.DataFrame, orders: dict[str, float]) -> str:
    figure, (by_time, by_dt) = plt.subplots(1, 2, figsize=FIGURE_SIZE)
    for engine, points in scene.groupby("engine", sort=False):
        good = points[(points["status"].isin(["ok", "failed"])) & (points["error"] > 0)]
        bad = points[~points["status"].isin(["ok", "failed", "unsupported"])]
        order = orders.get(engine, math.nan)
        label = f"{engine} (order {order:.2f})" if math.isfinite(order) else engine
        (line,) = by_time.loglog(good["wall_time_s"], good["error"], "o-", label=engine)
        by_dt.loglog(good["dt"], good["error"], "o-", color=line.get_color(), label=label)
        for axis, column in ((by_time, "wall_time_s"), (by_dt, "dt")):
            top = axis.get_ylim()[1] if len(good) else 1.0
            axis.plot(bad[column].fillna(1.0), [top] * len(bad), **FAILED_MARKER)
    by_time.set(
        xlabel="wall time of stepping (s)",
        ylabel="error",
        title="error vs run time (down-left is better)",
    )
    by_dt.set(xlabel="dt (s)", ylabel="error", title="error vs dt (failed points: red x)")
    by_dt.legend(fontsize=7)
    figure.tight_layout()
    buffer = io.StringIO()
    figure.savefig(buffer, format="svg")
    plt.close(figure)
    return svg_for_html(buffer.getvalue())


def render_sweep(rows: list[dict], path: Path) -> Path:
    """Write sweep.html for the sweep ``rows`` (sweep.csv's rows) to ``path``."""
    table = pd.DataFrame(rows)
    points = table[table["metric"] == "sweep_error"].copy()
    orders = table[table["metric"] == "convergence_order"]
    parts = [
        "<!doctype html><meta charset='utf-8'><title>physval sweep</title>",
        "<style>body{font-family:sans-serif;margin:2em}td,th{padding:2px 8px;border-bottom:1px solid #ddd}</style>",
        "<h1>physval sweep: error against run time</h1>",
    ]
    for scene, group in points.groupby("scenario", sort=False):
        scene_orders = dict(
            zip(
                orders[orders["scenario"] == scene]["engine"],
                orders[orders["scenario"] == scene]["value"],
                strict=True,
            )
        )
        reference = html.escape(str(group["expected_kind"].iloc[0]))
        parts.append(f"<h2>{html.escape(str(scene))}</h2><p>reference: {reference}</p>")
        parts.append(_chart(group, scene_orders))
        shown = group[
            [
                "engine",
                "dt",
                "steps",
                "error",
                "status",
                "wall_time_s",
                "real_time_factor",
                "message",
            ]
        ]
        parts.append(
            shown.to_html(index=False, na_rep="", float_format=lambda v: f"{v:.4g}", escape=True)
        )
    write_atomically(path, "\n".join(parts))
    return path
