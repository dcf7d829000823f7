"""Terminal output of ``physval run`` through ``rich``: the progress bar and the summary matrix.

``Progress`` draws a bar on stderr while the jobs run (nothing at all when stderr is not a
terminal); ``summary`` renders the scenes x engines matrix as a string that fits a given width,
with short engine labels (E1..En) and a legend mapping them to the full engine specs.
"""

from __future__ import annotations

import datetime
import io
import math
import sys
import threading
import time
from collections import Counter
from collections.abc import Iterable
from types import TracebackType

import pandas as pd
from rich import box
from rich.console import Console
from rich.progress import (
    BarColumn,
    MofNCompleteColumn,
    TextColumn,
    TimeElapsedColumn,
    TimeRemainingColumn,
)
from rich.progress import Progress as RichProgress
from rich.table import Column, Table
from rich.text import Text

from validation.contract import SWEEP_ROW_PREFIXES
from validation.engine_api import declarations
from validation.nightly.known import outcome_of
from validation.report.news import (
    NEWS_SECTIONS,
    NEWS_WORDS,
    class_counts,
    headline,
    news_selections,
)
from validation.report.outcomes import OUTCOME_ORDER, error_ratio, outcome_label
from validation.scenario.problems import printable

BAR_WIDTH = 30
"""Characters of the progress bar itself (the old hand-drawn bar's width)."""

SUMMARY_WIDTH = 100
"""Default width of the summary in columns: fits a CI log and a standard terminal."""

SCENE_MAX_WIDTH = 28
"""Longest scene name shown in full; longer ones are truncated with an ellipsis."""

SCENE_MIN_WIDTH = 12
"""The scene column is never squeezed below this to make room for engine columns."""

CELL_MIN_WIDTH = 6
"""Narrowest engine column: an abbreviated outcome word with its marker ("*unst.") or a
compact ratio ("3.4e-5") per line."""

WORST_MARKER = "*"
"""Prefix of the worst cell of each scene (also bold), so it shows without colours too."""

NO_TOLERANCE = "-"
"""Cell word of a (scene, engine) whose rows ran fine but have no tolerance to check."""

CELL_WORDS = {"no_tolerance": NO_TOLERANCE}
"""Cell words that differ from the report's outcome words (``outcome_label``)."""

ABBREVIATIONS = {
    "passed": "pass",
    "failed": "fail",
    "unstable": "unst.",
    "crashed": "crash",
    "timed_out": "t/out",
    "model_mismatch": "mism.",
    "unsupported": "unsup",
    "not installed": "n/inst",
}
"""Short cell words used when the full word does not fit the engine column (named in a key)."""

STYLES = {
    "error": "bold red",
    "crashed": "bold red",
    "timed_out": "bold red",
    "model_mismatch": "red",
    "unstable": "red",
    "failed": "red",
    "known": "dark_orange",
    "fixed": "blue",
    "passed": "green",
    "no_tolerance": "dim",
    "unsupported": "dim",
    "not_installed": "dim",
}
"""Cell colours per outcome, the report's colour families (red: needs a look; amber: a known
finding; blue: a fixed one; green: passed; grey: nothing judged), used only when
``summary(..., color=True)``."""

RATIO_KEY = "number = largest |error|/(tolerance+band) of the cell's checked rows"
"""What the number under a cell is, for the key line (the report's cells show the same)."""

COUNT_ORDER = tuple(o for o in OUTCOME_ORDER if o != "not_run")
"""The counts line's outcomes, worst first as the report's chips; each row has one of them."""

PROGRESS_PREFIX = "progress"
"""First word of the line per finished job printed when stderr is not a terminal (a CI log),
so a log reader (or a test) can tell progress lines from messages."""


def message_lines(log: str) -> list[str]:
    """The lines of a captured stderr that are messages, not per-job progress lines (what a
    reader or a test checks is "one line")."""
    return [line for line in log.strip().splitlines() if not line.startswith(PROGRESS_PREFIX)]


class Progress:
    """Progress on stderr: a bar on a terminal, a line per finished job in a log.

    Use it as a context manager in the main process and call ``advance(label, detail)`` each
    time a job finishes, in whatever order the workers finish them (e.g. as futures complete).
    On a terminal it draws a bar (done/total, elapsed time, ETA, the last job's label). When
    stderr is not a terminal (a CI log) it prints one line per finished job instead,
    ``progress 12/240 0:01:05 bounce_ladder · mujoco ok 0.8 s``, so a long run is never
    silent for longer than its longest job (a CI's no-output timeout kills silent jobs).
    ``console`` replaces the stderr console (tests inject ``Console(force_terminal=..., file=
    ...)``). With ``auto_refresh`` a background thread redraws the clock every second; it is
    off by default because forking worker processes while such a thread writes to stderr can
    deadlock the workers (the bar is redrawn on every ``advance``).
    """

    def __init__(self, total: int, console: Console | None = None, auto_refresh: bool = False):
        self.total, self.done = total, 0
        self._lock = threading.Lock()
        self._console = console if console is not None else Console(file=sys.stderr)
        self.active = self._console.is_terminal
        self._started = time.monotonic()
        self._bar: RichProgress | None = None
        if self.active:
            self._bar = RichProgress(
                BarColumn(bar_width=BAR_WIDTH),
                MofNCompleteColumn(),
                TimeElapsedColumn(),
                TextColumn("eta"),
                TimeRemainingColumn(),
                TextColumn(
                    "{task.fields[label]}", table_column=Column(no_wrap=True, overflow="ellipsis")
                ),
                console=self._console,
                auto_refresh=auto_refresh,
            )
            self._task = self._bar.add_task("physval run", total=total, label="")
            self._bar.start()

    def advance(self, label: str, detail: str = "") -> None:
        """One job finished; ``label`` names it (e.g. "bounce_ladder · mujoco"), ``detail``
        says how it ended (e.g. "ok 0.8 s"; shown in a log's line)."""
        with self._lock:
            self.done += 1
            if self._bar is not None:
                self._bar.update(self._task, advance=1, label=label, refresh=True)
            elif self.total:
                self._console.file.write(self.line(label, detail) + "\n")
                self._console.file.flush()

    def line(self, label: str, detail: str) -> str:
        """The log line of the job just finished (``PROGRESS_PREFIX`` first)."""
        elapsed = datetime.timedelta(seconds=round(time.monotonic() - self._started))
        width = len(str(self.total))
        parts = [PROGRESS_PREFIX, f"{self.done:>{width}}/{self.total}", str(elapsed), label]
        return printable(" ".join([*parts, detail] if detail else parts))  # one line each

    def close(self) -> None:
        """Stop drawing and leave the final bar on its own line; safe to call twice."""
        with self._lock:
            if self._bar is not None:
                self._bar.stop()
                self._bar = None

    def __enter__(self) -> Progress:
        return self

    def __exit__(
        self,
        kind: type[BaseException] | None,
        value: BaseException | None,
        traceback: TracebackType | None,
    ) -> None:
        self.close()


def _number(value) -> float:
    """A cell of a row as a float: NaN for None, an empty CSV cell or text."""
    try:
        return math.nan if value is None else float(value)
    except (TypeError, ValueError):
        return math.nan


def _ratio(row: dict) -> float:
    """The row's |error| / (tolerance + band), as the report computes it (NaN unchecked)."""
    band = _number(row.get("band"))
    allowance = _number(row.get("tolerance")) + (0.0 if math.isnan(band) else band)
    return error_ratio(_number(row.get("error")), allowance)


def is_sweep_row(row: dict) -> bool:
    """Whether a row is one of a scene's sweep rows (``SWEEP_ROW_PREFIXES``)."""
    return str(row.get("metric", "")).split(".", 1)[0] in SWEEP_ROW_PREFIXES


def _cell(group: list[dict]) -> tuple[str, float | None]:
    """The worst outcome of one (scene, engine)'s rows (the report's order, ``OUTCOME_ORDER``)
    and the largest error/tolerance of its checked rows, as the report's cell shows them."""
    outcome = min((outcome_of(row) for row in group), key=OUTCOME_ORDER.index)
    ratios = [ratio for ratio in map(_ratio, group) if not math.isnan(ratio)]
    return outcome, (max(ratios) if ratios else None)


def _word(outcome: str) -> str:
    """The cell word of an outcome: the report's word, ``-`` for no tolerance."""
    return CELL_WORDS.get(outcome, outcome_label(outcome))


def _ratio_text(ratio: float) -> str:
    """Two significant digits, the shorter of fixed and compact-exponent spelling:
    0.34, 12, 1.2e3, 1.2e-4 (never wider than a narrow column for ordinary ratios); ``inf``
    for an error against a zero tolerance."""
    if not math.isfinite(ratio):
        return "inf"
    mantissa, _, exponent = f"{ratio:.2g}".partition("e")
    fixed = f"{mantissa}e{int(exponent)}" if exponent else mantissa
    mantissa, _, exponent = f"{ratio:.1e}".partition("e")
    scientific = f"{mantissa}e{int(exponent)}"
    return scientific if len(scientific) < len(fixed) else fixed


def _shown_word(word: str, worst: bool, width: int | None) -> str:
    """The cell word, abbreviated when it and the worst marker do not fit ``width``."""
    marker = WORST_MARKER if worst else ""
    if width is not None and len(marker + word) > width:
        return ABBREVIATIONS.get(word, word)
    return word


def _cell_text(word: str, ratio: float | None, worst: bool, width: int | None) -> str:
    """A cell's text on one line; with a ``width`` (narrow columns), the word abbreviated to fit
    and the ratio always on a second line, so every cell of the matrix reads the same way."""
    head = (WORST_MARKER if worst else "") + _shown_word(word, worst, width)
    if ratio is None:
        return head
    separator = " " if width is None else "\n"
    return f"{head}{separator}{_ratio_text(ratio)}"


def packed_lines(entries: Iterable[str], width: int, prefix: str, sep: str = "  ") -> list[str]:
    """``prefix`` then ``entries`` joined by ``sep``, in lines of at most ``width`` columns
    (an entry is never split; continuation lines are indented under the first entry)."""
    indent = " " * (len(prefix) + 1) if prefix else ""
    lines, line = [], ""
    for entry in entries:
        if not line:
            line = f"{prefix} {entry}" if prefix else entry
        elif len(line + sep + entry) <= width:
            line += sep + entry
        else:
            lines.append(line + sep.rstrip())
            line = indent + entry
    return [*lines, line]


def counts(rows: list[dict]) -> dict[str, int]:
    """Rows per outcome (``outcome_of``: known findings applied), worst first, only the
    outcomes that occur: the report's summary chips, adding up to ``len(rows)``."""
    found = Counter(outcome_of(row) for row in rows)
    return {outcome: found[outcome] for outcome in COUNT_ORDER if found[outcome]}


def engine_labels(rows: list[dict]) -> dict[str, str]:
    """Full engine spec -> short header label (E1..En), variants of one engine side by side."""
    specs = list(dict.fromkeys(row["engine"] for row in rows))
    names = list(dict.fromkeys(spec.split("(")[0] for spec in specs))
    ordered = sorted(specs, key=lambda spec: names.index(spec.split("(")[0]))
    return {spec: f"E{i}" for i, spec in enumerate(ordered, start=1)}


def summary(rows: list[dict], width: int = SUMMARY_WIDTH, color: bool = False) -> str:
    """Scenes x engines as text at most ``width`` columns wide, then the legend, the key and
    the counts.

    Each cell is the worst outcome of that (scene, engine), in the report's words and order
    (error, model_mismatch, unstable, failed, known, fixed, passed, "-" for no tolerance,
    unsupported), with the largest error/tolerance of its checked rows (two significant
    digits); a scene's sweep rows are tracked, not judged, and do not colour its cells. The
    worst cell of each scene is bold and marked ``*``. Engine columns are headed E1..En, named
    in the legend. ``color`` adds ANSI colours (pass ``sys.stdout.isatty()`` to colour only on
    a terminal); otherwise the text is plain.
    """
    if not rows:
        return "(no rows)"
    judged = [row for row in rows if not is_sweep_row(row)] or rows
    labels = engine_labels(judged)
    engines = list(labels)
    scenes = list(dict.fromkeys(row["scenario"] for row in rows))
    groups: dict[tuple[str, str], list[dict]] = {}
    for row in judged:
        groups.setdefault((row["scenario"], row["engine"]), []).append(row)
    cells = {key: _cell(group) for key, group in groups.items()}

    def rank(key):
        outcome, ratio = cells[key]
        return -OUTCOME_ORDER.index(outcome), -math.inf if ratio is None else ratio

    worst = set()
    for scene in scenes:
        present = [(scene, engine) for engine in engines if (scene, engine) in cells]
        ranks = {rank(key) for key in present}
        if len(ranks) > 1:  # a scene whose cells all tie has nothing to point at
            worst.add(max(present, key=rank))

    scene_width = min(SCENE_MAX_WIDTH, max(len(s) for s in [*scenes, "scene"]))
    natural = max(
        max(len(label) for label in labels.values()),
        *(len(_cell_text(_word(o), r, key in worst, None)) for key, (o, r) in cells.items()),
    )
    room = (width - scene_width - len(engines)) // len(engines)  # one space between columns
    if natural <= room:
        cell_width, fit = natural, None
    else:
        cell_width = max(room, CELL_MIN_WIDTH)
        cell_width = max(cell_width, _widest_part(cells, worst, cell_width))
        fit = cell_width
        scene_width = min(
            scene_width, max(SCENE_MIN_WIDTH, width - len(engines) * (cell_width + 1))
        )
        if scene_width + len(engines) * (cell_width + 1) > width:  # would wrap mid-word
            return "\n".join([*compact_matrix(rows, width), *_tally(rows, width)])

    table = Table(
        Column("scene", width=scene_width, no_wrap=True, overflow="ellipsis"),
        *(Column(labels[e], width=cell_width, overflow="fold") for e in engines),
        box=box.SIMPLE_HEAD,
        show_edge=False,
        padding=(0, 0),
        header_style="bold",
    )
    used = set()
    for scene in scenes:
        line = [Text(scene)]  # the column truncates it with an ellipsis
        for engine in engines:
            key = (scene, engine)
            if key not in cells:
                line.append(Text(""))
                continue
            outcome, ratio = cells[key]
            word = _word(outcome)
            if _shown_word(word, key in worst, fit) != word:
                used.add(word)
            text = _cell_text(word, ratio, key in worst, fit)
            style = STYLES.get(outcome, "") + (" bold" if key in worst else "")
            line.append(Text(text, style=style.strip()))
        table.add_row(*line)

    console = Console(
        file=io.StringIO(),
        width=width,
        color_system="standard" if color else None,
        force_terminal=color,
        legacy_windows=False,
    )
    console.print(table)
    legend = packed_lines((f"{labels[e]}={e}" for e in engines), width, "engines:")
    key = [f"{ABBREVIATIONS[word]}={word}" for word in ABBREVIATIONS if word in used]
    key += [f"{WORST_MARKER} worst cell of its scene", f"{NO_TOLERANCE} no tolerance", RATIO_KEY]
    tally = _tally(rows, width)
    for line in [*legend, *packed_lines(key, width, "key:"), *tally, *install_lines(rows)]:
        console.print(line, highlight=False, markup=False, soft_wrap=False)
    return "\n".join(line.rstrip() for line in console.file.getvalue().splitlines())


def _widest_part(cells: dict, worst: set, width: int) -> int:
    """The widest line of any cell's text in columns of ``width`` (a ratio like 1.2e-10 can
    be wider than the narrowest column)."""
    return max(
        len(part)
        for key, (outcome, ratio) in cells.items()
        for part in _cell_text(_word(outcome), ratio, key in worst, width).split("\n")
    )


def _tally(rows: list[dict], width: int) -> list[str]:
    """The counts line of the rows' outcomes, within ``width``."""
    found = (f"{n} {outcome_label(o)}" for o, n in counts(rows).items())
    return packed_lines(found, width, f"{len(rows)} rows:", ", ")


def install_lines(rows: list[dict]) -> list[str]:
    """One line per engine a scene names that is not installed here: how many scenes were
    not run in it, and how to install it."""
    absent: dict[str, set[str]] = {}
    for row in rows:
        if row.get("status") == "not_installed":
            absent.setdefault(str(row["engine"]).split("(")[0], set()).add(row["scenario"])
    engines = declarations()
    return [
        f"{name} not installed: {len(scenes)} scene{'s' if len(scenes) != 1 else ''} not run in "
        f"it ({engines[name].install if name in engines else 'install its package'})"
        for name, scenes in absent.items()
    ]


NAMED_NEWS = ("regressed", "changed", "new_failures")
"""The news sections whose rows the terminal names one by one (what a nightly reader needs
first); the others are counted, as the report's collapsed sections."""

MAX_NAMED = 10
"""Rows named per section; the rest are counted, and every one is in report.html's news."""


def _named(key: str, rows: pd.DataFrame, width: int) -> list[str]:
    """``  regressed: scene · engine · metric (error 3.1e-3)``, one per row, never cut: the
    error on a line of its own when the line would pass ``width``."""
    word = NEWS_WORDS[key].removesuffix("s") if key == "new_failures" else NEWS_WORDS[key]
    lines = []
    for _, row in rows.head(MAX_NAMED).iterrows():
        error = pd.to_numeric(pd.Series([row.get("error")]), errors="coerce").iloc[0]
        said = "" if pd.isna(error) else f" (error {error:.3g})"
        line = f"  {word}: {row['scenario']} · {row['engine']} · {row['metric']}"
        fits = len(line + said) <= width or not said
        lines += [line + said] if fits else [line, f"    {said.strip()}"]  # never cut
    if len(rows) > MAX_NAMED:
        lines.append(f"  ... and {len(rows) - MAX_NAMED} more {NEWS_WORDS[key]} in report.html")
    return lines


NO_BASELINE_NEWS = ("new_failures", "fixed", "known")
"""The news sections a run without a baseline has."""


def _against_baseline(table: pd.DataFrame) -> bool:
    """Whether the rows were classified against a baseline (a ``baseline`` class)."""
    return bool("baseline" in table and table["baseline"].fillna("").astype(bool).any())


def _news_keys(table: pd.DataFrame) -> list[str]:
    """The news sections a run has: every one against a baseline, else ``NO_BASELINE_NEWS``."""
    if _against_baseline(table):
        return [key for key, _, _ in NEWS_SECTIONS]
    return list(NO_BASELINE_NEWS)


def news_counts(
    rows: list[dict],
    comparison: pd.DataFrame | None = None,
    baseline: object = None,
    width: int = SUMMARY_WIDTH,
) -> list[str]:
    """The news line: the count of each of the run's news sections (``news``), packed
    within ``width``."""
    table = judged_table(rows)
    selected = news_selections(table, comparison)
    keys = _news_keys(table)
    counts = [f"{len(selected[key])} {NEWS_WORDS[key]}" for key in keys]
    head = f"news against {baseline}:" if _against_baseline(table) else "news (no baseline):"
    return packed_lines(counts, width, head, ", ")


def news(
    rows: list[dict],
    comparison: pd.DataFrame | None = None,
    baseline: object = None,
    width: int = SUMMARY_WIDTH,
) -> str:
    """The run's news as report.html's news counts it (``report.news.news_selections``: the
    same sections, the same counts): a line of counts, then the regressions, changed rows and
    new failures by name. ``comparison`` is the run's baseline.csv (None without a baseline),
    ``baseline`` the baseline's file, named in the first line."""
    table = judged_table(rows)
    selected = news_selections(table, comparison)
    lines = news_counts(rows, comparison, baseline, width)
    for key in NAMED_NEWS:
        if key in _news_keys(table):
            lines += _named(key, selected[key], width)
    return "\n".join(lines)


COMPACT_WORDS = {
    "error": "ERROR",
    "crashed": "CRASH",
    "timed_out": "T/OUT",
    "model_mismatch": "MISM",
    "unstable": "UNST",
    "failed": "FAIL",
    "known": "known",
    "fixed": "fixed",
    "passed": "pass",
    "no_tolerance": "-",
    "unsupported": "unsup",
    "not_installed": "n/ins",
}
"""The compact matrix's cell words, at most ``COMPACT_CELL`` wide (capitals: needs a look),
named in its key."""

COMPACT_CELL = max(len(word) for word in COMPACT_WORDS.values())
"""Width of a compact matrix cell: its longest word."""


def judged_table(rows: list[dict]) -> pd.DataFrame:
    """The rows as a table with each row's ``outcome`` (known findings applied)."""
    table = pd.DataFrame(rows)
    table["outcome"] = [outcome_of(row) for row in rows]
    return table


def compact_matrix(rows: list[dict], width: int = SUMMARY_WIDTH) -> list[str]:
    """Scenes x engines for a CI log, no line wider than the width its heading declares
    (``width``, or more when one engine key, scene name or row of cells cannot be shorter):
    engine keys (E1=spec) one entry never split, full scene names, one word per cell
    (``COMPACT_WORDS``, the worst of the cell's rows), a scene on its own line above its
    cells when both do not fit on one."""
    if not rows:
        return ["(no rows)"]
    judged = [row for row in rows if not is_sweep_row(row)] or rows
    labels = engine_labels(judged)
    column = max(COMPACT_CELL, *(len(label) for label in labels.values()))
    groups: dict[tuple[str, str], list[dict]] = {}
    for row in judged:
        groups.setdefault((row["scenario"], row["engine"]), []).append(row)
    scenes = list(dict.fromkeys(row["scenario"] for row in rows))
    cells_width = len(labels) * (column + 1) - 1
    legend = [f"{label}={engine}" for engine, label in labels.items()]
    scene_width = max(len(scene) for scene in [*scenes, "scene"])
    width = max(width, cells_width, *(len(entry) for entry in legend))
    inline = scene_width + 2 + cells_width <= width
    if not inline:
        width = max(width, *(len(scene) for scene in scenes))
    used = set()

    def cells(scene: str) -> str:
        words = []
        for engine in labels:
            group = groups.get((scene, engine))
            word = COMPACT_WORDS[_cell(group)[0]] if group else ""
            used.add(word)
            words.append(word.ljust(column))
        return " ".join(words).rstrip()

    header = " ".join(label.ljust(column) for label in labels.values()).rstrip()
    lines = [("scene".ljust(scene_width) + "  " if inline else "") + header]
    for scene in scenes:
        if inline:
            lines.append(f"{scene.ljust(scene_width)}  {cells(scene)}".rstrip())
        else:
            lines += [scene, cells(scene)]
    key = [f"{w}={outcome_label(o)}" for o, w in COMPACT_WORDS.items() if w in used]
    heading = f"matrix ({len(scenes)} scenes x {len(labels)} engines, lines <= {width} columns):"
    return [
        heading,
        *packed_lines(legend, width, "engines:"),
        *packed_lines(key, width, "key:"),
        *lines,
    ]


def shown_value(value) -> str:
    """A number as the row lines show it (4 significant digits), the text otherwise."""
    number = _number(value)
    if math.isnan(number):
        return "" if value is None or (isinstance(value, float)) else str(value)
    return f"{number:.4g}"


def row_lines(rows: list[dict], comparison: pd.DataFrame | None = None) -> list[str]:
    """One line per failing or new row, never cut: its news word (regressed, changed, new
    failure), scene, engine, metric, value, expected, tolerance and error, and for a
    regression the baseline's error before the new one."""
    selected = news_selections(judged_table(rows), comparison)
    lines = []
    for key in NAMED_NEWS:
        word = NEWS_WORDS[key].removesuffix("s") if key == "new_failures" else NEWS_WORDS[key]
        for _, row in selected[key].iterrows():
            fields = [
                f"{word}: {row['scenario']}",
                str(row["engine"]),
                str(row["metric"]),
                f"value {shown_value(row.get('value'))}",
                f"expected {shown_value(row.get('expected'))}",
                f"tolerance {shown_value(row.get('tolerance'))}",
                f"error {shown_value(row.get('error'))}",
            ]
            before = shown_value(row.get("baseline_error"))
            if before:
                fields.append(f"baseline error {before}")
            lines.append(printable(" | ".join(fields)))
    return lines


def counts_lines(
    rows: list[dict], comparison: pd.DataFrame | None = None, width: int = SUMMARY_WIDTH
) -> list[str]:
    """The headline, then every class's count within ``width``, in the words of the summary
    file and the page (``report.news.class_counts``, ``headline``)."""
    table = judged_table(rows)
    selected = news_selections(table, comparison)
    found = (f"{n} {word}" for word, n in class_counts(table, selected).items())
    return [headline(table, selected), *packed_lines(found, width, f"{len(table)} rows:", ", ")]


def log_summary(
    rows: list[dict],
    comparison: pd.DataFrame | None = None,
    baseline: object = None,
    width: int = SUMMARY_WIDTH,
) -> str:
    """What ``physval run`` prints when stdout is not a terminal (a CI log): the failing and
    new rows one per line, never cut (``row_lines``), the compact matrix (``compact_matrix``),
    the headline with every class's count and the news counts."""
    failing = row_lines(rows, comparison)
    lines = [f"failing or new rows ({len(failing)}):" if failing else "no failing or new rows"]
    lines += [*failing, *compact_matrix(rows, width), *install_lines(rows)]
    lines += [
        *counts_lines(rows, comparison, width),
        *news_counts(rows, comparison, baseline, width),
    ]
    return "\n".join(lines)
