"""The scene's own expectations measure what they say, in any body frame (issue-10 findings 5, 6)."""

from __future__ import annotations

import math

import numpy as np
import pytest

from validation.cli import BUNDLED_SCENARIOS
from validation.jobs.run import run_job
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
    """The result rows of one engine run of ``scenario`` as ``physval run`` makes them (with
    its sampling of the trajectory), by metric."""
    scene = compile_scene(scenario)
    run, measured = run_job((scene, parse_engine_spec(engine)))
    return {row["metric"]: row for row in compare_scene(scene, [run], [measured])}


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


DROP_HEIGHT, RESTITUTION, RADIUS = 1.0, 0.5, 0.1
"""m, -, m: a ball dropped onto the ground."""

REBOUND = RESTITUTION * math.sqrt(2 * 9.81 * (DROP_HEIGHT - RADIUS))
"""m/s, the rebound of the continuous-time impact (v = sqrt(2 g h), times e)."""


def drop(duration: float) -> Scenario:
    return Scenario.model_validate(
        {
            "name": "drop",
            "dt": 1e-3,
            "duration": duration,
            "ground": {"restitution": RESTITUTION},
            "engines": ["mini"],
            "bodies": [
                {
                    "name": "ball",
                    "shape": {"type": "sphere", "radius": RADIUS},
                    "mass": 1.0,
                    "position": [0, 0, DROP_HEIGHT],
                    "restitution": RESTITUTION,
                }
            ],
            "expect": [
                {"kind": "velocity_after_impact", "body": "ball", "value": [0, 0, REBOUND]},
                {"kind": "bounce_heights", "body": "ball", "value": [0.325]},
                {"kind": "position_at", "body": "ball", "time": 0.3, "value": [0, 0, 0.5586]},
            ],
        }
    )


SHORT_RUN_S, LONG_RUN_S = 2.9, 6.0
"""s: 2 900 steps are all kept as samples; 6 000 are more than ``MAX_SAMPLES``, so the long
run's trajectory keeps every second state."""


def test_expectations_do_not_depend_on_the_run_length():
    """The first bounce of one drop, measured in a 2.9 s and a 6 s run: the same numbers
    (issue-10 finding 4: the sampled long run read the rebound g·dt off)."""
    short = measure_rows(drop(SHORT_RUN_S), "mini")
    long = measure_rows(drop(LONG_RUN_S), "mini")
    for metric in ("velocity_after_impact.ball", "bounce_heights.ball", "position_at.ball"):
        assert short[metric]["value"] == long[metric]["value"], (
            metric,
            short[metric],
            long[metric],
        )
        assert short[metric]["error"] == long[metric]["error"], (
            metric,
            short[metric],
            long[metric],
        )


SOFT_CONTACT = "mujoco(restitution=soft)"
"""MuJoCo's own soft contact: the impact lasts several steps (critically damped spring)."""

FREE_FLIGHT_TOLERANCE = 1e-9
"""m/s. After the contact has ended the ball is in free flight: its velocity at the first
state apart, carried back to the impulse centroid with g, is the reading (round-off only)."""


def test_velocity_after_a_soft_impact_is_read_once_the_contact_has_ended():
    """Issue-10 finding 3: with a soft contact the impulse centroid falls mid-contact, where
    the ball still moves down (-0.22 m/s); the reading must be the ball leaving, carried back."""
    scenario = drop(1.0)
    scene = compile_scene(scenario)
    run, measured = run_job((scene, parse_engine_spec(SOFT_CONTACT)))
    event = next(e for e in run.recording.impacts if "ball" in (e.body_a, e.body_b))
    assert event.time_end - event.time_start > 3 * scenario.dt, "the contact should last steps"
    rows = {m.metric: m for m in measured}
    # the run keeps positions only (``recording.KEEP``): the velocities from a run keeping states
    trajectory = run_engine(scene, parse_engine_spec(SOFT_CONTACT)).recording.trajectory
    apart = int(np.flatnonzero(trajectory.t >= event.time_end - 1e-12)[0])
    leaving = trajectory.vel[apart, 0, 2] + 9.81 * (event.time_end - event.time_impulse)
    row = rows["velocity_after_impact.ball"]
    assert leaving > 0.0, f"the ball leaves at {leaving} m/s"
    assert abs(row.value - leaving) <= FREE_FLIGHT_TOLERANCE, (row.value, leaving, row.message)
    # the error is the distance to the target straight up: |leaving - e v|, not leaving + e v
    assert abs(row.error - abs(REBOUND - leaving)) <= FREE_FLIGHT_TOLERANCE, (row, leaving)
