"""The nightly pages (history.html, compare.html): Jinja2 templates with autoescape on, and
matplotlib figures inlined as SVG. Self-contained like report.html: inline styles, inline SVG,
no scripts, nothing fetched."""

from __future__ import annotations

import io
from pathlib import Path
from typing import Any

import matplotlib
from matplotlib.figure import Figure

from validation.report import templating
from validation.report.plots import svg_for_html

matplotlib.use("Agg")  # headless: rendering must never need a display

TEMPLATE_DIR = Path(__file__).resolve().parent / "templates"

ENVIRONMENT = templating.template_environment(TEMPLATE_DIR)


def render_page(template: str, context: dict[str, Any]) -> str:
    """``templates/<template>`` rendered with ``context`` (every value escaped), compact."""
    return templating.render_page(ENVIRONMENT, template, context)


def figure_svg(figure: Figure, salt: str) -> str:
    """A figure as an inline ``<svg>``: text as text, ids salted per figure (distinct within a
    page, the same on every rendering) and no date, so the page is deterministic."""
    buffer = io.StringIO()
    with matplotlib.rc_context({"svg.fonttype": "none", "svg.hashsalt": f"physval-{salt}"}):
        figure.savefig(buffer, format="svg", metadata={"Date": None})
    return svg_for_html(buffer.getvalue())
