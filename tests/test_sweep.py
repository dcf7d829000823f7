"""physval sweep: convergence order, failed points kept, timing of the stepping alone."""

from __future__ import annotations

import math

import pandas as pd
import pytest

from validation.cli import BUNDLED_SCENARIOS, main
from validation.jobs.plan import plan_run
from validation.jobs.sweep import GridError, parse_dt_grid, run_sweep
from validation.scenario import Scenario, load_scenario
from validation.scenario.engine_spec import parse_engine_spec

CROSS_CHECK_TOLERANCE = 1e-6
"""MuJoCo RK4 at dt/10 against DOP853 on a 10 rad/s spring: RK4's error (ω dt)^4 · ω t per
unit amplitude is about 1e-10 m here; 1e-6 says the two references agree."""

ORDER_TOLERANCE = 0.05
"""Semi-implicit Euler's position error on a parabola is exactly g·dt·t/2, first order: the
fitted slope is 1 to round-off (measured 0.99997); 0.05 leaves room for the sampling."""


def test_semi_implicit_euler_converges_at_first_order_on_the_projectile():
    scenario = load_scenario(BUNDLED_SCENARIOS / "formulas" / "projectile.yaml")
    rows = run_sweep(
        [(scenario, parse_engine_spec("mini"), parse_dt_grid("4e-3:2.5e-4:4"))], workers=1
    )
    order = next(
        r["value"]
        for r in rows
        if r["metric"] == "convergence_order" and r.get("of") == "position_error"
    )
    assert abs(order - 1.0) < ORDER_TOLERANCE, f"fitted order {order:.4f}"
    assert all(r["expected_kind"] == "dop853" for r in rows)


def test_an_exploding_point_is_kept_as_unstable_in_the_csv_and_the_plot(tmp_path):
    out = tmp_path / "sweep"
    path = BUNDLED_SCENARIOS / "stiff" / "stiff_spring_oscillator.yaml"
    code = main(
        [
            "sweep",
            str(path),
            "--engines",
            "mini",
            "--dt",
            "4e-3,1e-3,5e-4",
            "--out",
            str(out),
            "--jobs",
            "1",
        ]
    )
    assert code == 0
    table = pd.read_csv(out / "sweep.csv")
    points = table[table["metric"] == "position_error"].set_index("dt")
    assert points.loc[4e-3, "status"] == "unstable", points  # ω·dt = 4 > 2
    assert (points.loc[[1e-3, 5e-4], "status"] == "ok").all(), points
    page = (out / "sweep.html").read_text()
    assert "unstable" in page and "<svg" in page
    assert "#c0392b" in page, "the failed point's red cross is missing from the chart"


TIMING_REPEATS = 5
"""Interleaved repeats of each timing; the minimum is kept (the least disturbed run)."""


def test_stepping_time_excludes_recording(monkeypatch):
    """The sweep's time of a point is the stepping alone: keeping 500 samples or 5 changes the
    recording work, not the time (compared with each other, never with a wall-clock bound)."""
    from validation.jobs import sweep

    scenario = Scenario.model_validate(
        {
            "name": "fly",
            "dt": 0.001,
            "duration": 1.0,
            "bodies": [
                {
                    "name": "b",
                    "shape": {"type": "box", "half_extents": [0.1, 0.2, 0.3]},
                    "mass": 1.0,
                    "angular_velocity": [1, 2, 3],
                }
            ],
        }
    )
    spec = parse_engine_spec("mini(gyroscopic=explicit)")
    reference = sweep.choose_reference(scenario, spec, 1e-3)
    times = {500: math.inf, 5: math.inf}
    for _ in range(TIMING_REPEATS):  # interleaved, so a change in the machine's load hits both
        for samples in times:
            monkeypatch.setattr(sweep, "SAMPLES", samples)
            point = sweep.sweep_point(scenario, spec, 1e-3, reference)[0]
            times[samples] = min(times[samples], point["wall_time_s"])
    ratio = times[500] / times[5]
    assert 0.5 < ratio < 2.0, (
        f"stepping time {times[500]:.4f} s (500 samples) vs {times[5]:.4f} s (5)"
    )


@pytest.mark.parametrize("text", ["abc", "1e-3:1e-4", "0,1e-3", "-1e-3", ""])
def test_bad_grids_are_rejected(text):
    with pytest.raises(GridError):
        parse_dt_grid(text)


def test_grid_forms():
    assert parse_dt_grid("1e-1:1e-3:3") == pytest.approx([1e-1, 1e-2, 1e-3])
    assert parse_dt_grid("1e-3, 5e-4") == [1e-3, 5e-4]


def test_scenes_without_a_closed_form_use_restarted_segments_or_rk4():
    """A bounce has no expectation here: self-consistency over restarted segments, whose error
    shrinks with dt; a spring chain without contact: MuJoCo RK4 as the reference."""
    bounce = Scenario.model_validate(
        {
            "name": "bounce",
            "dt": 0.002,
            "duration": 0.6,
            "ground": {"restitution": 0.5},
            "bodies": [
                {
                    "name": "b",
                    "shape": {"type": "sphere", "radius": 0.1},
                    "mass": 1.0,
                    "position": [0, 0, 0.5],
                    "velocity": [0.3, 0, 0],
                    "restitution": 0.5,
                }
            ],
        }
    )
    rows = run_sweep([(bounce, parse_engine_spec("mini"), [4e-3, 1e-3])], workers=1)
    points = [r for r in rows if r["metric"] == "position_error"]
    assert all(r["expected_kind"].startswith("self:mini@") for r in points), points
    assert points[0]["error"] > points[1]["error"] > 0, points

    spring = Scenario.model_validate(
        {
            "name": "chain",
            "dt": 0.001,
            "duration": 0.2,
            "gravity": [0, 0, 0],
            "bodies": [
                {
                    "name": "a",
                    "shape": {"type": "sphere", "radius": 0.01},
                    "mass": 1.0,
                    "position": [0.01, 0, 0],
                }
            ],
            "springs": [{"a": "a", "b": "world", "stiffness": 100.0, "rest_length": 0.0}],
        }
    )
    rows = run_sweep([(spring, parse_engine_spec("mini"), [4e-3, 2e-3, 1e-3])], workers=1)
    kinds = {r["expected_kind"] for r in rows}
    assert kinds == {"dop853"}, kinds
    order = next(
        r["value"]
        for r in rows
        if r["metric"] == "convergence_order" and r.get("of") == "position_error"
    )
    assert 0.8 < order < 2.2, f"fitted order {order}"
    check = [r for r in rows if r["metric"] == "reference_cross_check"]
    assert check and all(r["error"] < CROSS_CHECK_TOLERANCE for r in check), check


TUMBLE_ORDER_FIRST = (0.8, 1.2)
"""The explicit and implicit gyroscopic terms are first-order schemes: their fitted order of
the orientation error lies near 1 (a 20 % band for a four-point fit)."""

NO_GYROSCOPIC_ORDER = 0.3
"""The documented law (no gyroscopic term) converges to a different motion: ω stays fixed,
so its error does not shrink with dt (order near 0)."""

NO_GYROSCOPIC_EXCESS = 10.0
"""... and at the finest step its error is far above the corrected laws' (measured ~100x)."""


def test_the_orientation_error_shows_the_documented_law_does_not_converge_on_a_tumble():
    tumble = Scenario.model_validate(
        {
            "name": "tumble",
            "dt": 1e-3,
            "duration": 1.0,
            "gravity": [0, 0, 0],
            "bodies": [
                {
                    "name": "box",
                    "shape": {"type": "box", "half_extents": [0.3, 0.2, 0.1]},
                    "mass": 1.0,
                    "angular_velocity": [0.4, 0.3, 3.0],
                }
            ],
        }
    )
    grid = [4e-3, 2e-3, 1e-3, 5e-4]
    rows = run_sweep(
        [
            (tumble, parse_engine_spec(spec), grid)
            for spec in ("mini", "mini(gyroscopic=explicit)", "mini(gyroscopic=implicit)")
        ],
        workers=1,
    )

    def order(engine: str) -> float:
        return next(
            r["value"]
            for r in rows
            if r["engine"] == engine
            and r["metric"] == "convergence_order"
            and r.get("of") == "orientation_error"
        )

    def finest(engine: str) -> float:
        return next(
            r["error"]
            for r in rows
            if r["engine"] == engine and r["metric"] == "orientation_error" and r["dt"] == grid[-1]
        )

    for corrected in ("mini(gyroscopic=explicit)", "mini(gyroscopic=implicit)"):
        low, high = TUMBLE_ORDER_FIRST
        assert low < order(corrected) < high, (corrected, order(corrected))
    assert abs(order("mini")) < NO_GYROSCOPIC_ORDER, order("mini")
    assert finest("mini") > NO_GYROSCOPIC_EXCESS * finest("mini(gyroscopic=explicit)"), (
        finest("mini"),
        finest("mini(gyroscopic=explicit)"),
    )


FIRST_FLIP = """\
description: the Dzhanibekov box of scenarios/rotation, for its first flip only (2 s)
dt: 1.0e-3
duration: 2.0
gravity: [0.0, 0.0, 0.0]
engines: [mini, "mujoco(integrator=RK4)"]
bodies:
  - name: box
    shape: {type: box, half_extents: [0.3, 0.2, 0.1]}
    mass: 1.0
    angular_velocity: [0.05, 10.0, 0.05]
"""

RK4_ORDER_TOLERANCE = 0.05
"""MuJoCo RK4 on the flip, measured: 8.21e-7, 8.66e-9, 8.29e-11 rad at 1e-2, 3.2e-3, 1e-3 s
(fitted 3.996); 0.05 leaves room for the max-over-time sampling of the errors."""


def test_a_sweep_fits_rk4_above_its_floor_and_marks_the_points_left_out(tmp_path):
    """RK4 reaches round-off at 3.2e-4 s (8.7e-12 rad after 6,250 steps, whose round-off is
    2.8e-12): its order is fitted over the three larger steps; the documented law (mini, no
    gyroscopic term) never flips, 2.77 rad at every dt: saturated, no order. sweep.csv says so
    per point and per order; the page draws and names the markers."""
    scene = tmp_path / "first_flip.yaml"
    scene.write_text(FIRST_FLIP)
    out = tmp_path / "sweep"
    engines = "mini, mujoco(integrator=RK4)"
    argv = [
        "sweep",
        str(scene),
        "--engines",
        engines,
        "--dt",
        "1e-2,3.2e-3,1e-3,3.2e-4",
        "--jobs",
        "1",
    ]
    assert main([*argv, "--out", str(out)]) == 0
    table = pd.read_csv(out / "sweep.csv")
    orders = table[
        (table["metric"] == "convergence_order") & (table["of"] == "orientation_error")
    ].set_index("engine")
    rk4 = orders.loc["mujoco(integrator=RK4)"]
    assert abs(rk4["value"] - 4.0) < RK4_ORDER_TOLERANCE, f"fitted order {rk4['value']:.4f}"
    assert rk4["fit_points"] == 3, rk4
    assert (rk4["fit_dt_min"], rk4["fit_dt_max"]) == (pytest.approx(1e-3), pytest.approx(1e-2))
    assert math.isnan(orders.loc["mini", "value"]), orders.loc["mini"]
    assert orders.loc["mini", "message"].startswith("not in the asymptotic range"), orders
    points = table[table["metric"] == "orientation_error"].sort_values("dt", ascending=False)
    roles = points.groupby("engine")["fit_role"].agg(list)
    assert roles["mujoco(integrator=RK4)"] == ["fitted"] * 3 + ["floor"], points
    assert roles["mini"] == ["saturated"] * 4, points
    page = (out / "sweep.html").read_text()
    for legend in (
        "filled: in the order fit",
        "floor-bound: left out of the order fit",
        "saturated: left out of the order fit",
    ):
        assert f"{legend}</span>" in page, f"the legend lacks {legend!r}"  # a legend entry
    assert "fitted over 3 points, dt 0.001 to 0.01 s" in page, "the page lacks RK4's range"


# --- an error-controlled engine is swept over its accuracy -----------------------------------

ACCURACY_ORDER = 0.93
ACCURACY_ORDER_TOLERANCE = 0.1
"""Drake's continuous profile (RK3) on a 10 rad/s spring observed every 50 ms: the position
error follows the accuracy asked for, order 0.93 in it (measured over 1e-2 to 1e-6: 4.3e-3 to
7.7e-7 m); 0.1 leaves room for the error control's step choices. An accuracy that did not
reach the integrator would give order 0 (every point the same run)."""


def observed_spring() -> Scenario:
    return Scenario.model_validate(
        {
            "name": "observed_spring",
            "dt": 0.05,
            "duration": 2.0,
            "gravity": [0, 0, 0],
            "bodies": [
                {
                    "name": "bob",
                    "shape": {"type": "sphere", "radius": 0.1},
                    "mass": 1.0,
                    "position": [0.55, 0, 0],
                }
            ],
            "springs": [{"a": "bob", "b": "world", "stiffness": 100.0, "rest_length": 0.5}],
        }
    )


def test_an_error_controlled_spec_is_swept_over_its_accuracy_with_its_run_time():
    from validation.jobs.nightly_run import sweep_result_rows
    from validation.jobs.sweep import ACCURACY_GRID, sweep_scene

    rows = sweep_scene((observed_spring(), parse_engine_spec("drake(profile=continuous)"), [0.05]))
    points = [r for r in rows if r["metric"] == "position_error"]
    assert [r["accuracy"] for r in points] == list(ACCURACY_GRID), points
    assert {r["dt"] for r in points} == {0.05}, "an accuracy sweep keeps the scene's dt"
    assert all(r["wall_time_s"] > 0 for r in points), points
    errors = [r["error"] for r in points]
    assert errors == sorted(errors, reverse=True), errors
    (order,) = [
        r for r in rows if r["metric"] == "convergence_order" and r["of"] == "position_error"
    ]
    assert abs(order["value"] - ACCURACY_ORDER) <= ACCURACY_ORDER_TOLERANCE, order
    assert "accuracy 1e-06 to 0.01" in order["message"], order
    names = {r["metric"] for r in sweep_result_rows(rows)}
    assert "sweep_error.position_error@accuracy=0.0001" in names, sorted(names)
    assert not any("@dt=" in name for name in names), sorted(names)


def test_a_fixed_step_sweep_keeps_its_dt_rows():
    from validation.jobs.nightly_run import sweep_result_rows

    rows = [
        {
            "scenario": "s",
            "engine": "mini",
            "metric": "position_error",
            "dt": 1e-3,
            "value": 1.0,
            "error": 1.0,
        }
    ]
    assert [r["metric"] for r in sweep_result_rows(rows)] == ["sweep_error.position_error@dt=0.001"]


def test_a_run_in_chosen_engines_sweeps_those_engines_only():
    """``--engines`` replaces every scene's engine list, its ``sweep:`` list too: a run in
    MuJoCo does not step mini or PyBullet for the stiff spring's sweep."""
    scene = BUNDLED_SCENARIOS / "stiff" / "stiff_spring_oscillator.yaml"
    own = {spec.label for _, spec, _ in plan_run([scene], None, None, None).sweeps}
    assert own == {"mini", "mujoco", "mujoco(integrator=RK4)", "pybullet"}, own
    chosen = {spec.label for _, spec, _ in plan_run([scene], "mujoco", None, None).sweeps}
    assert chosen == {"mujoco"}, chosen
