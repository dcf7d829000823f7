"""The Jinja2 environment of every physval page: report.html, sweep.html, history.html and
compare.html extend ``templates/base.html.j2`` and include ``templates/style.css``, one
stylesheet inlined into each page (no file is fetched)."""

from __future__ import annotations

from pathlib import Path

from jinja2 import Environment, FileSystemLoader, StrictUndefined

from validation.report.outcomes import OUTCOME_COLOURS, RED_OUTCOMES

TEMPLATE_DIR = Path(__file__).resolve().parent / "templates"
"""The shared templates (base, style) and the report's and sweep page's own."""


def template_environment(*directories: Path) -> Environment:
    """Jinja2 on template folders (a page's own, then ``TEMPLATE_DIR``): autoescaping on,
    undefined names an error, and the outcome colours the stylesheet prints."""
    environment = Environment(
        loader=FileSystemLoader([*directories, TEMPLATE_DIR]),
        autoescape=True,
        undefined=StrictUndefined,
        trim_blocks=True,
        lstrip_blocks=True,
    )
    environment.globals.update(outcome_colours=OUTCOME_COLOURS, red_outcomes=RED_OUTCOMES)
    return environment


ENVIRONMENT = template_environment()
"""The report's and sweep page's templates (compiled once per process)."""
