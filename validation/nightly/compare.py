"""``physval compare RUN_A RUN_B``: the rows that moved beyond noise between two runs.

Each run is a run folder (results.csv, provenance.json) or the id of a run in the history
(``--db``); an existing folder wins over a number. Rows are matched on (scenario, engine spec,
metric) and classified by the noise rule (``validation.measure.noise``, defined there once):

- ``regressed`` / ``improved`` / ``changed``: decided by the noise rule
  (``validation.measure.noise.classify_change``, the one rule of baseline, compare and
  history): the verdict got worse / better, or the error grew / shrank beyond the noise floor
  (finite -> inf grew, inf -> finite shrank, a lost error grew); ``changed`` a row without an
  error whose value moved, or a verdict that changed within one rank (failed -> unstable)
  while the numbers did not move;
- ``reference_moved``: a ``divergence`` row that moved while only its scene's reference
  engine moved (``noise.attribute_divergence``);
- ``new`` / ``missing``: the row is only in run B / only in run A.

Runs of different selections (``history.selection_key``: what each run was asked to run) are
compared on what both ran (``--selection shared``, the default): every row when the two runs
have one selection, else only the rows of the (scene, engine) pairs both runs ran, so that a
nightly against a scene author's run of one scene is not a list of ``missing`` rows; the rows
left out are counted on the page and in the summary line. ``--selection all`` compares every
row of both runs.

Unchanged rows are left out. Writes ``compare.csv`` and ``compare.html`` (self-contained, like
report.html) into ``--out`` (default ``reports/compare/``, beside the other generated pages and
git-ignored); exit 0 whatever moved (it is a report), 2 on bad input with one line.
"""

from __future__ import annotations

import dataclasses
import math
import sys
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import pandas as pd

from validation.contract import EXIT_BAD_INPUT, EXIT_OK
from validation.csv_safe import csv_text
from validation.files import csv_written, folder_target_problem, page_written, write_atomically
from validation.measure.noise import (
    NOISE_RULE,
    REFERENCE_MOVED,
    Reading,
    attribute_divergence,
    classify_change,
    floor_for,
    noise_floor,
)
from validation.nightly.baseline import VERDICT_RANK
from validation.nightly.history import (
    KEY_COLUMNS,
    UNRECORDED,
    HistoryInputError,
    check_url,
    database_url,
    describe_selection,
    load_run,
    read_run_folder,
    selection_key,
    valid_selection,
)
from validation.nightly.known import outcome_of
from validation.nightly.pages import render_page
from validation.report.build import format_number

COMPARE_CSV, COMPARE_HTML = "compare.csv", "compare.html"
DEFAULT_OUT = Path("reports") / "compare"
TEMPLATE = "compare.html.j2"

COMPARE_COLUMNS = (
    "scenario",
    "engine",
    "metric",
    "change",
    "value_a",
    "value_b",
    "error_a",
    "error_b",
    "tolerance",
    "noise_floor",
    "verdict_a",
    "verdict_b",
    "engine_version_a",
    "engine_version_b",
)
"""compare.csv, in order: one row per moved row (``tolerance`` is run B's, else run A's)."""

CHANGES = ("regressed", "changed", "improved", REFERENCE_MOVED, "new", "missing")
"""The classes of a moved row, news first (the page's and the CSV's order)."""

ROW_FIELDS = ("value", "error", "tolerance", "verdict", "engine_version")
"""The columns of each run that the comparison keeps, suffixed ``_a`` / ``_b``."""


@dataclass(frozen=True)
class RunSide:
    """One of the two runs: where it came from and its rows."""

    label: str
    created: str
    commit: str
    engine_versions: dict[str, str]
    rows: pd.DataFrame
    """scenario, engine, metric, value, error, tolerance, verdict, engine_version."""
    selection: dict | None = None
    """What the run was asked to run (``history.valid_selection``), None when unrecorded."""

    @property
    def selection_key(self) -> str:
        return selection_key(self.selection)


COMPARE_SELECTIONS = ("shared", "all")
"""``--selection``: the rows both runs' selections ran (default), or every row."""


def _verdicts(rows: pd.DataFrame) -> list[str]:
    """Each row's verdict: its ``outcome`` when the run wrote one (known findings), else its
    own (``known.outcome_of``)."""
    return [outcome_of(row) for row in rows.to_dict("records")]


def _side(
    label: str,
    created: Any,
    commit: Any,
    versions: Any,
    rows: pd.DataFrame,
    selection: dict | None = None,
) -> RunSide:
    rows = rows.assign(verdict=_verdicts(rows))
    return RunSide(
        label=label,
        created="" if created is None or pd.isna(created) else str(created)[:19],
        commit=str(commit or ""),
        engine_versions={
            str(k): str(v) for k, v in (versions if isinstance(versions, dict) else {}).items()
        },
        rows=rows[[*KEY_COLUMNS, *ROW_FIELDS]].reset_index(drop=True),
        selection=valid_selection(selection),
    )


def resolve_run(text: str, url: str) -> RunSide:
    """``RUN``: an existing run folder, else a run id in the history at ``url``."""
    folder = Path(text)
    if folder.is_dir():
        results, provenance = read_run_folder(folder)
        engines = provenance.get("engines")
        versions = {
            label: info.get("version", "") if isinstance(info, dict) else ""
            for label, info in (engines if isinstance(engines, dict) else {}).items()
        }
        return _side(
            str(folder),
            provenance.get("created"),
            provenance.get("git_commit"),
            versions,
            results,
            provenance.get("selection"),
        )
    if not (text.isascii() and text.isdigit()):
        raise HistoryInputError(f"{text}: no such run folder, and not a run id")
    history = load_run(url, int(text))
    run = history.runs.iloc[0]
    return _side(
        f"run {int(text)}",
        run["created"],
        run["commit"],
        run["engine_versions"],
        history.latest,
        run["selection"],
    )


@dataclass(frozen=True)
class Shared:
    """The rows ``compare`` matches (``shared_rows``) and what it left out."""

    a: RunSide
    b: RunSide
    rule: str
    same_selection: bool
    left_out: pd.DataFrame
    """run (A or B), scenario, engine, rows: the (scene, engine) pairs only that run ran."""


def compare_rule(text: str | None) -> str:
    """``--selection`` of ``compare``, checked: ``shared`` (None, the default) or ``all``."""
    rule = COMPARE_SELECTIONS[0] if text is None else text
    if rule not in COMPARE_SELECTIONS:
        raise HistoryInputError(
            f"--selection {rule[:40]!r}: expected {' or '.join(COMPARE_SELECTIONS)}"
        )
    return rule


def shared_rows(a: RunSide, b: RunSide, rule: str | None = None) -> Shared:
    """The two runs' rows to compare: ``shared`` (None, the default) every row when both runs
    recorded one selection, else only the rows of the (scene, engine) pairs both runs ran;
    ``all`` every row (``compare_rule``)."""
    rule = compare_rule(rule)
    same = a.selection_key == b.selection_key != UNRECORDED
    empty = pd.DataFrame(columns=["run", "scenario", "engine", "rows"])
    if rule == "all" or same:
        return Shared(a, b, rule, same, empty)
    pairs = [pd.MultiIndex.from_frame(side.rows[["scenario", "engine"]]) for side in (a, b)]
    both = pairs[0].intersection(pairs[1])
    kept, left_out = [], []
    for name, side, pair in zip("AB", (a, b), pairs, strict=True):
        inside = pair.isin(both)
        kept.append(dataclasses.replace(side, rows=side.rows[inside].reset_index(drop=True)))
        counts = side.rows[~inside].groupby(["scenario", "engine"], sort=True).size()
        left_out += [(name, scene, engine, int(n)) for (scene, engine), n in counts.items()]
    return Shared(*kept, rule, same, pd.DataFrame(left_out, columns=empty.columns))


def judged(row: dict[str, Any]) -> tuple[float, float]:
    """The two numbers the noise rule compares: the errors, or the values of a row that has
    no error in either run (no expected value), as history.html's trends do."""
    if math.isnan(row["error_a"]) and math.isnan(row["error_b"]):
        return row["value_a"], row["value_b"]
    return row["error_a"], row["error_b"]


def _reading(row: dict[str, Any], side: str) -> Reading:
    verdict = row[f"verdict_{side}"]
    return Reading(
        error=row[f"error_{side}"],
        value=row[f"value_{side}"],
        rank=VERDICT_RANK.get(verdict, 0),
        verdict=verdict,
    )


def classify(row: dict[str, Any]) -> str:
    """The change of one matched row (``unchanged`` when it did not move), divergence
    attribution aside (``compare_runs``)."""
    if not isinstance(row["verdict_a"], str):
        return "new"
    if not isinstance(row["verdict_b"], str):
        return "missing"
    floor = floor_for(row["scenario"], row["metric"])
    return classify_change(_reading(row, "a"), _reading(row, "b"), floor)


def _version_moved(row: dict[str, Any]) -> bool:
    a, b = (row[f"engine_version_{s}"] for s in "ab")
    return isinstance(a, str) and isinstance(b, str) and a != b


def compare_runs(a: RunSide, b: RunSide) -> pd.DataFrame:
    """The moved rows of B against A (``COMPARE_COLUMNS``), news first, then by name."""
    found = classified_rows(a, b)
    return found[found["change"] != "unchanged"].reset_index(drop=True)


def classified_rows(a: RunSide, b: RunSide) -> pd.DataFrame:
    """Every matched row of B against A with its class, ``unchanged`` ones included (last)."""
    matched = a.rows.merge(b.rows, on=list(KEY_COLUMNS), how="outer", suffixes=("_a", "_b"))
    for column in ("value", "error", "tolerance"):
        for side in "ab":
            matched[f"{column}_{side}"] = matched[f"{column}_{side}"].astype(float)
    matched["tolerance"] = matched["tolerance_b"].fillna(matched["tolerance_a"])
    records = matched.to_dict("records")
    changes = [classify(row) for row in records]
    matched["change"] = attribute_divergence(
        (
            {**row, "change": change, "version_moved": _version_moved(row)}
            for row, change in zip(records, changes, strict=True)
        ),
        "change",
    )
    matched["noise_floor"] = [
        noise_floor(*judged(r), floor_for(r["scenario"], r["metric"])) for r in records
    ]
    found = matched.copy()
    found["order"] = [(*CHANGES, "unchanged").index(change) for change in found["change"]]
    found = found.sort_values(["order", *KEY_COLUMNS], kind="stable")
    return found[list(COMPARE_COLUMNS)].reset_index(drop=True)


def _side_context(side: RunSide) -> dict[str, Any]:
    return {
        "label": side.label,
        "created": side.created,
        "commit": side.commit,
        "versions": side.engine_versions,
        "rows": len(side.rows),
        "key": side.selection_key,
        "selection": describe_selection(side.selection),
    }


def selection_context(shared: Shared) -> dict[str, Any]:
    """What compare.html says about the two selections and the rows it left out."""
    left = shared.left_out
    return {
        "rule": shared.rule,
        "same": shared.same_selection,
        "left_out_rows": int(left["rows"].sum()) if len(left) else 0,
        "left_out": [
            {"run": r.run, "scenario": r.scenario, "engine": r.engine, "rows": r.rows}
            for r in left.itertuples(index=False)
        ],
    }


def selection_note(shared: Shared) -> str:
    """The summary line's words on the selections (empty when nothing was left out)."""
    if shared.left_out.empty:
        return ""
    pairs = len(shared.left_out)
    rows = int(shared.left_out["rows"].sum())
    return (
        f"; {rows} rows of {pairs} (scene, engine) pairs only one run ran left out (selections "
        f"{shared.a.selection_key} and {shared.b.selection_key}; --selection all compares them)"
    )


def _versions(row: dict[str, Any]) -> str:
    """``old → new`` when the row's engine version changed, else the one version."""
    a, b = (
        v if isinstance(v, str) else "" for v in (row["engine_version_a"], row["engine_version_b"])
    )
    return f"{a} → {b}" if a and b and a != b else b or a


def version_note(a: RunSide, b: RunSide) -> str:
    """The printed line naming each engine whose version differs between the two runs
    (``engine versions differ: mujoco 3.3.7 → 3.4.0``; an engine one run lacks is left out),
    empty when none does: two versions of one engine compared (docs/two-engine-versions.md)."""
    moved = [
        f"{engine} {a.engine_versions[engine]} → {version}"
        for engine, version in sorted(b.engine_versions.items())
        if a.engine_versions.get(engine, version) != version
    ]
    return f"engine versions differ: {', '.join(moved)}" if moved else ""


FOLDED = ("missing", "unchanged")
"""Classes listed folded under their scene (a count first): not what a reader looks for."""


def scene_groups(rows: list[dict[str, Any]], unchanged: pd.DataFrame | None) -> list[dict]:
    """The page's rows grouped by scene, scenes with a regression first, then with any move,
    then by name; each with its counts per class, its moved rows (open when any), its missing
    rows and its unchanged rows (both folded)."""
    unchanged_counts = (
        unchanged["scenario"].value_counts().to_dict() if unchanged is not None else {}
    )
    names = list(dict.fromkeys([r["scenario"] for r in rows] + list(unchanged_counts)))
    groups = []
    for name in names:
        mine = [r for r in rows if r["scenario"] == name]
        counts = {c: sum(r["change"] == c for r in mine) for c in CHANGES}
        counts["unchanged"] = int(unchanged_counts.get(name, 0))
        moved = [r for r in mine if r["change"] not in FOLDED]
        groups.append(
            {
                "name": name,
                "counts": [(c, n) for c, n in counts.items() if n],
                "moved": moved,
                "missing": [r for r in mine if r["change"] == "missing"],
                "unchanged": _shown_rows(unchanged[unchanged["scenario"] == name])
                if unchanged is not None
                else [],
                "open": bool(moved),
                "key": (not counts["regressed"], not moved, name),
            }
        )
    return sorted(groups, key=lambda g: g["key"])


def _shown_rows(frame: pd.DataFrame) -> list[dict[str, Any]]:
    return [
        {
            **{k: row[k] for k in (*KEY_COLUMNS, "change")},
            **{k: row[k] if isinstance(row[k], str) else "" for k in ("verdict_a", "verdict_b")},
            **{
                k: format_number(row[k])
                for k in ("value_a", "value_b", "error_a", "error_b", "tolerance", "noise_floor")
            },
            "versions": _versions(row),
        }
        for row in frame.to_dict("records")
    ]


def build_context(
    a: RunSide, b: RunSide, moved_rows: pd.DataFrame, unchanged: pd.DataFrame | None = None
) -> dict[str, Any]:
    """Everything compare.html shows: the runs, the counts, the rows grouped by scene."""
    shown = _shown_rows(moved_rows)
    counts = moved_rows["change"].value_counts()
    return {
        "a": _side_context(a),
        "b": _side_context(b),
        "counts": [(change, int(counts.get(change, 0))) for change in CHANGES],
        "rows": shown,
        "scenes": scene_groups(shown, unchanged),
        "unchanged_count": 0 if unchanged is None else len(unchanged),
        "noise_rule": NOISE_RULE,
    }


COMPARE_OUTPUTS = {
    COMPARE_CSV: csv_written("a physval compare.csv", COMPARE_COLUMNS),
    COMPARE_HTML: page_written("a physval compare page", "physval compare"),
}
"""What ``compare`` writes into its ``--out``, as it begins (``files.Written``): a file there
that physval did not write is refused, never overwritten."""


def _check_flags(url: str | None, folder: Path, runs: tuple[str, str]) -> None:
    """``--db`` (when given) a usable URL even if both runs are folders, and ``--out`` a
    folder compare.csv and compare.html can be written into, neither of the run folders it
    reads nor a file there that physval did not write: HistoryInputError otherwise."""
    if url is not None:
        check_url(url, "--db")
    for run in runs:
        if Path(run).is_dir() and folder.resolve() == Path(run).resolve():
            raise HistoryInputError(f"--out: {folder} is the run folder {run} this command reads")
    problem = folder_target_problem(folder, COMPARE_OUTPUTS)
    if problem:
        raise HistoryInputError(f"--out: {problem}")


def compare_main(
    run_a: str, run_b: str, db: str | None, out: Path | None, selection: str | None = None
) -> int:
    """``physval compare``: writes compare.csv and compare.html; 0, or 2 and one line."""
    try:
        url = database_url(db)
        rule = compare_rule(selection)  # the flags checked before any run is read
        folder = out or DEFAULT_OUT
        _check_flags(url if db is not None else None, folder, (run_a, run_b))
        shared = shared_rows(resolve_run(run_a, url), resolve_run(run_b, url), rule)
    except HistoryInputError as error:
        print(error, file=sys.stderr)
        return EXIT_BAD_INPUT
    a, b = shared.a, shared.b
    every_row = classified_rows(a, b)
    moved_rows = every_row[every_row["change"] != "unchanged"].reset_index(drop=True)
    folder.mkdir(parents=True, exist_ok=True)
    write_atomically(folder / COMPARE_CSV, csv_text(moved_rows))
    unchanged = every_row[every_row["change"] == "unchanged"]
    context = {
        **build_context(a, b, moved_rows, unchanged),
        "selection": selection_context(shared),
    }
    write_atomically(folder / COMPARE_HTML, render_page(TEMPLATE, context))
    counts = ", ".join(f"{n} {change}" for change, n in context["counts"] if n)
    print(
        f"{len(moved_rows)} rows moved ({counts or 'none'}){selection_note(shared)} "
        f"-> {folder / COMPARE_HTML}"
    )
    if note := version_note(a, b):
        print(note)
    return EXIT_OK
