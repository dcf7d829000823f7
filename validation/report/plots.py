"""Phase 4 of report.html: the charts, as inline SVG written by ``svgchart``.

``plot_scene_series`` draws the scene's energy, |p| and |L| over time (only those a drift row
of the scene judges), ``plot_restitution`` e measured against impact speed, one colour per
engine spec (``palette``) on both; ``svg_for_html`` (used by the nightly pages' matplotlib
figures) turns a matplotlib SVG file into an element to inline in a page that has no scripts
and fetches nothing.
"""

from __future__ import annotations

import re

import numpy as np
import pandas as pd

from validation.report.palette import engine_style
from validation.report.svgchart import PLOT_LIMIT, Chart, Trace

PLOT_QUANTITIES = (
    ("energy", "energy_drift", "energy E (J)"),
    ("p_norm", "linear_momentum_drift", "|p| linear momentum (kg·m/s)"),
    ("L_norm", "angular_momentum_drift", "|L| about the COM (kg·m²/s)"),
)
"""Series column -> the drift metric that judges it -> chart title: a quantity is drawn when a
row of that metric has a number in the scene (a conserved quantity under test), not otherwise."""

MAX_IMPACT_POINTS = 400
"""Impacts drawn per engine in the e-against-speed chart (evenly chosen from impacts.csv, which
keeps every impact of a run up to ``impact_log.MAX_SAMPLED_IMPACTS``): a pile of 216 balls
has thousands, and 400 already fill the chart."""

PLOTTED_SERIES = ("t", "energy", "px", "py", "pz", "Lx", "Ly", "Lz")
PLOTTED_IMPACTS = ("normal_velocity_before", "e_requested", "e_measured", "band")
"""The columns of series.csv and impacts.csv that a plot reads."""


def plain_text(label: object) -> str:
    """``label`` as matplotlib text that is printed as written: ``$`` would start mathtext
    (a name with ``$x^$`` raised a parse error), so it is escaped."""
    return str(label).replace("$", r"\$")


def drawable(table: pd.DataFrame, columns: tuple[str, ...]) -> tuple[pd.DataFrame, int]:
    """``table`` with every value of ``columns`` that is non-finite or beyond ``PLOT_LIMIT``
    set to NaN (a gap in the plot; rows without a time are dropped), and how many there were."""
    table = table.copy()
    clipped = 0
    for column in (c for c in columns if c in table):
        values = pd.to_numeric(table[column], errors="coerce").to_numpy(float)
        bad = ~(np.abs(values) <= PLOT_LIMIT)
        clipped += int(bad.sum())
        table[column] = np.where(bad, np.nan, values)
    if "t" in table:
        table = table[table["t"].notna()]
    return table, clipped


def engine_styles(engines: list[str]) -> dict[str, tuple[str, str]]:
    """Engine -> (colour, dash): each spec's own (``palette.engine_style``), on every page."""
    return {engine: tuple(engine_style(engine)) for engine in engines}


def _norm(series: pd.DataFrame, columns: tuple[str, str, str]) -> np.ndarray:
    return np.sqrt(sum(series[c].to_numpy(float) ** 2 for c in columns))


def svg_for_html(svg: str) -> str:
    """matplotlib's SVG file as an element to inline: no XML prolog, DOCTYPE or metadata."""
    svg = re.sub(r"<\?xml[^>]*\?>\s*", "", svg)
    svg = re.sub(r"<!DOCTYPE[^>]*>\s*", "", svg)
    svg = re.sub(r"<metadata>.*?</metadata>\s*", "", svg, flags=re.DOTALL)
    return svg.replace("<svg ", '<svg class="plot" role="img" ', 1).strip()


def scene_series_charts(series: pd.DataFrame, engines: list[str], judged: set[str]):
    """The conserved quantities a drift row of the scene judges (``judged``: metric names),
    over time, one line per engine: ``svgchart.Chart`` objects."""
    with np.errstate(over="ignore", invalid="ignore"):  # a norm past PLOT_LIMIT is not drawn
        series = series.assign(
            p_norm=_norm(series, ("px", "py", "pz")), L_norm=_norm(series, ("Lx", "Ly", "Lz"))
        )
    series, _ = drawable(series, ("p_norm", "L_norm"))
    charts = []
    for column, metric, title in PLOT_QUANTITIES:
        if metric not in judged:
            continue
        traces = []
        for engine in engines:
            mine = series[series["engine"] == engine].sort_values("t", kind="stable")
            if mine.empty:
                continue
            style = engine_style(engine)
            traces.append(
                Trace(
                    engine,
                    mine["t"].to_numpy(float),
                    mine[column].to_numpy(float),
                    style.colour,
                    style.dash,
                )
            )
        if traces:
            charts.append(Chart(title, "t (s)", "", traces))
    return charts


def plot_scene_series(scene: str, series: pd.DataFrame, engines: list[str], judged: set[str]):
    """``scene_series_charts`` of one scene (``scene`` names it in errors)."""
    return scene_series_charts(series, engines, judged)


def _evenly(frame: pd.DataFrame, count: int) -> pd.DataFrame:
    if len(frame) <= count:
        return frame
    return frame.iloc[np.unique(np.linspace(0, len(frame) - 1, count).astype(int))]


def plot_restitution(scene: str, impacts: pd.DataFrame, engines: list[str]):
    """e measured against impact speed |v_n before| (log axis), markers in each engine's
    colour; in grey each impact's requested e with its band (where the run wrote it): a
    ``svgchart.Chart``. Markers, not lines: a scene's impacts may ask for several e."""
    band = (
        pd.to_numeric(impacts["band"], errors="coerce").fillna(0.0)
        if "band" in impacts
        else pd.Series(0.0, index=impacts.index)
    )
    requested = _evenly(impacts.assign(band=band), MAX_IMPACT_POINTS * max(1, len(engines)))
    traces = [
        Trace(
            "e requested ± band",
            requested["normal_velocity_before"].abs().to_numpy(float),
            requested["e_requested"].to_numpy(float),
            "#aaaaaa",
            line=False,
            marker="-",
            yerr=requested["band"].to_numpy(float),
        )
    ]
    for engine in engines:
        mine = _evenly(impacts[impacts["engine"] == engine], MAX_IMPACT_POINTS)
        if mine.empty:
            continue
        traces.append(
            Trace(
                engine,
                mine["normal_velocity_before"].abs().to_numpy(float),
                mine["e_measured"].to_numpy(float),
                engine_style(engine).colour,
                line=False,
                marker="o",
            )
        )
    return Chart(
        "e measured against impact speed", "impact speed |v_n| (m/s)", "e", traces, xlog=True
    )
