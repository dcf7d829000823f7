"""Terminal output of ``physval run`` through ``rich``: the progress bar and the summary matrix.

``Progress`` draws a bar on stderr while the jobs run (nothing at all when stderr is not a
terminal); ``summary`` renders the scenes x engines matrix as a string that fits a given width,
with short engine labels (E1..En) and a legend mapping them to the full engine specs.
"""

from __future__ import annotations

import io
import math
import sys
import threading
from collections.abc import Iterable
from types import TracebackType

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

from validation.contract import BAD_STATUSES

BAR_WIDTH = 30
"""Characters of the progress bar itself (the old hand-drawn bar's width)."""

SUMMARY_WIDTH = 100
"""Default width of the summary in columns: fits a CI log and a standard terminal."""

SCENE_MAX_WIDTH = 28
"""Longest scene name shown in full; longer ones are truncated with an ellipsis."""

SCENE_MIN_WIDTH = 12
"""The scene column is never squeezed below this to make room for engine columns."""

CELL_MIN_WIDTH = 6
"""Narrowest engine column: an abbreviated status word with its marker ("*unst.") or a
compact ratio ("3.4e-5") per line."""

WORST_MARKER = "*"
"""Prefix of the worst cell of each scene (also bold), so it shows without colours too."""

NO_TOLERANCE = "-"
"""Cell word of a (scene, engine) whose rows ran fine but have no tolerance to check."""

CELL_WORDS = {"failed": "FAIL", "ok": "PASS"}
"""Cell words that differ from the status name; the other statuses are shown by name."""

SEVERITY = (NO_TOLERANCE, "PASS", "unsupported", "FAIL", "unstable", "model_mismatch", "error")
"""Cell words from best to worst: a cell shows its worst row, a scene highlights its worst
cell (ties broken by the larger error/tolerance ratio)."""

ABBREVIATIONS = {"unstable": "unst.", "model_mismatch": "mism.", "unsupported": "unsup"}
"""Short cell words used when the full word does not fit the engine column (named in a key)."""

STYLES = {
    "PASS": "green",
    "FAIL": "red",
    "unstable": "magenta",
    "model_mismatch": "yellow",
    "error": "red",
    "unsupported": "dim",
    NO_TOLERANCE: "dim",
}
"""Cell colours, used only when ``summary(..., color=True)``."""

TOLERANCE_FLOOR = 1e-300
"""Divisor floor of error/tolerance, so a zero tolerance gives a huge ratio, not a division error."""

COUNT_NAMES = (
    "passed",
    "failed",
    "unstable",
    "error",
    "model_mismatch",
    "unsupported",
    "no tolerance",
)
"""The counts line's categories, in order; each row falls in exactly one of them."""


class Progress:
    """A progress bar on stderr: done/total, elapsed time, ETA and the last finished job's label.

    Use it as a context manager in the main process and call ``advance(label)`` each time a
    job finishes, in whatever order the workers finish them (e.g. as futures complete). It is
    silent, with no output at all, when stderr is not a terminal. ``console`` replaces the
    stderr console (tests inject ``Console(force_terminal=True, file=...)``); the bar is then
    drawn if that console is a terminal. With ``auto_refresh`` a background thread redraws the
    clock every second; it is off by default because forking worker processes while such a
    thread writes to stderr can deadlock the workers (the bar is redrawn on every ``advance``).
    """

    def __init__(self, total: int, console: Console | None = None, auto_refresh: bool = False):
        self.total, self.done = total, 0
        self._lock = threading.Lock()
        self.active = console.is_terminal if console is not None else sys.stderr.isatty()
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
                console=console if console is not None else Console(file=sys.stderr),
                auto_refresh=auto_refresh,
            )
            self._task = self._bar.add_task("physval run", total=total, label="")
            self._bar.start()

    def advance(self, label: str) -> None:
        """One job finished; ``label`` names it (e.g. "bounce_ladder · mujoco")."""
        with self._lock:
            self.done += 1
            if self._bar is not None:
                self._bar.update(self._task, advance=1, label=label, refresh=True)

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


def _missing(value) -> bool:
    """True for None, NaN and anything that is not a number (an empty CSV cell)."""
    try:
        return value is None or math.isnan(float(value))
    except (TypeError, ValueError):
        return True


def _band(row: dict) -> float:
    """The row's discretization band (0 when it has none)."""
    band = row.get("band")
    return 0.0 if _missing(band) else float(band)


def _cell(group: list[dict]) -> tuple[str, float | None]:
    """The worst outcome of one (scene, engine)'s rows and its worst finite error/tolerance."""
    statuses = {row["status"] for row in group}
    checked = [row for row in group if not _missing(row["tolerance"])]
    ratios = [
        float(row["error"]) / max(float(row["tolerance"]) + _band(row), TOLERANCE_FLOOR)
        for row in checked
        if not _missing(row["error"])
    ]
    finite = [ratio for ratio in ratios if math.isfinite(ratio)]
    bad = [CELL_WORDS.get(status, status) for status in BAD_STATUSES if status in statuses]
    if bad:
        word = max(bad, key=SEVERITY.index)
    elif "unsupported" in statuses:
        word = "unsupported"
    else:
        word = "PASS" if checked else NO_TOLERANCE
    return word, (max(finite) if finite else None)


def _ratio_text(ratio: float) -> str:
    """Two significant digits, the shorter of fixed and compact-exponent spelling:
    0.34, 12, 1.2e3, 1.2e-4 (never wider than a narrow column for ordinary ratios)."""
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


def _packed(entries: Iterable[str], width: int, prefix: str, sep: str = "  ") -> list[str]:
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
    """Rows per category of ``COUNT_NAMES``: passed (ok and checked), the bad statuses,
    unsupported, and no tolerance (ok but unchecked); the categories add up to ``len(rows)``."""
    found = dict.fromkeys(COUNT_NAMES, 0)
    for row in rows:
        if row["status"] != "ok":
            found[row["status"]] += 1
        else:
            found["no tolerance" if _missing(row["tolerance"]) else "passed"] += 1
    return found


def engine_labels(rows: list[dict]) -> dict[str, str]:
    """Full engine spec -> short header label (E1..En), variants of one engine side by side."""
    specs = list(dict.fromkeys(row["engine"] for row in rows))
    names = list(dict.fromkeys(spec.split("(")[0] for spec in specs))
    ordered = sorted(specs, key=lambda spec: names.index(spec.split("(")[0]))
    return {spec: f"E{i}" for i, spec in enumerate(ordered, start=1)}


def summary(rows: list[dict], width: int = SUMMARY_WIDTH, color: bool = False) -> str:
    """Scenes x engines as text at most ``width`` columns wide, then the legend and counts.

    Each cell is the worst outcome of that (scene, engine) — PASS, FAIL, unstable, error,
    model_mismatch, unsupported or "-" (no tolerance) — with its worst error/tolerance ratio
    (two significant digits); the worst cell of each scene is bold and marked ``*``. Engine
    columns are headed E1..En, named in the legend. ``color`` adds ANSI colours (pass
    ``sys.stdout.isatty()`` to colour only on a terminal); otherwise the text is plain.
    """
    if not rows:
        return "(no rows)"
    labels = engine_labels(rows)
    engines = list(labels)
    scenes = list(dict.fromkeys(row["scenario"] for row in rows))
    groups: dict[tuple[str, str], list[dict]] = {}
    for row in rows:
        groups.setdefault((row["scenario"], row["engine"]), []).append(row)
    cells = {key: _cell(group) for key, group in groups.items()}

    def rank(key):
        word, ratio = cells[key]
        return SEVERITY.index(word), -math.inf if ratio is None else ratio

    worst = set()
    for scene in scenes:
        present = [(scene, engine) for engine in engines if (scene, engine) in cells]
        ranks = {rank(key) for key in present}
        if len(ranks) > 1:  # a scene whose cells all tie has nothing to point at
            worst.add(max(present, key=rank))

    scene_width = min(SCENE_MAX_WIDTH, max(len(s) for s in [*scenes, "scene"]))
    natural = max(
        max(len(label) for label in labels.values()),
        *(len(_cell_text(*cells[key], key in worst, None)) for key in cells),
    )
    room = (width - scene_width - len(engines)) // len(engines)  # one space between columns
    if natural <= room:
        cell_width, fit = natural, None
    else:
        cell_width = max(room, CELL_MIN_WIDTH)
        fit = cell_width
        scene_width = min(
            scene_width, max(SCENE_MIN_WIDTH, width - len(engines) * (cell_width + 1))
        )

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
            word, ratio = cells[key]
            if _shown_word(word, key in worst, fit) != word:
                used.add(word)
            text = _cell_text(word, ratio, key in worst, fit)
            style = STYLES.get(word, "") + (" bold" if key in worst else "")
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
    legend = _packed((f"{labels[e]}={e}" for e in engines), width, "engines:")
    key = [f"{ABBREVIATIONS[word]}={word}" for word in ABBREVIATIONS if word in used]
    key += [f"{WORST_MARKER} worst cell of its scene", f"{NO_TOLERANCE} no tolerance"]
    found = counts(rows)
    tally = _packed(
        (f"{found[name]} {name}" for name in COUNT_NAMES), width, f"{len(rows)} rows:", ", "
    )
    for line in [*legend, *_packed(key, width, "key:"), *tally]:
        console.print(line, highlight=False, markup=False, soft_wrap=False)
    return "\n".join(line.rstrip() for line in console.file.getvalue().splitlines())
