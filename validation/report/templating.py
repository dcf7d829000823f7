"""The Jinja2 environment of every physval page: report.html, sweep.html, history.html and
compare.html extend ``templates/base.html.j2`` and include ``templates/style.css``, one
stylesheet inlined into each page (no file is fetched)."""

from __future__ import annotations

import re
from pathlib import Path
from typing import Any

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


PRESERVED = re.compile(r"(<pre\b.*?</pre>)", re.S | re.I)
"""Elements whose whitespace is shown as written: left as they are by ``compact``."""

INDENT = re.compile(r"\n[ \t]+")
"""A line's leading blanks: the templates' indentation."""


def compact(html: str) -> str:
    """``html`` without the indentation of its lines (outside ``PRESERVED`` elements): the
    same page, drawn the same (a newline is still the whitespace between two tags or words),
    about 5 % smaller for the library's report."""
    parts = PRESERVED.split(html)
    return "".join(part if i % 2 else INDENT.sub("\n", part) for i, part in enumerate(parts))


def render_page(environment: Environment, template: str, context: dict[str, Any]) -> str:
    """``template`` of ``environment`` rendered with ``context`` (every value escaped),
    ``compact``."""
    return compact(environment.get_template(template).render(**context))
