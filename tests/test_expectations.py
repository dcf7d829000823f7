"""The scene's own expectations measure what they say, in any body frame (issue-10 findings 5, 6)."""

from __future__ import annotations

import pytest

from validation.cli import BUNDLED_SCENARIOS
from validation.measure.comparator import compare_scene
from validation.measure.runner import run_engine
from validation.scenario import Scenario, ScenarioError, load_scenario
from validation.scenario.compiled import compile_scene
from validation.scenario.engine_spec import parse_engine_spec

AXIAL, TRANSVERSE = 2.0, 1.0
"""kg·m²: a top symmetric about its body axis, 2 about it and 1 across it."""

SPIN, WOBBLE = 3.0, 0.1
"""rad/s about the symmetry axis, and across it (a small nutation)."""

PRECESSION = (AXIAL - TRANSVERSE) / TRANSVERSE * SPIN
"""rad/s, Euler's equations of a torque-free axisymmetric body: ω turns about the symmetry
axis in the body frame at (I3 - I1)/I1 · ω3 (Landau & Lifshitz §33)."""

RK4_RATE_TOLERANCE = 1e-6
"""rad/s. MuJoCo RK4 at dt = 1e-3 on a 3 rad/s precession: a per-step phase error of order
(λ dt)^5 = 2e-13 rad, 2e-9 rad over the run; the fitted rate is limited by round-off of the
unwrapped angle (measured 4e-12 rad/s)."""


def top(axis: int) -> Scenario:
    """The top with its symmetry axis along body axis ``axis`` (0, 1, 2 = x, y, z)."""
    moments = [TRANSVERSE] * 3
    moments[axis] = AXIAL
    omega = [0.0, 0.0, 0.0]
    omega[axis] = SPIN
    omega[(axis + 1) % 3] = WOBBLE
    return Scenario.model_validate(
        {
            "name": f"top_{'xyz'[axis]}",
            "dt": 1e-3,
            "duration": 2.0,
            "gravity": [0, 0, 0],
            "engines": ["mujoco(integrator=RK4)"],
            "bodies": [
                {
                    "name": "top",
                    "shape": {"type": "sphere", "radius": 0.1},
                    "mass": 1.0,
                    "inertia": moments,
                    "angular_velocity": omega,
                }
            ],
            "expect": [{"kind": "precession_rate", "body": "top", "value": PRECESSION}],
            "checks": {"precession_rate.top": RK4_RATE_TOLERANCE},
        }
    )


def measure_rows(scenario: Scenario, engine: str) -> dict[str, dict]:
    """The result rows of one engine run of ``scenario``, by metric."""
    scene = compile_scene(scenario)
    rows = compare_scene(scene, [run_engine(scene, parse_engine_spec(engine))])
    return {row["metric"]: row for row in rows}


@pytest.mark.parametrize("axis", [0, 1, 2], ids=["x", "y", "z"])
def test_precession_is_measured_about_the_symmetry_axis_whichever_it_is(axis):
    row = measure_rows(top(axis), "mujoco(integrator=RK4)")["precession_rate.top"]
    assert abs(row["value"] - PRECESSION) <= RK4_RATE_TOLERANCE, (row["value"], row["message"])
    assert row["passed"] is True, row


def test_precession_of_a_body_without_a_symmetry_axis_is_refused_at_load(tmp_path):
    file = tmp_path / "lopsided.yaml"
    file.write_text(
        "dt: 0.001\nduration: 1.0\nbodies:\n"
        "  - {name: top, shape: {type: box, half_extents: [0.3, 0.2, 0.1]}, mass: 1.0}\n"
        "expect:\n  - {kind: precession_rate, body: top, value: 1.0}\n"
    )
    with pytest.raises(ScenarioError) as error:
        load_scenario(file)
    assert "symmetry" in str(error.value) and ":6:" in str(error.value), str(error.value)


def test_rows_carry_the_measured_value_the_target_and_their_difference():
    """mini without the gyroscopic term cannot flip (formulas.md 4): the flips row reads
    value 0 (measured), expected 3 (target), error 3."""
    scenario = load_scenario(BUNDLED_SCENARIOS / "rotation" / "dzhanibekov_box.yaml")
    flips = measure_rows(scenario, "mini")["flips.box"]
    assert (flips["value"], flips["expected"], flips["error"]) == (0.0, 3.0, 3.0), flips
    rate = measure_rows(top(2), "mujoco(integrator=RK4)")["precession_rate.top"]
    assert rate["expected"] == PRECESSION, rate
    assert abs(rate["error"] - abs(rate["value"] - rate["expected"])) < 1e-15, rate
