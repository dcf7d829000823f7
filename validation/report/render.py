"""The HTML report of one run folder: ``report.html``, one self-contained page.

``render_report(run_dir)`` reads the run's record files and writes ``run_dir/report.html``
atomically (a temporary file in the same folder, then ``os.replace``), so a failed rendering
never damages an older report. The page has no scripts and fetches nothing: the styles are
inline and the plots are inline SVG, so it works offline and can be attached to a CI run as
one file.

Phases, one module each: read (``read.load_run``) -> judge each row
(``outcomes.classify_rows``) -> build the matrix, summary, offenders and scene sections
(``build.build_context``) -> plot (``plots.plot_scene_series``) -> template
(``templates/report.html.j2``, here) -> write (``validation.files.write_atomically``, here).
"""

from __future__ import annotations

import sys
from pathlib import Path
from typing import Any

from validation.contract import EXIT_BAD_INPUT, EXIT_OK, REPORT_FILE
from validation.files import write_atomically
from validation.report.build import build_context
from validation.report.read import ReportInputError, load_run
from validation.report.templating import ENVIRONMENT, render_page

TEMPLATE_NAME = "report.html.j2"


def render_html(context: dict[str, Any]) -> str:
    """The page: ``templates/report.html.j2`` with autoescaping on, compact."""
    return render_page(ENVIRONMENT, TEMPLATE_NAME, context)


def render_report(run_dir: Path, shown_as: Path | None = None) -> Path:
    """Render ``run_dir/report.html`` from the run's record files; returns its path. The page
    names ``shown_as`` as its run folder (a run renders in staging, then publishes).

    Raises ``ReportInputError`` when results.csv is absent or unreadable. Any exception
    leaves an existing report.html as it was.
    """
    run_dir = Path(run_dir)
    run = load_run(run_dir)
    if shown_as is not None:
        run.run_dir = Path(shown_as)
    html = render_html(build_context(run))
    target = run_dir / REPORT_FILE
    write_atomically(target, html)
    return target


def report_command(run_dir: Path | str) -> int:
    """``physval report DIR``: 0 and the report's path on stdout, or 2 and one line on stderr."""
    run_dir = Path(run_dir)
    try:
        path = render_report(run_dir)
    except ReportInputError as error:
        print(f"{run_dir}: {error}", file=sys.stderr)
        return EXIT_BAD_INPUT
    except OSError as error:  # the folder cannot take report.html
        print(
            f"{run_dir / REPORT_FILE}: cannot be written ({error.strerror or error})",
            file=sys.stderr,
        )
        return EXIT_BAD_INPUT
    print(path)
    return EXIT_OK
