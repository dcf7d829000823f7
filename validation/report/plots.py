"""Phase 4 of report.html: matplotlib figures as inline SVG.

``plot_scene_series`` draws a scene's energy, |p| and |L| over time, one line per engine;
``svg_for_html`` (also used by ``sweep_page``) turns matplotlib's SVG file into an element
to inline in a page that has no scripts and fetches nothing.
"""

from __future__ import annotations

import io
import itertools
import re

import matplotlib
import numpy as np
import pandas as pd
from matplotlib.figure import Figure
from matplotlib.ticker import MaxNLocator

matplotlib.use("Agg")  # headless: rendering must never need a display

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

TICKS_PER_AXIS = 5
"""At most this many labelled ticks per axis: enough to read a value off, and tick labels are
most of a figure's drawing time (measured: 5 instead of matplotlib's 7-9 saves 20 %)."""

LEGEND_COLUMNS = 4
"""Engines per legend row above the plots."""

LEGEND_ROW_HEIGHT = 0.075
"""Fraction of the figure height one legend row takes (9 pt text in a 3.6 in figure)."""

MARGINS = {"left": 0.045, "right": 0.99, "bottom": 0.14, "wspace": 0.22}
"""Fixed subplot margins (figure fractions), room for tick labels at ``PLOT_FONT_SIZE``: a
fixed layout draws the figure once, where constrained layout measured every text extent
first (measured: half the rendering time of a run's report)."""

TITLE_ROOM = 0.09
"""Fraction of the height above the axes for their titles."""
MAX_POINTS_PER_LINE = 1200
"""Longer lines are thinned to per-bucket min/max pairs: spikes stay visible, the page small."""
PLOT_QUANTITIES = (
    ("energy", "energy E (J)"),
    ("p_norm", "|p| linear momentum (kg·m/s)"),
    ("L_norm", "|L| about the COM (kg·m²/s)"),
)
"""Series column -> axis title, one axis each."""


PLOT_LIMIT = 1e100
"""Largest magnitude a plotted value (time, energy, momentum, impact speed, e) may have;
beyond it, or non-finite, a value is not drawn (a gap) and the page says how many: near
1e308 matplotlib's transforms overflow (t = 1e308 crashed the report), and nothing a scene
measures comes near 1e100."""

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
    """Engine -> (colour, line style), by position in ``engines``; both cycle."""
    return {
        engine: (
            ENGINE_COLOURS[i % len(ENGINE_COLOURS)],
            ENGINE_LINE_STYLES[i % len(ENGINE_LINE_STYLES)],
        )
        for i, engine in enumerate(engines)
    }


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


def svg_for_html(svg: str) -> str:
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
    figure = Figure(figsize=FIGURE_SIZE_IN)
    axes = figure.subplots(1, len(PLOT_QUANTITIES), sharex=True)
    with np.errstate(over="ignore", invalid="ignore"):  # a norm past PLOT_LIMIT is not drawn
        series = series.assign(
            p_norm=_norm(series, ("px", "py", "pz")), L_norm=_norm(series, ("Lx", "Ly", "Lz"))
        )
    series, _ = drawable(series, ("p_norm", "L_norm"))
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
                label=plain_text(engine),
            )
    for axis, (_, title) in zip(axes, PLOT_QUANTITIES, strict=True):
        axis.xaxis.set_major_locator(MaxNLocator(TICKS_PER_AXIS))
        axis.yaxis.set_major_locator(MaxNLocator(TICKS_PER_AXIS))
        axis.set_title(title, fontsize=PLOT_FONT_SIZE + 1)
        axis.set_xlabel("t (s)", fontsize=PLOT_FONT_SIZE)
        axis.tick_params(labelsize=PLOT_FONT_SIZE)
        axis.grid(True, color="#e6e6e6", linewidth=0.6)
    handles, labels = axes[0].get_legend_handles_labels()
    rows = -(-len(labels) // LEGEND_COLUMNS)
    figure.subplots_adjust(top=1.0 - TITLE_ROOM - rows * LEGEND_ROW_HEIGHT, **MARGINS)
    if handles:
        figure.legend(
            handles,
            labels,
            loc="upper center",
            ncols=min(len(labels), LEGEND_COLUMNS),
            fontsize=PLOT_FONT_SIZE,
            frameon=False,
        )
    buffer = io.StringIO()
    # Text stays text (small, searchable); the salt makes element ids deterministic and
    # distinct between the page's figures.
    with matplotlib.rc_context({"svg.fonttype": "none", "svg.hashsalt": f"physval-{scene}"}):
        figure.savefig(buffer, format="svg", metadata={"Date": None})
    return svg_for_html(buffer.getvalue())


RESTITUTION_FIGURE_IN = (6.0, 3.2)
"""Size of the restitution-against-speed plot of a scene card."""


def plot_restitution(
    scene: str, impacts: pd.DataFrame, engines: list[str], colours: dict[str, tuple[str, str]]
) -> str:
    """e_measured against impact speed |v_n before| (log axis), one marker series per engine;
    in grey each impact's requested e with its band (where the run wrote it): an inline
    ``<svg>``. Markers, not lines: a scene's impacts may ask for several values of e."""
    figure = Figure(figsize=RESTITUTION_FIGURE_IN)
    axis = figure.subplots()
    speed = impacts["normal_velocity_before"].abs().to_numpy(float)
    band = (
        pd.to_numeric(impacts["band"], errors="coerce").fillna(0.0).to_numpy(float)
        if "band" in impacts
        else np.zeros(speed.size)
    )
    axis.errorbar(
        speed,
        impacts["e_requested"].to_numpy(float),
        yerr=band,
        fmt="_",
        color="#aaaaaa",
        elinewidth=3,
        markersize=8,
        label="e requested ± band",
    )
    for engine in engines:
        mine = impacts[impacts["engine"] == engine]
        if mine.empty:
            continue
        colour, _ = colours[engine]
        axis.plot(
            mine["normal_velocity_before"].abs().to_numpy(float),
            mine["e_measured"].to_numpy(float),
            linestyle="none",
            marker="o",
            markersize=3.5,
            color=colour,
            label=plain_text(engine),
        )
    axis.set_xscale("log")
    axis.set_xlabel("impact speed |v_n| (m/s)", fontsize=PLOT_FONT_SIZE)
    axis.set_ylabel("e measured", fontsize=PLOT_FONT_SIZE)
    axis.tick_params(labelsize=PLOT_FONT_SIZE)
    axis.grid(True, color="#e6e6e6", linewidth=0.6)
    axis.legend(fontsize=PLOT_FONT_SIZE - 1, frameon=False, loc="best")
    figure.subplots_adjust(left=0.13, right=0.98, bottom=0.16, top=0.96)
    buffer = io.StringIO()
    with matplotlib.rc_context({"svg.fonttype": "none", "svg.hashsalt": f"physval-e-{scene}"}):
        figure.savefig(buffer, format="svg", metadata={"Date": None})
    return svg_for_html(buffer.getvalue())
