"""Terminal output (validation.jobs.terminal): the summary fits its width and says what the rows
say; the progress bar is silent off a terminal and draws on one."""

from __future__ import annotations

import io
import math
import re

import pandas as pd
import pytest
from rich.console import Console

from validation.contract import RESULTS_COLUMNS
from validation.jobs.terminal import (
    COMPACT_WORDS,
    PROGRESS_PREFIX,
    SCENE_MAX_WIDTH,
    Progress,
    compact_matrix,
    counts_lines,
    log_summary,
    news,
    row_lines,
    summary,
)
from validation.nightly.known import outcome_of
from validation.report.outcomes import outcome_label

BARE_RUN_SCENES = [
    "gazebo_boxes_complex",
    "gazebo_boxes_simple",
    "mujoco_free_box_energy",
    "simbenchmark_666_pile",
    "simbenchmark_bouncing_7x7",
    "box_drop_edge",
    "box_drop_flat",
    "box_stack",
    "capsule_drop",
    "newtons_cradle",
    "bounce_ladder",
    "head_on_ratio_1",
    "head_on_ratio_10",
    "head_on_ratio_1e6",
    "oblique_impact_spin",
    "projectile",
    "dzhanibekov_box",
    "stable_major_axis_spin",
    "torque_free_symmetric_top",
    "deep_initial_penetration",
    "impact_100ms_thin_box",
    "mass_ratio_1e6",
    "millimetre_spheres",
    "slow_bounce_below_threshold",
    "stiff_spring_chain",
    "stiff_spring_oscillator",
    "a_scene_name_well_beyond_the_truncation_limit",  # stands for a long user scene
]
"""27 scenes, as in a bare ``physval run`` (the bundled library's names, one made long)."""

BARE_RUN_SPECS = [
    "mini",
    "mini(gyroscopic=explicit)",
    "mini(gyroscopic=implicit)",
    "mini(position_correction=baumgarte)",
    "mini(position_correction=split_impulse)",
    "mujoco",
    "mujoco(integrator=RK4)",
    "mujoco(integrator=implicitfast)",
    "pybullet",
    "pybullet(profile=defaults)",
]
"""Ten engine specs with the real long spellings of the library's scenes."""

OUTCOMES = [
    "ok",
    "ok",
    "failed",
    "ok",
    "unstable",
    "unchecked",
    "model_mismatch",
    "error",
    "unsupported",
]
"""Cycled over the (scene, engine) cells so every outcome occurs many times."""

COUNTS_LINE = re.compile(r"^(\d+) rows: (.*)$", re.MULTILINE | re.DOTALL)


def _row(scene, engine, metric, error, tolerance, status) -> dict:
    row = dict.fromkeys(RESULTS_COLUMNS)
    passed = None if tolerance is None or math.isnan(tolerance) else error <= tolerance
    row.update(
        scenario=scene,
        engine=engine,
        metric=metric,
        error=error,
        tolerance=tolerance,
        passed=passed,
        status=status,
        message="",
    )
    return row


def _cell_rows(scene: str, engine: str, outcome: str, ratio: float) -> list[dict]:
    """The rows one (scene, engine) produces for ``outcome``, the worst error/tolerance ``ratio``."""
    if outcome in ("model_mismatch", "error", "unsupported"):  # not run: one status row
        return [_row(scene, engine, "status", None, None, outcome)]
    if outcome == "unchecked":
        return [_row(scene, engine, "divergence", 0.3, math.nan, "ok")]
    status = "ok" if outcome in ("ok", "failed") else outcome
    rows = [
        _row(scene, engine, "energy_drift", ratio * 1e-3, 1e-3, "failed" if ratio > 1 else status),
        _row(scene, engine, "momentum_drift", 1e-13, 1e-6, status),
        _row(scene, engine, "divergence", 0.01, None, status),
    ]
    if outcome == "unstable":
        rows.append(_row(scene, engine, "status", None, None, "unstable"))
    return rows


def bare_run_rows(scenes=BARE_RUN_SCENES, specs=BARE_RUN_SPECS) -> list[dict]:
    rows = []
    for i, scene in enumerate(scenes):
        for j, engine in enumerate(specs):
            outcome = OUTCOMES[(i + j) % len(OUTCOMES)]
            ratio = 3.4 * 10 ** (i % 5) if outcome == "failed" else 0.012 * (j + 1)
            rows += _cell_rows(scene, engine, outcome, ratio)
    return rows


def _legend(text: str) -> dict[str, str]:
    """Short label -> full spec, read from the lines from ``engines:`` up to ``key:``."""
    block = text[text.index("engines:") : text.index("key:")]
    return dict(re.findall(r"(E\d+)=(\S+)", block))


def test_bare_run_summary_fits_100_columns_and_names_every_scene_and_engine():
    text = summary(bare_run_rows(), width=100)
    lines = text.splitlines()
    assert max(len(line) for line in lines) <= 100, max(lines, key=len)
    for scene in BARE_RUN_SCENES:
        shown = scene if len(scene) <= SCENE_MAX_WIDTH else scene[: SCENE_MAX_WIDTH - 1] + "…"
        assert any(line.startswith(shown) for line in lines), scene
    assert "a_scene_name_well_beyond_the_truncation_limit" not in text
    legend = _legend(text)
    assert sorted(legend.values()) == sorted(BARE_RUN_SPECS)
    header = lines[0].split()
    assert header[1:] == list(legend), header  # every header label is explained, in order


def test_failing_cell_shows_failed_and_its_ratio_and_is_the_only_highlight():
    rows = [
        *_cell_rows("bounce_ladder", "mini", "ok", 0.5),
        *_cell_rows("bounce_ladder", "mujoco(integrator=RK4)", "failed", 3.4),
        *_cell_rows("bounce_ladder", "pybullet", "ok", 0.25),
    ]
    text = summary(rows)
    assert "*failed 3.4" in text
    assert "passed 0.5" in text and "passed 0.25" in text
    table = text[: text.index("engines:")]
    assert table.count("*") == 1  # only the worst cell of the scene is marked


def test_ratios_keep_two_significant_digits_in_narrow_columns():
    rows = [*_cell_rows("projectile", "mini", "failed", 3456.0)]
    rows += _cell_rows("projectile", BARE_RUN_SPECS[1], "ok", 0.000123)
    for engine in BARE_RUN_SPECS[2:]:
        rows += _cell_rows("projectile", engine, "ok", 0.01234)
    text = summary(rows, width=100)
    assert "3.5e3" in text and "1.2e-4" in text and "0.012" in text
    assert "fail" in text


def test_counts_line_equals_the_outcomes_of_the_rows_in_the_reports_words():
    rows = bare_run_rows()
    text = summary(rows)
    found = COUNTS_LINE.search(text)
    assert found, text
    said = {name: int(n) for n, name in re.findall(r"(\d+) ([a-z_ ]+?)(?:,|$)", found.group(2))}
    outcomes = [outcome_of(row) for row in rows]
    expected = {outcome_label(o): outcomes.count(o) for o in set(outcomes)}
    assert int(found.group(1)) == len(rows)
    assert said == expected, (said, expected)
    assert len(expected) == 7, expected  # the synthetic run has every kind of row


def _known(rows: list[dict]) -> list[dict]:
    """The rows with the outcome a scene's known finding gives them (``apply_known``)."""
    return [
        {**row, "outcome": "known" if row["status"] == "failed" else outcome_of(row)}
        for row in rows
    ]


def test_a_known_finding_is_never_shown_as_a_failure():
    rows = [
        *_known(_cell_rows("dzhanibekov_box", "mini", "failed", 3.4)),
        *_cell_rows("dzhanibekov_box", "mujoco", "ok", 0.5),
    ]
    text = summary(rows)
    table = text[: text.index("engines:")]
    assert "*known 3.4" in table and "fail" not in table, table
    assert "1 known" in text and "failed" not in text, text


@pytest.mark.parametrize("status", ["unsupported", "error"])
def test_sweep_rows_do_not_colour_the_scene(status):
    rows = _cell_rows("projectile", "mini", "ok", 0.96)
    sweep = _row("projectile", "mini", "sweep_order.orientation_error", None, None, status)
    text = summary([*rows, sweep])
    table = text[: text.index("engines:")]
    assert "passed 0.96" in table and status[:5] not in table, table
    assert f"1 {status}" in text  # counted all the same, as the report's chips count it
    judged = summary([*rows, {**sweep, "metric": "orientation_error"}])
    table = judged[: judged.index("engines:")]
    assert ("error" in table) == (status == "error"), table  # unsupported ranks below passed


def test_every_line_of_the_summary_and_its_key_fits_100_columns():
    rows = bare_run_rows()
    text = summary(rows, width=100)
    assert max(len(line) for line in text.splitlines()) <= 100, max(text.splitlines(), key=len)
    assert "number = largest |error|/(tolerance+band)" in text


def test_colour_only_when_asked():
    rows = _cell_rows("projectile", "mini", "failed", 3.4)
    assert "\x1b[" not in summary(rows)
    assert "\x1b[" in summary(rows, color=True)


def test_progress_prints_a_line_per_job_when_stderr_is_not_a_terminal(capsys):
    jobs = ("bounce_ladder · mujoco", "projectile · mini", "box_stack · pybullet")
    with Progress(3) as progress:
        for label in jobs:
            progress.advance(label, "ok 0.8 s")
    assert progress.done == 3
    out, err = capsys.readouterr()
    lines = err.splitlines()
    assert out == "" and len(lines) == 3, err
    for done, (line, label) in enumerate(zip(lines, jobs, strict=True), start=1):
        assert line.startswith(f"{PROGRESS_PREFIX} {done}/3 0:00:0"), line
        assert line.endswith(f"{label} ok 0.8 s"), line


def test_progress_draws_on_a_terminal_in_any_finishing_order():
    screen = io.StringIO()
    console = Console(file=screen, force_terminal=True, width=100)
    with Progress(3, console=console) as progress:
        progress.advance("projectile · mini")
        progress.advance("bounce_ladder · mujoco")
        drawn = screen.getvalue()
        assert "2/3" in drawn and "bounce_ladder · mujoco" in drawn
        progress.advance("box_stack · pybullet")
    assert "3/3" in screen.getvalue()


def test_progress_on_an_injected_console_that_is_not_a_terminal_prints_lines():
    screen = io.StringIO()
    with Progress(2, console=Console(file=screen, force_terminal=False)) as progress:
        progress.advance("projectile · mini")
        progress.advance("box_stack · pybullet")
    lines = screen.getvalue().splitlines()
    assert [line.split()[1] for line in lines] == ["1/2", "2/2"], lines
    assert "\x1b[" not in screen.getvalue()  # no bar, no cursor codes in a log


def test_the_terminal_news_has_the_reports_sections_and_counts():
    """The same run gives the same words and counts in the terminal and in report.html's news
    (both from ``report.news.news_selections``), regressions and new failures named."""
    import pandas as pd

    from validation.jobs.terminal import news
    from validation.report.news import NEWS_WORDS, build_news

    rows = [
        {**_row("a", "mini", "energy_drift", 2e-3, 1e-3, "failed"), "baseline": "regressed"},
        {**_row("b", "mini", "energy_drift", 2e-3, 1e-3, "failed"), "baseline": "new"},
        {**_row("c", "mini", "energy_drift", 1e-4, 1e-3, "ok"), "baseline": "unchanged"},
        {**_row("d", "mini", "sweep_order.x", None, None, "ok"), "baseline": "changed"},
    ]
    rows = [{**row, "outcome": outcome_of(row)} for row in rows]
    comparison = pd.DataFrame(
        [
            *(
                {
                    "scenario": r["scenario"],
                    "engine": r["engine"],
                    "metric": r["metric"],
                    "baseline": r["baseline"],
                    "error": r["error"],
                    "baseline_error": 1e-4,
                }
                for r in rows
            ),
            {
                "scenario": "a",
                "engine": "mini",
                "metric": "gone",
                "baseline": "missing",
                "error": math.nan,
                "baseline_error": 1.0,
            },
        ]
    )
    text = news(rows, comparison, "base.csv")
    page = build_news(pd.DataFrame(rows), comparison, {})
    for section in page["sections"]:
        assert f"{section['count']} {NEWS_WORDS[section['key']]}" in text, (section, text)
    assert "1 regressed" in text and "1 new failures" in text and "1 changed" in text, text
    assert "  regressed: a · mini · energy_drift (error 0.002)" in text, text
    assert "  new failure: b · mini · energy_drift" in text, text
    assert "  changed: d · mini · sweep_order.x" in text, text
    assert max(len(line) for line in text.splitlines()) <= 100


FOURTEEN_SPECS = [
    *BARE_RUN_SPECS,
    "rapier",
    "rapier(solver_iterations=16)",
    "drake",
    "drake(time_step=0.0001,discrete_contact_approximation=similar)",
]
"""14 engine specs, as the issue's CI log: the long spellings a nightly runs."""

LONG_SCENES = [
    *BARE_RUN_SCENES,
    "a_user_scene_whose_name_is_longer_than_any_column_can_hold_in_a_ci_log_line_of_100",
]

DECLARED = re.compile(r"lines <= (\d+) columns")


def fourteen_engine_rows() -> list[dict]:
    return bare_run_rows(LONG_SCENES, FOURTEEN_SPECS)


def test_ci_log_matrix_with_14_engines_never_exceeds_its_declared_width():
    rows = fourteen_engine_rows()
    lines = compact_matrix(rows, width=100)
    declared = int(DECLARED.search(lines[0]).group(1))
    assert declared == max(100, len(LONG_SCENES[-1])), lines[0]
    for line in lines:
        assert len(line) <= declared, line
    legend = _legend("\n".join(lines))
    assert sorted(legend.values()) == sorted(FOURTEEN_SPECS)
    for scene in LONG_SCENES:  # full names, never cut
        assert scene in lines, scene
    text = log_summary(rows, width=100)
    matrix_end = text.index(LONG_SCENES[-1])
    for line in text[:matrix_end].splitlines()[1:]:
        if " | " not in line:  # the failing rows are one line each, never cut
            assert len(line) <= declared, line


def test_ci_log_names_every_failing_row_on_one_line_with_value_expected_tolerance():
    rows = fourteen_engine_rows()
    failing = [row for row in rows if outcome_of(row) in ("failed", "unstable", "error")]
    failing += [r for r in rows if outcome_of(r) in ("model_mismatch", "crashed", "timed_out")]
    lines = row_lines(rows)
    assert len(lines) == len(failing) > 0
    scene, engine, metric = failing[0]["scenario"], failing[0]["engine"], failing[0]["metric"]
    line = next(entry for entry in lines if f"{scene} | {engine} | {metric} |" in entry)
    assert "value " in line and "expected " in line and "tolerance " in line


CELL_TOKENS = {
    *(outcome_label(o) for o in ("passed", "failed", "unstable", "error", "unsupported")),
    "model_mismatch",
    "pass",
    "fail",
    "unst.",
    "mism.",
    "unsup",
    "-",
    *COMPACT_WORDS.values(),
}
RATIO_TOKEN = re.compile(r"^(\d+(\.\d+)?(e-?\d+)?|inf)$")


@pytest.mark.parametrize("width", [100, 120, 200])
def test_terminal_matrix_with_14_engines_never_wraps_a_word(width):
    """Before: at 100 columns the engine columns were folded: "passed" read "passe" / "d"."""
    lines = summary(fourteen_engine_rows(), width=width).splitlines()
    scene_lines = 0
    for line in lines:
        assert len(line) <= width, line
        head, *tokens = line.split() or [""]
        if head.rstrip("…") and any(s.startswith(head.rstrip("…")) for s in LONG_SCENES):
            scene_lines += 1
        elif not line.startswith(" ") or "=" in line:
            continue  # the header, the legend, the key and the counts
        else:
            tokens = line.split()  # a cell's second line: its ratios
        for token in tokens:
            assert token.lstrip("*") in CELL_TOKENS or RATIO_TOKEN.match(token), (token, line)
    assert scene_lines == len(LONG_SCENES), lines


def test_headline_with_known_rows_never_says_all_passed():
    """Before: report.html said "All N runs passed" with 52 known failures."""
    rows = [
        *_known(_cell_rows("dzhanibekov_box", "mini", "failed", 3.4)),
        *_cell_rows("dzhanibekov_box", "mujoco", "ok", 0.5),
    ]
    lines = counts_lines(rows)
    assert not lines[0].startswith("All"), lines
    assert "1 of 6 rows are known failures" in lines[0] and "1 known" in lines[1], lines
    assert "0 new failures" in lines[1], lines
    passing = counts_lines(_cell_rows("projectile", "mini", "ok", 0.5))
    assert passing[0].startswith("All 3 rows passed"), passing


def test_a_regressions_line_shows_the_baseline_error_before_the_new_one():
    rows = _cell_rows("spin", "mini", "ok", 0.9)
    rows[0]["baseline"] = "regressed"
    for row in rows[1:]:
        row["baseline"] = "unchanged"
    comparison = pd.DataFrame(
        [
            {
                "scenario": "spin",
                "engine": "mini",
                "metric": row["metric"],
                "baseline": row["baseline"],
                "baseline_error": 1.25e-4 if row is rows[0] else row["error"],
                "error": row["error"],
            }
            for row in rows
        ]
    )
    (line,) = row_lines(rows, comparison)
    assert line.startswith("regressed: spin | mini | energy_drift"), line
    assert "error 0.0009" in line and "baseline error 0.000125" in line, line


def test_news_never_cuts_a_row_at_its_error():
    """Before: "new failure: ... velocity_after_impact.light_e05 (error 0…" cut at 100 columns."""
    rows = _cell_rows("head_on_ratio_10", "mujoco(integrator=RK4)", "failed", 909.1)
    rows[0]["metric"] = "velocity_after_impact.light_e05_of_a_long_named_body"
    text = news(rows, width=80)
    assert "…" not in text, text
    assert "(error 0.909)" in text, text
    for line in text.splitlines():
        assert len(line) <= 80 or "(error" not in line, line
