"""The noise rule (``validation.measure.noise.classify_change``): one table of cases, and the
baseline, ``compare`` and the history's step detection reading every case alike."""

from __future__ import annotations

import math

import numpy as np
import pandas as pd
import pytest

from validation.contract import BASELINE_CLASSES
from validation.measure import noise
from validation.measure.noise import (
    ABSOLUTE_NOISE,
    NOISE_FLOORS,
    RELATIVE_NOISE,
    Reading,
    attribute_divergence,
    classify_change,
)
from validation.nightly import compare
from validation.nightly.baseline import (
    VERDICT_RANK,
    baseline_table,
    classify,
    exit_failed,
    read_baseline,
)
from validation.nightly.steps import detect_steps
from validation.report.news import build_news

INF, NAN = math.inf, math.nan
SCENE = "drop"
"""A regular scene (not in ``NOISE_FLOORS``)."""


def passed(error: float = NAN, value: float = NAN, signed=None, verdict: str = "passed"):
    return Reading(
        error=error,
        value=value,
        signed=None if signed is None else np.atleast_1d(np.asarray(signed, dtype=float)),
        rank=VERDICT_RANK[verdict],
        verdict=verdict,
    )


GROWN = 1e-3 * (1 + 3 * RELATIVE_NOISE)
WITHIN = 1e-3 * (1 + 0.3 * RELATIVE_NOISE)

CASES = [
    # (what, before, now, class)
    ("verdict worse", passed(1e-3), passed(1e-3, verdict="failed"), "regressed"),
    ("verdict better", passed(1e-3, verdict="failed"), passed(1e-3), "improved"),
    ("verdict worse, error smaller", passed(1e-3), passed(1e-4, verdict="unstable"), "regressed"),
    ("same rank, other verdict", passed(verdict="error"), passed(verdict="unstable"), "changed"),
    ("finite grew", passed(1e-3), passed(GROWN), "regressed"),
    ("finite shrank", passed(GROWN), passed(1e-3), "improved"),
    ("finite within the floor", passed(1e-3), passed(WITHIN), "unchanged"),
    ("identical", passed(1e-3), passed(1e-3), "unchanged"),
    ("19x far inside a tolerance", passed(1.4e-7), passed(2.6e-6), "regressed"),
    ("0 to below the absolute floor", passed(0.0), passed(0.5 * ABSOLUTE_NOISE), "unchanged"),
    ("0 to above the absolute floor", passed(0.0), passed(3 * ABSOLUTE_NOISE), "regressed"),
    ("finite -> inf", passed(1e-3), passed(INF), "regressed"),
    ("inf -> finite", passed(INF), passed(1e-3), "improved"),
    ("inf -> inf", passed(INF), passed(INF), "unchanged"),
    ("error lost (number -> NaN)", passed(1e-3), passed(NAN, value=1.0), "regressed"),
    ("inf -> NaN", passed(INF), passed(NAN), "regressed"),
    ("error appeared (NaN -> number)", passed(NAN, value=1.0), passed(1e-3), "changed"),
    ("NaN -> inf", passed(NAN), passed(INF), "changed"),
    ("value only: order 0.98 -> 0", passed(value=0.98), passed(value=0.0), "changed"),
    ("value only: order 0.98 -> 1.02", passed(value=0.98), passed(value=1.02), "changed"),
    ("value only: same", passed(value=0.98), passed(value=0.98), "unchanged"),
    (
        "value only: within the floor",
        passed(value=0.98),
        passed(value=0.98 * (1 + 0.3 * RELATIVE_NOISE)),
        "unchanged",
    ),
    ("value only: number -> NaN", passed(value=0.98), passed(value=NAN), "changed"),
    ("value only: NaN -> number", passed(value=NAN), passed(value=0.98), "changed"),
    ("value only: NaN -> NaN", passed(), passed(), "unchanged"),
    ("value only: finite -> inf", passed(value=2.0), passed(value=INF), "changed"),
    ("value only: inf -> inf", passed(value=INF), passed(value=INF), "unchanged"),
    ("value only: -inf -> inf", passed(value=-INF), passed(value=INF), "changed"),
    (
        "signed scalar flipped",
        passed(1.9e-3, signed=-1.9e-3),
        passed(1.9e-3, signed=1.9e-3),
        "regressed",
    ),
    (
        "signed scalar held",
        passed(1.9e-3, signed=-1.9e-3),
        passed(1.9e-3, signed=-1.9e-3),
        "unchanged",
    ),
    (
        "signed vector turned",
        passed(5e-3, signed=[0, 0, -5e-3]),
        passed(5e-3, signed=[0, 5e-3, 0]),
        "regressed",
    ),
    (
        "signed vs unsigned baseline",
        passed(5e-3),
        passed(5e-3, signed=[0, 0, 5e-3]),
        "unchanged",
    ),
    ("signed and inf", passed(INF, signed=INF), passed(INF, signed=-INF), "unchanged"),
]
"""Every combination of finite / inf / NaN errors and values, verdicts and signs."""


@pytest.mark.parametrize(("what", "before", "now", "expected"), CASES, ids=[c[0] for c in CASES])
def test_classify_change(what, before, now, expected):
    found = classify_change(before, now, noise.floor_for(SCENE, "energy_drift"))
    assert found == expected, f"{what}: {before} -> {now} read {found}, expected {expected}"


def test_the_table_covers_every_class_of_the_rule():
    assert {c[3] for c in CASES} == {"regressed", "improved", "changed", "unchanged"}


def test_a_19x_move_far_inside_tolerance_regresses_against_a_baseline():
    """Halving the solver iterations moved a drift 1.4e-7 -> 2.6e-6 under a tolerance of 0.15
    (the old rule's floor: 1e-3 of it, 1.5e-4): a move, whatever the tolerance."""
    rows = [results_row("mini", "energy_drift", 1.4e-7, 0.15)]
    before = baseline_table(pd.DataFrame(rows), {SCENE: "abc"})
    now = results_row("mini", "energy_drift", 2.6e-6, 0.15)
    (classified,), _ = classify([now], before, {SCENE: "abc"})
    assert classified["baseline"] == "regressed", classified
    assert exit_failed([classified])


def test_measured_floors_are_looser_only_where_they_were_measured():
    """A move within a chaotic scene's measured floor is noise there and news in a regular
    scene; a row's own floor (an unstable balance) leaves the rest of its scene regular."""
    stack = noise.floor_for("box_stack", "energy_drift")
    assert stack.relative == noise.CHAOTIC_RELATIVE > RELATIVE_NOISE
    before, within, beyond = passed(1e-4), passed(2e-4), passed(11e-4)  # 2x, then 11x
    assert classify_change(before, within, stack) == "unchanged"
    assert classify_change(before, within, noise.floor_for(SCENE, "energy_drift")) == "regressed"
    assert classify_change(before, beyond, stack) == "regressed", "a tenfold move is news"
    balance = noise.floor_for("millimetre_spheres", "position_at.upper")
    assert classify_change(passed(1.9e-10), passed(1.3e-6), balance) == "unchanged"
    assert noise.floor_for("millimetre_spheres", "penetration_max") is noise.REGULAR
    for key, floor in NOISE_FLOORS.items():
        assert floor.why and (floor.relative > RELATIVE_NOISE or floor.absolute > ABSOLUTE_NOISE)
        scene, _, metric = key.partition("/")
        assert noise.floor_for(scene, metric or "any_metric") is floor, key


# --- the same rule in the baseline, compare and the history -------------------------------


def results_row(engine, metric, error, tolerance=None, value=None, scenario=SCENE, **extra):
    no_error = isinstance(error, float) and math.isnan(error)
    ok = None if tolerance is None or no_error else bool(error <= tolerance)
    return {
        "scenario": scenario,
        "engine": engine,
        "metric": metric,
        "value": (1.0 + error if not no_error else NAN) if value is None else value,
        "expected": NAN if no_error else 1.0,
        "expected_kind": "" if no_error else "analytic",
        "error": error,
        "tolerance": tolerance,
        "passed": ok,
        "status": "ok" if ok is not False else "failed",
        "engine_version": "1.0",
        **extra,
    }


def _row_of(reading: Reading, metric: str) -> dict:
    failing = reading.verdict in ("failed",)
    row = results_row("mini", metric, reading.error, 1.0, value=reading.value)
    row.update(
        passed=None if reading.verdict == "no_tolerance" else not failing,
        status=reading.verdict if reading.verdict in ("error", "unstable") else row["status"],
        outcome=reading.verdict,
    )
    if row["status"] in ("error", "unstable"):
        row["passed"] = None
    if reading.signed is not None:
        columns = (
            ["signed_error"] if reading.signed.size == 1 else ["error_x", "error_y", "error_z"]
        )
        row.update(dict(zip(columns, reading.signed.tolist(), strict=True)))
    return row


def test_baseline_and_compare_read_every_case_as_the_rule_does(tmp_path):
    """Each case of the table as rows of a baseline and of two run folders: the baseline's
    class and compare's change are the rule's class (compare keeps no signed error: it reads
    those cases on their size)."""
    befores = [_row_of(before, f"case{i}") for i, (_, before, _, _) in enumerate(CASES)]
    befores = [{**r, "outcome": r["outcome"]} for r in befores]
    nows = [_row_of(now, f"case{i}") for i, (_, _, now, _) in enumerate(CASES)]
    path = tmp_path / "baseline.csv"
    baseline_table(pd.DataFrame(befores), {SCENE: "abc"}).to_csv(path, index=False)
    classified, missing = classify(nows, read_baseline(path), {SCENE: "abc"})
    assert not missing
    found = {r["metric"]: r["baseline"] for r in classified}
    a = compare._side("a", None, "", {}, pd.DataFrame(befores))
    b = compare._side("b", None, "", {}, pd.DataFrame(nows))
    moved = compare.compare_runs(a, b)
    changes = dict(zip(moved["metric"], moved["change"], strict=True))
    for i, (what, before, now, expected) in enumerate(CASES):
        assert found[f"case{i}"] == expected, (what, found[f"case{i}"])
        unsigned = Reading(before.error, before.value, None, before.rank, before.verdict)
        unsigned_now = Reading(now.error, now.value, None, now.rank, now.verdict)
        expected_compare = classify_change(unsigned, unsigned_now)
        assert changes.get(f"case{i}", "unchanged") == expected_compare, what


def test_the_history_finds_a_step_where_the_rule_sees_a_move():
    """Step detection merges levels by the same rule: the 19x move of a bit-identical series
    is a step, a change within the floor is none, finite -> inf is a step, and so is a fitted
    order's fall (a value series)."""
    series = {
        "19x": (np.array([1.4e-7] * 10 + [2.6e-6] * 10), [(10, 1)]),
        "within the floor": (np.array([1e-3] * 10 + [WITHIN] * 10), []),
        "just beyond the floor": (np.array([1e-3] * 10 + [GROWN] * 10), [(10, 1)]),
        "finite -> inf": (np.array([1e-3] * 10 + [INF] * 10), [(10, 1)]),
        "order 0.98 -> 0": (np.array([0.98] * 10 + [0.0] * 10), [(10, -1)]),
    }
    steps = detect_steps(np.vstack([values for values, _ in series.values()]))
    assert len(steps) == len(series)
    for (what, (values, expected)), found in zip(series.items(), steps, strict=True):
        assert [(s.at, s.direction) for s in found] == expected, (what, found)
        rule = classify_change(Reading(error=values[0]), Reading(error=values[-1]))
        assert (rule != "unchanged") == bool(found), (what, rule)


# --- divergence rows ----------------------------------------------------------------------


def divergence_row(engine, change, reference="mini", scene=SCENE):
    kind = f"engine:{reference}" if reference else ""
    return {"scenario": scene, "engine": engine, "metric": "divergence", "expected_kind": kind,
            "change": change}  # fmt: skip


def own_row(engine, change, scene=SCENE, version_moved=False):
    return {"scenario": scene, "engine": engine, "metric": "energy_drift", "change": change,
            "version_moved": version_moved}  # fmt: skip


DIVERGENCE_CASES = [
    # (what, rows, classes)
    (
        "only the reference moved",
        [own_row("mini", "regressed"), own_row("mujoco", "unchanged"),
         divergence_row("mujoco", "regressed")],
        ["regressed", "unchanged", "reference_moved"],
    ),
    (
        "the reference's version changed, its rows did not move",
        [own_row("mini", "unchanged", version_moved=True), divergence_row("mujoco", "improved")],
        ["unchanged", "reference_moved"],
    ),
    (
        "the measured engine moved too: its own",
        [own_row("mini", "regressed"), own_row("mujoco", "regressed"),
         divergence_row("mujoco", "regressed")],
        ["regressed", "regressed", "regressed"],
    ),
    (
        "only the measured engine moved",
        [own_row("mini", "unchanged"), own_row("pybullet", "improved"),
         divergence_row("pybullet", "regressed")],
        ["unchanged", "improved", "regressed"],
    ),
    (
        "nothing else moved",
        [own_row("mini", "unchanged"), divergence_row("mujoco", "changed")],
        ["unchanged", "changed"],
    ),
    (
        "the reference moved in another scene only",
        [own_row("mini", "regressed", scene="other"), own_row("mini", "unchanged"),
         divergence_row("mujoco", "regressed")],
        ["regressed", "unchanged", "regressed"],
    ),
    (
        "no expected_kind: the one engine without a divergence row is the reference",
        [own_row("mini", "regressed"), divergence_row("mujoco", "regressed", reference=""),
         divergence_row("pybullet", "unchanged", reference="")],
        ["regressed", "reference_moved", "unchanged"],
    ),
]  # fmt: skip


@pytest.mark.parametrize(
    ("what", "rows", "expected"), DIVERGENCE_CASES, ids=[c[0] for c in DIVERGENCE_CASES]
)
def test_divergence_is_charged_to_the_engine_that_moved(what, rows, expected):
    assert attribute_divergence(rows, "change") == expected, what


def test_a_baseline_charges_divergence_to_the_reference_and_covers_every_class():
    """mini (the reference) got worse, MuJoCo did not: MuJoCo's divergence row reads
    reference_moved, which does not fail the run; the other classes on the way."""
    before_rows = [
        results_row("mini", "energy_drift", 1e-3, 0.01),
        results_row("mujoco", "energy_drift", 2e-3, 0.01),
        results_row("mujoco", "divergence", 1e-4, expected_kind="engine:mini"),
        results_row("mini", "sweep_order.position", NAN, value=0.98),
        results_row("mini", "velocity_error", 1e-3, 0.01),
        results_row("mini", "gone", 1e-3, 0.01),
        results_row("pybullet", "energy_drift", 1e-3, 0.01, scenario="spin"),
    ]
    before = baseline_table(pd.DataFrame(before_rows), {SCENE: "abc", "spin": "old"})
    now = [
        results_row("mini", "energy_drift", 5e-3, 0.01),  # regressed
        results_row("mujoco", "energy_drift", 2e-3, 0.01),  # unchanged
        results_row("mujoco", "divergence", 4e-3, expected_kind="engine:mini"),  # mini's move
        results_row("mini", "sweep_order.position", NAN, value=0.0),  # changed
        results_row("mini", "velocity_error", 1e-4, 0.01),  # improved, 10x
        results_row("mini", "arrived", 1e-3, 0.01),  # new
        results_row("pybullet", "energy_drift", 1e-3, 0.01, scenario="spin"),  # scene changed
    ]
    classified, missing = classify(now, before, {SCENE: "abc", "spin": "new"})
    found = [r["baseline"] for r in classified + missing]
    assert found == [
        "regressed",
        "unchanged",
        "reference_moved",
        "changed",
        "improved",
        "new",
        "scene_changed",
        "missing",
    ], found
    assert set(found) == set(BASELINE_CLASSES)
    assert not exit_failed([classified[2]]), "reference_moved does not fail the run"
    assert exit_failed([classified[3]]), "changed fails the run like a regression"


def test_a_version_that_reads_as_a_number_is_no_move(tmp_path):
    """An engine version such as 3.10 stays text when a baseline is read back: it did not
    move, so a divergence against that engine is not charged to it."""
    rows = [
        {**results_row("mini", "energy_drift", 1e-3, 0.01), "engine_version": "3.10"},
        {**results_row("mujoco", "divergence", 1e-4), "expected_kind": "engine:mini"},
    ]
    path = tmp_path / "baseline.csv"
    baseline_table(pd.DataFrame(rows), {SCENE: "abc"}).to_csv(path, index=False)
    now = [dict(rows[0]), {**rows[1], "value": 4e-3, "error": 4e-3}]
    classified, _ = classify(now, read_baseline(path), {SCENE: "abc"})
    assert [r["baseline"] for r in classified] == ["unchanged", "regressed"], classified


def test_compare_charges_divergence_to_the_reference():
    before = [
        results_row("mini", "energy_drift", 1e-3, 0.01),
        results_row("mujoco", "divergence", 1e-4),
    ]
    after = [
        results_row("mini", "energy_drift", 5e-3, 0.01),
        results_row("mujoco", "divergence", 4e-3),
    ]
    a = compare._side("a", None, "", {}, pd.DataFrame(before))
    b = compare._side("b", None, "", {}, pd.DataFrame(after))
    moved = compare.compare_runs(a, b)
    assert dict(zip(moved["engine"], moved["change"], strict=True)) == {
        "mini": "regressed",
        "mujoco": "reference_moved",
    }


# --- the news -----------------------------------------------------------------------------


def test_a_large_improvement_is_news():
    table = pd.DataFrame(
        [
            {**results_row("mini", m, e, 0.01), "outcome": "passed", "baseline": "improved"}
            for m, e in (("halved", 5e-4), ("a_little", 9e-4), ("now_finite", 1e-3))
        ]
    )
    baseline = table[["scenario", "engine", "metric", "baseline", "outcome", "error"]].assign(
        baseline_error=["1e-3", "1e-3", "inf"]  # baseline.csv is read as text
    )
    news = build_news(table, baseline, {})
    section = next(s for s in news["sections"] if s["key"] == "large_improvements")
    assert [r["metric"] for r in section["rows"]] == ["halved", "now_finite"], section
    assert section["open"]
    assert noise.large_improvement(1e-3, 1e-3 / noise.LARGE_IMPROVEMENT)
    assert not noise.large_improvement(1e-3, 0.6e-3)
