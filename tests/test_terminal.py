"""Terminal output (validation.jobs.terminal): the summary fits its width and says what the rows
say; the progress bar is silent off a terminal and draws on one."""

from __future__ import annotations

import io
import math
import re

import pytest
from rich.console import Console

from validation.contract import RESULTS_COLUMNS
from validation.jobs.terminal import PROGRESS_PREFIX, SCENE_MAX_WIDTH, Progress, summary
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


def bare_run_rows() -> list[dict]:
    rows = []
    for i, scene in enumerate(BARE_RUN_SCENES):
        for j, engine in enumerate(BARE_RUN_SPECS):
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
