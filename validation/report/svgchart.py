"""Small inline-SVG charts for report.html and sweep.html, written directly as SVG text.

A chart is a ``Chart`` of ``Trace``s (a line, markers, or both; error bars optional) on a
linear or log axis; ``render_chart`` returns an ``<svg>`` element and ``legend_items`` what
its legend lists. No matplotlib: a matplotlib figure costs 60-200 ms to save as SVG and
writes 30-80 kB (measured on the library's report: 19.5 s and 5.7 MB for ~120 figures),
where a chart here costs about a millisecond and a few kB: a line keeps at most
``MAX_POINTS`` points (each bucket's min and max, ``thin_line``) with coordinates
rounded to ``COORDINATE_DECIMALS``.

Tick labels are the tick values themselves, printed with as many digits as tell them apart:
never an offset (matplotlib's ``1e-12+5e-1``) or a multiplier. A quantity constant to
round-off is drawn on an axis at least ``MIN_RELATIVE_SPAN`` of its size wide, so a flat line
looks flat; the rows carry the exact drift.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from html import escape

import numpy as np

from validation.report.palette import engine_style

WIDTH, HEIGHT = 380, 200
"""px: one chart; three fit side by side in the report's 1200 px column."""

MARGIN = {"left": 58, "right": 10, "top": 20, "bottom": 36}
"""px around the plot area: tick labels left and below, the title above."""

FONT_PX = 11
"""Tick labels and axis titles (the page's body text is 14 px)."""

TICKS = 5
"""At most this many labelled ticks per axis: enough to read a value off."""

MAX_POINTS = 180
"""Points kept per line (buckets of min and max): about one per 1.7 px of the plot's 312 px
width, so nothing visible is lost; spikes and explosions survive the bucketing."""

COORDINATE_DECIMALS = 1
"""Decimals of an SVG coordinate (px) of text, markers and the grid: 0.1 px is below what a
screen shows."""

LINE_DECIMALS = 0
"""Decimals of a line's points (px): whole pixels, the resolution of the screen the chart is
drawn on (380 px wide), and two thirds of the bytes of 0.1 px; lines are most of a page."""

MIN_RELATIVE_SPAN = 1e-6
"""An axis spans at least this fraction of its largest |value|: a quantity conserved to
round-off (relative 1e-15) is drawn flat with 7-digit labels, not as noise with 16 digits."""

PAD = 0.04
"""Fraction of the data range added at each end of an axis, so points on the edge stay whole."""

MAX_LABEL_DIGITS = 12
"""Significant digits a tick label may take to differ from its neighbours (enough for any
axis at least ``MIN_RELATIVE_SPAN`` wide)."""

MARKER_RADIUS = 2.6
"""px, a point marker's half-size."""

PLOT_LIMIT = 1e100
"""Largest magnitude a plotted value (time, energy, momentum, impact speed, e, a traced
quantity) may have; beyond it, or non-finite, a value is not drawn (a gap): near 1e308 an
axis's span overflows (t = 1e308 crashed the report once), and nothing a scene measures comes
near 1e100."""

GRID, AXIS, TEXT = "#e6e6e6", "#888888", "#333333"
"""Grid lines, the plot's frame, and text."""

BAND_FILL, BAND_OPACITY = "#2e9d4a", 0.16
"""The tolerance band (``Chart.band``): a pale green strip behind the traces, where a check
passes."""

CHAR_PX = 0.62 * FONT_PX
"""Upper bound of a tick label character's width (px) in the page's sans-serif at
``FONT_PX``: DejaVu Sans digits and the minus sign are 0.636 em, the others narrower; the
left margin grows with the longest y label so no label is clipped by the SVG's box."""

YLABEL_PX = 16
"""px left of the y tick labels for the rotated y-axis title."""


@dataclass
class Trace:
    """One thing drawn on a chart: a line through (x, y), markers at them, or both.

    ``marker``: "" none, "o" dot, "s" square, "^" triangle, "x" cross, "-" a short bar (an
    expected value); ``hollow`` draws the outline only; ``yerr`` draws a vertical bar of that
    half-height at each point; ``legend`` False leaves it out of the chart's legend."""

    label: str
    x: np.ndarray
    y: np.ndarray
    colour: str
    dash: str = ""
    line: bool = True
    marker: str = ""
    hollow: bool = False
    yerr: np.ndarray | None = None
    width: float = 1.4
    legend: bool = True


@dataclass
class Chart:
    """A titled chart of traces, each axis linear or logarithmic."""

    title: str
    xlabel: str
    ylabel: str = ""
    traces: list[Trace] = field(default_factory=list)
    xlog: bool = False
    ylog: bool = False
    band: tuple[float, float] | None = None
    """(low, high) of the y axis where a check passes (the tolerance band), drawn as a strip
    across the plot and always inside the axis."""


def thin_line(t: np.ndarray, y: np.ndarray, max_points: int = MAX_POINTS):
    """At most ``max_points`` points: each of ``max_points // 2`` equal buckets keeps its min
    and max (in time order), so spikes and explosions survive; non-finite values become gaps
    (a bucket of gaps keeps its first point, a gap). Vectorized over the buckets."""
    t, y = np.asarray(t, dtype=float), np.asarray(y, dtype=float)
    y = np.where(np.isfinite(y), y, np.nan)
    if t.size <= max_points:
        return t, y
    per = -(-t.size // (max_points // 2))
    buckets = -(-t.size // per)
    blocks = np.full(buckets * per, np.nan)
    blocks[: t.size] = y
    blocks = blocks.reshape(buckets, per)
    empty = np.isnan(blocks).all(axis=1)
    low = np.where(np.isnan(blocks), np.inf, blocks).argmin(axis=1)
    high = np.where(np.isnan(blocks), -np.inf, blocks).argmax(axis=1)
    low[empty] = high[empty] = 0
    offsets = np.arange(buckets) * per
    index = np.unique(np.concatenate([offsets + low, offsets + high]))
    index = index[index < t.size]
    return t[index], y[index]


def _number(value: float, decimals: int = COORDINATE_DECIMALS) -> str:
    text = f"{value:.{decimals}f}"
    text = text.rstrip("0").rstrip(".") if "." in text else text
    return "0" if text in ("-0", "") else text


def _finite(values: np.ndarray, log: bool) -> np.ndarray:
    values = np.asarray(values, dtype=float)
    keep = (np.abs(values) <= PLOT_LIMIT) & ((values > 0) if log else True)
    return values[keep]


def data_range(arrays: list[np.ndarray], log: bool) -> tuple[float, float]:
    """The axis limits (in log10 units for a log axis) holding every finite value, padded."""
    values = np.concatenate([_finite(a, log) for a in arrays] or [np.zeros(0)])
    if values.size == 0:
        return (0.0, 1.0)
    if log:
        values = np.log10(values)
    low, high = float(values.min()), float(values.max())
    span = high - low
    floor = 0.5 if log else MIN_RELATIVE_SPAN * max(abs(low), abs(high))
    if span < floor or span == 0.0:
        middle = (low + high) / 2
        half = max(floor, 1.0 if middle == 0 and not log else 0.0) / 2 or 0.5
        low, high = middle - half, middle + half
    pad = PAD * (high - low)
    return low - pad, high + pad


def nice_step(span: float, count: int = TICKS) -> float:
    """A step of 1, 2, 2.5 or 5 times a power of ten giving at most ``count`` ticks."""
    raw = span / max(count - 1, 1)
    power = 10.0 ** math.floor(math.log10(raw))
    return next(
        (m * power for m in (1, 2, 2.5, 5, 10) if span / (m * power) <= count - 1), 10 * power
    )


def linear_ticks(low: float, high: float) -> list[float]:
    """Ticks at multiples of a nice step within [low, high] (exact zero where one falls)."""
    step = nice_step(high - low)
    first = math.ceil(low / step - 1e-9)
    ticks = [(first + i) * step for i in range(math.floor(high / step + 1e-9) - first + 1)]
    return [0.0 if abs(t) < step * 1e-9 else t for t in ticks]


def log_ticks(low: float, high: float) -> list[float]:
    """Ticks of a log axis (limits in log10 units): powers of ten, every k-th one when there are
    many; on an axis spanning less than two decades, linear ticks in value."""
    decades = list(range(math.ceil(low - 1e-9), math.floor(high + 1e-9) + 1))
    if len(decades) < 2:
        return [t for t in linear_ticks(10.0**low, 10.0**high) if t > 0]
    every = -(-len(decades) // TICKS)
    return [10.0**d for d in decades[::every]]


def tick_labels(ticks: list[float]) -> list[str]:
    """Each tick's value with the fewest significant digits that tell the ticks apart: the
    value itself, never an offset or a multiplier."""
    for digits in range(1, MAX_LABEL_DIGITS + 1):
        labels = [_label(t, digits) for t in ticks]
        if len(set(labels)) == len(labels):
            return labels
    return [_label(t, MAX_LABEL_DIGITS) for t in ticks]


PLAIN_RANGE = (1e-4, 1e6)
"""|tick| in this range is printed without an exponent (20, not 2e1; 0.0005, not 5e-4)."""


def _label(value: float, digits: int) -> str:
    text = f"{value:.{digits}g}"
    if "e" in text and PLAIN_RANGE[0] <= abs(value) < PLAIN_RANGE[1]:
        text = np.format_float_positional(
            value, precision=digits, unique=False, fractional=False, trim="-"
        )
    if "e" in text:  # 1e-05 -> 1e-5
        mantissa, exponent = text.split("e")
        text = f"{mantissa}e{int(exponent)}"
    return "0" if text == "-0" else text.replace("-", "−")


class _Scale:
    """Data -> px along one axis."""

    def __init__(self, low: float, high: float, start: float, stop: float, log: bool):
        self.low, self.high, self.start, self.stop, self.log = low, high, start, stop, log

    def __call__(self, values: np.ndarray) -> np.ndarray:
        values = np.asarray(values, dtype=float)
        values = np.where(np.abs(values) <= PLOT_LIMIT, values, np.nan)  # beyond: a gap
        with np.errstate(divide="ignore", invalid="ignore"):
            if self.log:
                values = np.where(values > 0, np.log10(np.where(values > 0, values, 1.0)), np.nan)
            fraction = (values - self.low) / (self.high - self.low)
        return self.start + fraction * (self.stop - self.start)


def _runs(x: np.ndarray, y: np.ndarray) -> list[str]:
    """Path data (``_path_data``) of the line's runs at line resolution (``LINE_DECIMALS``),
    split where a point is not drawable (a gap); a point that repeats its predecessor, or lies between two neighbours on
    the same horizontal or vertical pixel line, adds nothing drawn and is left out (a flat
    conserved quantity is two points, not 240)."""
    good = np.isfinite(x) & np.isfinite(y)
    found, current = [], []
    for xi, yi, ok in zip(
        np.round(x, LINE_DECIMALS).tolist(),
        np.round(y, LINE_DECIMALS).tolist(),
        good.tolist(),
        strict=True,
    ):
        if not ok:
            found, current = ([*found, current] if current else found), []
            continue
        point = (xi, yi)
        if current and current[-1] == point:
            continue
        if len(current) >= 2 and _between(current[-2], current[-1], point):
            current[-1] = point
            continue
        current.append(point)
    runs = [*found, current] if current else found
    return [_path_data(run) for run in runs]


def _path_data(run: list[tuple[float, float]]) -> str:
    """SVG path data of the points ``run`` (px, at ``LINE_DECIMALS``): a move to the first,
    then relative line-tos ``l dx dy ...``: the same polyline in about 60 % of the bytes of
    absolute ``x,y`` pairs (neighbouring points are a few pixels apart). The separator
    before a minus sign is left out, as the path grammar allows."""
    x_px, y_px = np.array(run).T
    moves = np.column_stack([np.diff(x_px), np.diff(y_px)]).ravel().tolist()
    text = [f"M{_number(x_px[0], LINE_DECIMALS)} {_number(y_px[0], LINE_DECIMALS)}"]
    for i, move in enumerate(moves):
        step = _number(move, LINE_DECIMALS)
        text.append(("l" if i == 0 else "" if step.startswith("-") else " ") + step)
    return "".join(text)


def _between(first: tuple, middle: tuple, last: tuple) -> bool:
    """``middle`` lies on the straight horizontal or vertical segment from ``first`` to ``last``."""
    for axis in (0, 1):
        other = 1 - axis
        if first[other] == middle[other] == last[other]:
            low, high = sorted((first[axis], last[axis]))
            return low <= middle[axis] <= high
    return False


def _marker_path(kind: str, x: np.ndarray, y: np.ndarray) -> str:
    r = MARKER_RADIUS
    good = np.isfinite(x) & np.isfinite(y)
    parts = []
    for xi, yi in zip(x[good].tolist(), y[good].tolist(), strict=True):
        if kind == "^":
            parts.append(f"M{_number(xi)} {_number(yi - r)}l{r:.1f} {1.7 * r:.1f}h{-2 * r:.1f}z")
        elif kind == "x":
            parts.append(
                f"M{_number(xi - r)} {_number(yi - r)}l{2 * r:.1f} {2 * r:.1f}m0 {-2 * r:.1f}l{-2 * r:.1f} {2 * r:.1f}"
            )
        elif kind == "-":
            parts.append(f"M{_number(xi - 2 * r)} {_number(yi)}h{4 * r:.1f}")
        else:  # "o" and "s": a zero-length segment drawn with a round or square cap
            parts.append(f"M{_number(xi)} {_number(yi)}h0")
    return "".join(dict.fromkeys(parts))  # an opaque marker drawn twice at one spot shows once


def _markers(trace: Trace, x: np.ndarray, y: np.ndarray) -> str:
    colour = escape(trace.colour)
    title = f"<title>{escape(trace.label)}</title>"
    path = _marker_path(trace.marker, x, y)
    if not path:
        return ""
    if trace.marker in ("o", "s") and not trace.hollow:
        cap = "round" if trace.marker == "o" else "square"
        return (
            f'<path d="{path}" stroke="{colour}" stroke-width="{2 * MARKER_RADIUS:.1f}" '
            f'stroke-linecap="{cap}">{title}</path>'
        )
    if trace.marker in ("o", "s"):  # hollow: outlines
        r = MARKER_RADIUS + 0.8
        good = np.isfinite(x) & np.isfinite(y)
        body = "".join(
            dict.fromkeys(
                f'<circle cx="{_number(xi)}" cy="{_number(yi)}" r="{r:.1f}"/>'
                if trace.marker == "o"
                else f'<rect x="{_number(xi - r)}" y="{_number(yi - r)}" width="{2 * r:.1f}" '
                f'height="{2 * r:.1f}"/>'
                for xi, yi in zip(x[good].tolist(), y[good].tolist(), strict=True)
            )
        )
        return f'<g fill="none" stroke="{colour}" stroke-width="1.2">{title}{body}</g>'
    fill = "none" if trace.hollow or trace.marker in ("x", "-") else colour
    width = 2.2 if trace.marker == "-" else 1.2
    return f'<path d="{path}" fill="{fill}" stroke="{colour}" stroke-width="{width}">{title}</path>'


def _trace_svg(trace: Trace, sx: _Scale, sy: _Scale) -> str:
    x, y = np.asarray(trace.x, dtype=float), np.asarray(trace.y, dtype=float)
    parts = []
    if trace.yerr is not None:
        err = np.asarray(trace.yerr, dtype=float)
        top, bottom = sy(y + err), sy(y - err)
        px = sx(x)
        bars = "".join(
            f"M{_number(a)} {_number(b)}V{_number(c)}"
            for a, b, c in zip(px.tolist(), top.tolist(), bottom.tolist(), strict=True)
            if all(map(math.isfinite, (a, b, c))) and abs(b - c) >= 0.5
        )
        if bars:
            parts.append(
                f'<path d="{bars}" stroke="{escape(trace.colour)}" stroke-width="3" opacity="0.5"/>'
            )
    if trace.line:
        tx, ty = thin_line(x, y, MAX_POINTS) if x.size > MAX_POINTS else (x, y)
        dash = f' stroke-dasharray="{escape(trace.dash)}"' if trace.dash else ""
        for path in _runs(sx(tx), sy(ty)):
            parts.append(
                f'<path d="{path}" fill="none" stroke="{escape(trace.colour)}" '
                f'stroke-width="{trace.width}"{dash}><title>{escape(trace.label)}</title></path>'
            )
    if trace.marker:
        parts.append(_markers(trace, sx(x), sy(y)))
    return "".join(parts)


BOLD_CHAR_PX = 0.66 * FONT_PX
"""Upper bound of a bold title character's width (px), as ``CHAR_PX``."""


def _fit(title: str, width: int) -> str:
    """A title longer than the chart is wide is squeezed to fit (SVG ``textLength``) rather
    than clipped by the SVG's box."""
    room = width - 2 * MARGIN["right"]
    if len(title) * BOLD_CHAR_PX <= room:
        return ""
    return f' textLength="{room}" lengthAdjust="spacingAndGlyphs"'


def left_margin(ylabels: list[str], titled: bool) -> int:
    """px left of the plot area: the longest y tick label (``CHAR_PX`` a character) and the
    rotated axis title, at least ``MARGIN["left"]``."""
    longest = max((len(label) for label in ylabels), default=0)
    return max(MARGIN["left"], math.ceil(longest * CHAR_PX) + 6 + (YLABEL_PX if titled else 0))


def right_margin(xlabels: list[str]) -> int:
    """px right of the plot area: half the last x tick label (centred on its tick, which may
    sit on the plot's edge), at least ``MARGIN["right"]``."""
    last = len(xlabels[-1]) if xlabels else 0
    return max(MARGIN["right"], math.ceil(last * CHAR_PX / 2) + 2)


def _band_svg(band: tuple[float, float] | None, sy: _Scale, left: float, right: float) -> str:
    if band is None:
        return ""
    low, high = sorted(sy(np.array(band, dtype=float)).tolist())
    return (
        f'<rect class="band" x="{left}" y="{_number(low)}" width="{right - left}" '
        f'height="{_number(max(high - low, 1.0))}" fill="{BAND_FILL}" '
        f'fill-opacity="{BAND_OPACITY}"><title>tolerance band</title></rect>'
    )


def render_chart(chart: Chart, width: int = WIDTH, height: int = HEIGHT) -> str:
    """The chart as an inline ``<svg>`` element (class ``chart``): frame, grid, tick labels,
    axis titles and traces, clipped to the plot area."""
    xs = [t.x for t in chart.traces]
    ys = [
        np.concatenate([t.y, *(() if t.yerr is None else (t.y + t.yerr, t.y - t.yerr))])
        for t in chart.traces
    ]
    if chart.band is not None:
        ys.append(np.array(chart.band, dtype=float))
    xlow, xhigh = data_range(xs, chart.xlog)
    ylow, yhigh = data_range(ys, chart.ylog)
    xticks = log_ticks(xlow, xhigh) if chart.xlog else linear_ticks(xlow, xhigh)
    yticks = log_ticks(ylow, yhigh) if chart.ylog else linear_ticks(ylow, yhigh)
    left = left_margin(tick_labels(yticks), bool(chart.ylabel))
    right = width - right_margin(tick_labels(xticks))
    top, bottom = MARGIN["top"], height - MARGIN["bottom"]
    sx = _Scale(xlow, xhigh, left, right, chart.xlog)
    sy = _Scale(ylow, yhigh, bottom, top, chart.ylog)
    grid, labels = [], []
    for label, at in zip(tick_labels(xticks), sx(np.array(xticks)).tolist(), strict=True):
        grid.append(f"M{_number(at)} {top}V{bottom}")
        labels.append(
            f'<text x="{_number(at)}" y="{bottom + 13}" text-anchor="middle">{label}</text>'
        )
    for label, at in zip(tick_labels(yticks), sy(np.array(yticks)).tolist(), strict=True):
        grid.append(f"M{left} {_number(at)}H{right}")
        labels.append(
            f'<text x="{left - 4}" y="{_number(at + 3.5)}" text-anchor="end">{label}</text>'
        )
    body = _band_svg(chart.band, sy, left, right) + "".join(
        _trace_svg(t, sx, sy) for t in chart.traces
    )
    return (
        f'<svg class="chart" role="img" viewBox="0 0 {width} {height}" width="{width}" '
        f'height="{height}" font-size="{FONT_PX}" fill="{TEXT}" stroke-linejoin="round">'
        f"<title>{escape(chart.title)}</title>"
        f'<path d="{"".join(grid)}" stroke="{GRID}" stroke-width="0.8"/>'
        f'<rect x="{left}" y="{top}" width="{right - left}" height="{bottom - top}" fill="none" stroke="{AXIS}"/>'
        f'<g class="ticks">{"".join(labels)}</g>'
        f'<text x="{width / 2:.0f}" y="13" text-anchor="middle" font-weight="600"{_fit(chart.title, width)}>{escape(chart.title)}</text>'
        f'<text x="{(left + right) / 2:.0f}" y="{height - 4}" text-anchor="middle">{escape(chart.xlabel)}</text>'
        + (
            f'<text transform="translate(11 {(top + bottom) / 2:.0f}) rotate(-90)" text-anchor="middle">{escape(chart.ylabel)}</text>'
            if chart.ylabel
            else ""
        )
        + f"{body}</svg>"
    )


def legend_items(chart: Chart) -> list[dict[str, str]]:
    """The chart's legend: each labelled trace once (label, colour, dash, marker)."""
    seen: dict[str, dict[str, str]] = {}
    for trace in chart.traces:
        if trace.legend and trace.label not in seen:
            seen[trace.label] = {
                "label": trace.label,
                "colour": trace.colour,
                "dash": trace.dash if trace.line else "",
                "marker": trace.marker if not trace.line else "",
                "hollow": "1" if trace.hollow else "",
            }
    return list(seen.values())


LEGEND_SAMPLE = (24, 10)
"""px, a legend entry's line or marker sample."""


def _sample(item: dict[str, str]) -> str:
    width, height = LEGEND_SAMPLE
    colour = escape(item["colour"])
    marker = item.get("marker", "")
    if marker:
        trace = Trace(
            "",
            np.array([width / 2]),
            np.array([height / 2]),
            item["colour"],
            line=False,
            marker=marker,
            hollow=bool(item.get("hollow")),
        )
        drawn = _markers(trace, trace.x, trace.y)
    else:
        dash = f' stroke-dasharray="{escape(item["dash"])}"' if item.get("dash") else ""
        drawn = f'<path d="M1 {height / 2}H{width - 1}" stroke="{colour}" stroke-width="2"{dash}/>'
    return f'<svg class="sample" width="{width}" height="{height}" viewBox="0 0 {width} {height}">{drawn}</svg>'


def legend_html(items: list[dict[str, str]]) -> str:
    """Legend entries (``legend_items``) as one line of samples and labels."""
    return "".join(
        f'<span class="key">{_sample(item)}{escape(item["label"])}</span>' for item in items
    )


def figure_html(chart: Chart, skip: set[str] | frozenset = frozenset()) -> str:
    """The chart and its legend (the traces labelled in ``skip`` left out: the engines, when
    the page lists them once above its charts) as a ``<figure class="chart">``."""
    items = [item for item in legend_items(chart) if item["label"] not in skip]
    caption = f'<figcaption class="legend">{legend_html(items)}</figcaption>' if items else ""
    return f'<figure class="chart">{render_chart(chart)}{caption}</figure>'


def engine_legend(engines: list[str]) -> str:
    """Each engine spec's line sample and label (its ``palette`` style), once for a page part."""
    items = []
    for engine in engines:
        style = engine_style(engine)
        items.append({"label": engine, "colour": style.colour, "dash": style.dash, "marker": ""})
    return legend_html(items)
