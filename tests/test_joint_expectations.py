"""A joint's expectations, ``joint_position_at`` and ``period``, against closed forms in every
engine that runs joints, and the loader's refusals.

The closed forms: a compound pendulum released at θ0 = 2 rad (its period the complete
elliptic integral, T = 4 √(I_O/(m g d)) K(sin(θ0/2)); at T/2 it turns at -2 θ0 from the
release), a cart on a slider pulled by a spring (s(t) = -A (1 - cos ωt), T = 2π/ω), a sphere
spun about a ball joint at its centre (its rotation vector ω t) and a wheel turning freely on a
hinge through its centre past many turns (θ = ω t).
"""

from __future__ import annotations

import math

import pytest
from test_every_row_can_fail import write
from test_joint_scenes import AMPLITUDE, DT, PERIOD, PIVOT_INERTIA, compound_pendulum

from validation.measure.runner import run_engine
from validation.scenario import Scenario, check_scenario
from validation.scenario.compiled import compile_scene
from validation.scenario.engine_spec import parse_engine_spec

G = 9.81
BAR_HALF = 0.5

ENGINES = ("mini", "mujoco", "mujoco(integrator=RK4)")
"""Every engine that runs joints, and MuJoCo's fourth-order integrator."""


def measured(scenario: Scenario, engine: str, expect: list[dict]) -> dict:
    """The rows of ``expect`` on ``scenario`` in ``engine``, by metric."""
    stated = {**scenario.model_dump(), "engines": [engine], "expect": expect}
    run = run_engine(compile_scene(Scenario.model_validate(stated)), parse_engine_spec(engine))
    assert run.status == "ok", (engine, run.status, run.message)
    return {row.metric: row for row in run.recording.expectations}


def crossing_interpolation(stiffness: float, amplitude: float, top_rate: float, steps: int):
    """s, what linear interpolation inside the crossing steps can add to a period measured
    over a whole number of periods (to a step) of ``steps`` steps: the mean of its ``steps + 1``
    states is off the centre of the swing by δ <= 2 A / steps (the one state more than whole
    periods hold, and the part of a step the run ends off a period), where the acceleration is
    about ω² δ and the rate the swing's largest; a linear interpolation misplaces a crossing in
    time by up to |a| h² / 8 / |rate|, an interval by twice that."""
    offset = 2 * amplitude / steps
    return 2 * stiffness * offset * DT**2 / 8 / top_rate


# --- the compound pendulum: period and the far turning point --------------------------------

OMEGA0_SQUARED = G * BAR_HALF / PIVOT_INERTIA
"""1/s², m g d / I_O (14.7): the pendulum's largest stiffness (sin x / x <= 1)."""

PENDULUM_STEPS = round(3 * PERIOD / DT)
"""Three periods: three upward crossings (at 3T/4, 7T/4, 11T/4), two intervals."""

TOP_RATE = math.sqrt(2 * OMEGA0_SQUARED * (1 - math.cos(AMPLITUDE)))
"""rad/s at the bottom of the swing, from the energy: 6.45."""

PENDULUM_CROSSING = crossing_interpolation(OMEGA0_SQUARED, AMPLITUDE, TOP_RATE, PENDULUM_STEPS)
"""s, 3.5e-10."""

PERIOD_TOLERANCE = {
    "mujoco": PERIOD * OMEGA0_SQUARED * DT**2 / 24 + PENDULUM_CROSSING,
    "mujoco(integrator=RK4)": PERIOD * (math.sqrt(OMEGA0_SQUARED) * DT) ** 4 + PENDULUM_CROSSING,
    "mini": 5e-5,
}
"""s. MuJoCo's semi-implicit Euler is symplectic Euler: its period is longer by ω²h²/24 of
itself (cos ω_h h = 1 - ω²h²/2), at most T ω0² h²/24 = 1.3e-6 s (measured 5.6e-7); RK4 by
O((ω0 h)⁴) of T, 4.7e-10 s (measured 1.8e-10); each plus the crossings' interpolation. mini's
joint impulses with Baumgarte's correction are not symplectic Euler: measured 2.5e-5 s at
dt = 1 ms; 5e-5 s is 2x that and a twentieth of a step, far below the dt / 2 that a crossing
placed on an observed step rather than inside it can cost."""

TURNING_TOLERANCE = {
    "mujoco": AMPLITUDE * OMEGA0_SQUARED * DT**2,
    "mujoco(integrator=RK4)": 1e-9,
    "mini": AMPLITUDE * OMEGA0_SQUARED * DT**2,
}
"""rad at T/2, the far turning point -2 θ0. Symplectic Euler's discrete oscillation is off the
exact one by a term in phase with the rate, O(ω h) of the amplitude (the slider's
SLIDER_TOLERANCE), which vanishes where the rate does: what is left at a turning point is
O((ω0 h)²) of θ0, 2.9e-5 rad (measured: MuJoCo 1.9e-9, mini 2.4e-5); RK4's O(h⁴) (measured
1.9e-12)."""


@pytest.mark.parametrize("engine", ENGINES)
def test_a_compound_pendulums_period_and_turning_point_are_the_elliptic_ones(engine):
    scenario = compound_pendulum([engine], duration=PENDULUM_STEPS * DT)
    rows = measured(
        scenario,
        engine,
        [
            {"kind": "period", "joint": "pivot", "value": PERIOD},
            {"kind": "joint_position_at", "joint": "pivot", "time": PERIOD / 2,
             "value": -2 * AMPLITUDE},
        ],
    )  # fmt: skip
    period, turning = rows["period.pivot"], rows["joint_position_at.pivot"]
    assert period.error < PERIOD_TOLERANCE[engine], period
    assert "3 upward crossings" in period.message, period.message
    assert turning.error < TURNING_TOLERANCE[engine], turning
    assert "interpolated" in turning.message, turning.message


def test_a_run_too_short_for_two_crossings_has_no_period():
    scenario = compound_pendulum(["mini"], duration=round(PERIOD / DT) * DT)
    row = measured(scenario, "mini", [{"kind": "period", "joint": "pivot", "value": PERIOD}])[
        "period.pivot"
    ]
    assert math.isinf(row.error), row
    assert "1 upward crossing(s)" in row.message and "a period needs two" in row.message, row


# --- a cart on a slider pulled by a spring ----------------------------------------------------

STIFFNESS = 100.0
"""N/m, on a 1 kg cart: ω = 10 rad/s, T = 0.628 s."""
STRETCH = 0.2
"""m, the spring's stretch at t = 0 (the amplitude A)."""
OMEGA = math.sqrt(STIFFNESS)
READ_AT = 0.5
"""s, between the turning points (|sin ωt| = 0.96: the largest O(h) term of the next constant)."""

SLIDER_TOLERANCE = {
    "mujoco": STRETCH * OMEGA * DT / 2 + STRETCH * OMEGA**3 * DT**2 * READ_AT / 24,
    "mujoco(integrator=RK4)": 1e-9,
    "mini": STRETCH * OMEGA * DT / 2 + STRETCH * OMEGA**3 * DT**2 * READ_AT / 24,
}
"""m at READ_AT. Symplectic Euler (mini and MuJoCo alike on this scene: the slider row does not
act along the spring) solves the oscillator exactly as x_n = A cos(nθ) - A (ω h / 2) sin(nθ)
to leading order (x_1 = A (1 - ω²h²), cos θ = 1 - ω²h²/2): a term A ω h / 2 = 1e-3 m in
phase with the rate, plus the period's ω²h²/24 over ω t of phase, 4.2e-7 m (measured: 9.63e-4
in both, A ω h / 2 · |sin 5|); RK4's O((ω h)⁴) of A over ω t (measured 8e-11)."""

SLIDER_PERIOD = 2 * math.pi / OMEGA
SLIDER_STEPS = round(3 * SLIDER_PERIOD / DT)
"""Three periods (1.885 s): three upward crossings."""

SLIDER_CROSSING = crossing_interpolation(STIFFNESS, STRETCH, STRETCH * OMEGA, SLIDER_STEPS)
"""s, 2.7e-9."""

SLIDER_PERIOD_TOLERANCE = {
    "mujoco": SLIDER_PERIOD * (OMEGA * DT) ** 2 / 24 + SLIDER_CROSSING,
    "mujoco(integrator=RK4)": SLIDER_PERIOD * (OMEGA * DT) ** 4 + SLIDER_CROSSING,
    "mini": SLIDER_PERIOD * (OMEGA * DT) ** 2 / 24 + SLIDER_CROSSING,
}
"""s. Symplectic Euler's period is off by ω²h²/24 of T to leading order (T_h = 2πh / arccos(1 -
ω²h²/2)), 2.618e-6 s (measured 2.617e-6 in both); RK4's by O((ω h)⁴) of T, 6.3e-9 s (measured
1.3e-9); each plus the crossings' interpolation."""


def slider_on_a_spring(duration: float) -> Scenario:
    """A 1 kg cart on a slider along x at z = 1 m, a spring to the world point 1 m behind it
    stretched by STRETCH; gravity across the slider."""
    return Scenario.model_validate(
        {
            "name": "slider_on_a_spring",
            "dt": DT,
            "duration": duration,
            "engines": ["mini"],
            "bodies": [
                {"name": "cart", "shape": {"type": "box", "half_extents": [0.1, 0.1, 0.1]},
                 "mass": 1.0, "position": [0.0, 0.0, 1.0]}
            ],
            "joints": [
                {"name": "rail", "type": "slider", "parent": "world", "child": "cart",
                 "anchor": [0.0, 0.0, 1.0], "axis": [1.0, 0.0, 0.0]}
            ],
            "springs": [
                {"a": "cart", "b": "world", "anchor_b": [-1.0, 0.0, 1.0],
                 "stiffness": STIFFNESS, "rest_length": 1.0 - STRETCH}
            ],
        }
    )  # fmt: skip


@pytest.mark.parametrize("engine", ENGINES)
def test_a_slider_on_a_spring_follows_the_closed_form_oscillator(engine):
    rows = measured(
        slider_on_a_spring(SLIDER_STEPS * DT),
        engine,
        [
            {"kind": "joint_position_at", "joint": "rail", "time": READ_AT,
             "value": -STRETCH * (1 - math.cos(OMEGA * READ_AT))},
            {"kind": "period", "joint": "rail", "value": SLIDER_PERIOD},
        ],
    )  # fmt: skip
    position, period = rows["joint_position_at.rail"], rows["period.rail"]
    assert position.error < SLIDER_TOLERANCE[engine], position
    assert " m" in position.message, position.message
    assert period.error < SLIDER_PERIOD_TOLERANCE[engine], period


# --- a ball's rotation vector, a hinge past many turns ---------------------------------------

SPIN = 2.5
"""rad/s: the sphere's spin about z (2.5 rad at READ_SPIN, inside the rotation vector's |φ| < π)."""
READ_SPIN = 1.0

SPIN_TOLERANCE = 1e-9
"""rad. A torque-free sphere about a ball joint at its centre turns at a constant ω (its
inertia is isotropic, gravity acts at the anchor): every engine integrates that exactly, to
round-off over 1000 steps (measured below 1e-12 rad); a rotation vector read in the wrong
frame or from the wrong body would be off by about |φ| = 2.5 rad."""


def spun(joint: dict, spin: list[float], duration: float) -> Scenario:
    """A 1 kg sphere at (0, 0, 1) on ``joint`` to the world at its centre, spinning at ``spin``."""
    return Scenario.model_validate(
        {
            "name": "spun",
            "dt": DT,
            "duration": duration,
            "engines": ["mini"],
            "bodies": [
                {"name": "wheel", "shape": {"type": "sphere", "radius": 0.2}, "mass": 1.0,
                 "position": [0.0, 0.0, 1.0], "angular_velocity": spin}
            ],
            "joints": [{"name": "pin", "parent": "world", "child": "wheel",
                        "anchor": [0.0, 0.0, 1.0], **joint}],
        }
    )  # fmt: skip


@pytest.mark.parametrize("engine", ENGINES)
def test_a_ball_joints_position_is_its_rotation_vector(engine):
    scene = spun({"type": "ball"}, [0.0, 0.0, SPIN], 1.0)
    expected = [0.0, 0.0, SPIN * READ_SPIN]
    row = measured(
        scene,
        engine,
        [{"kind": "joint_position_at", "joint": "pin", "time": READ_SPIN, "value": expected}],
    )["joint_position_at.pin"]
    assert row.error < SPIN_TOLERANCE, row
    assert row.signed is not None and len(row.signed) == 3, row


TURNS_RATE = 40.0
"""rad/s about the hinge: 40 rad (6.4 turns) in 1 s, over four batches of observed states
(``recording.BATCH_OBSERVATIONS`` = 256)."""


@pytest.mark.parametrize("engine", ENGINES)
def test_a_hinges_angle_goes_on_past_many_turns_across_batches(engine):
    scene = spun({"type": "hinge", "axis": [0.0, 0.0, 1.0]}, [0.0, 0.0, TURNS_RATE], 1.0)
    row = measured(
        scene,
        engine,
        [
            {
                "kind": "joint_position_at",
                "joint": "pin",
                "time": 0.9995,
                "value": TURNS_RATE * 0.9995,
            }
        ],
    )["joint_position_at.pin"]
    assert row.error < SPIN_TOLERANCE * TURNS_RATE, row


# --- the loader's refusals --------------------------------------------------------------------

JOINTED = """dt: 0.001
duration: 1.0
engines: [mini]
bodies:
  - {name: bar, shape: {type: sphere, radius: 0.1}, mass: 1.0, position: [0, 0, 1]}
  - {name: bob, shape: {type: sphere, radius: 0.1}, mass: 1.0, position: [0, 0, 0.5]}
  - {name: cart, shape: {type: sphere, radius: 0.1}, mass: 1.0, position: [1, 0, 1]}
  - {name: weld, shape: {type: sphere, radius: 0.1}, mass: 1.0, position: [1, 0, 0.5]}
joints:
  - {name: hinge, type: hinge, parent: world, child: bar, anchor: [0, 0, 1.5], axis: [0, 1, 0]}
  - {name: ball, type: ball, parent: bar, child: bob, anchor: [0, 0, 0.75]}
  - {name: rail, type: slider, parent: world, child: cart, anchor: [1, 0, 1], axis: [1, 0, 0]}
  - {name: glue, type: fixed, parent: cart, child: weld, anchor: [1, 0, 0.75]}
expect:
"""

REFUSALS = {
    "an unknown joint": (
        "{kind: period, joint: hinj, value: 1.0}",
        "expect[0].joint",
        "expected a joint name; got 'hinj'; did you mean 'hinge'?",
    ),
    "a ball's number": (
        "{kind: joint_position_at, joint: ball, time: 0.5, value: 0.3}",
        "expect[0].value",
        "'ball' is a ball joint: expected a vector [x, y, z] rad (its rotation vector); got 0.3",
    ),
    "a hinge's vector": (
        "{kind: joint_position_at, joint: hinge, time: 0.5, value: [0, 0.3, 0]}",
        "expect[0].value",
        "'hinge' is a hinge joint: expected a number (rad); got [0.0, 0.3, 0.0]",
    ),
    "a slider's vector": (
        "{kind: joint_position_at, joint: rail, time: 0.5, value: [0.1, 0, 0]}",
        "expect[0].value",
        "'rail' is a slider joint: expected a number (m)",
    ),
    "a fixed joint's position": (
        "{kind: joint_position_at, joint: glue, time: 0.5, value: 0.0}",
        "expect[0].joint",
        "'glue' is a fixed joint (it has no coordinate)",
    ),
    "a ball's period": (
        "{kind: period, joint: ball, value: 1.0}",
        "expect[0].joint",
        "expected a hinge or slider joint; 'ball' is a ball joint",
    ),
    "a fixed joint's period": (
        "{kind: period, joint: glue, value: 1.0}",
        "expect[0].joint",
        "expected a hinge or slider joint; 'glue' is a fixed joint",
    ),
    "a time after the run": (
        "{kind: joint_position_at, joint: hinge, time: 1.5, value: 0.1}",
        "expect[0].time",
        "expected a time within the run (<= 1.0 s)",
    ),
    "a body where a joint is expected": (
        "{kind: period, body: bar, value: 1.0}",
        "expect[0].joint",
        "required field is missing",
    ),
}


@pytest.mark.parametrize("case", sorted(REFUSALS))
def test_the_loader_refuses_a_joint_expectation_that_does_not_fit(tmp_path, case):
    entry, path, words = REFUSALS[case]
    scenario, problems = check_scenario(write(tmp_path, JOINTED + f"  - {entry}\n"))
    errors = [p for p in problems if not p.warning]
    assert scenario is None and errors, case
    assert any(p.path.startswith(path) and words in p.message for p in errors), [
        str(p) for p in errors
    ]


def test_each_joint_type_loads_the_expectations_that_fit_it(tmp_path):
    fits = (
        "  - {kind: joint_position_at, joint: hinge, time: 0.5, value: 0.1}\n"
        "  - {kind: joint_position_at, joint: ball, time: 0.5, value: [0, 0, 0.1]}\n"
        "  - {kind: joint_position_at, joint: rail, time: 0.5, value: 0.1}\n"
        "  - {kind: period, joint: hinge, value: 1.0}\n"
        "  - {kind: period, joint: rail, value: 1.0, name: rail_period}\n"
    )
    scenario, problems = check_scenario(write(tmp_path, JOINTED + fits))
    assert scenario is not None, [str(p) for p in problems]
    assert [e.metric for e in scenario.expect] == [
        "joint_position_at.hinge",
        "joint_position_at.ball",
        "joint_position_at.rail",
        "period.hinge",
        "rail_period",
    ]


def test_a_joints_reading_watches_the_contacts_of_every_body_joined_to_it():
    """An impulse on any body of an articulation moves its joints: the elbow's reading may not
    be interpolated across a contact change of the upper body, nor of the lower; a body on its
    own is not watched."""
    from test_joint_scenes import double_pendulum

    from validation.measure.expectations import trackers

    stated = double_pendulum(["mini"]).model_dump()
    stated["bodies"].append(
        {"name": "loose", "shape": {"type": "sphere", "radius": 0.1}, "mass": 1.0,
         "position": [3.0, 0.0, 0.0]}
    )  # fmt: skip
    stated["expect"] = [
        {"kind": "joint_position_at", "joint": "elbow", "time": 0.5, "value": 0.0},
        {"kind": "position_at", "body": "loose", "time": 0.5, "value": [0.0, 0.0, 0.0]},
    ]
    elbow, loose = trackers(compile_scene(Scenario.model_validate(stated)))
    assert sorted(elbow.watched.tolist()) == [0, 1], elbow.watched
    assert loose.watched.tolist() == [2], loose.watched


def test_a_periods_memory_grows_with_the_run_and_the_estimate_counts_it():
    """``period`` keeps the coordinate at every step: the worker's estimate adds its bytes per
    step (``GROWING_BYTES_PER_STATE``); a ``joint_position_at`` keeps a bracket and adds none."""
    from validation.jobs.memory import job_estimate
    from validation.measure.expectations import GROWING_BYTES_PER_STATE

    scenario = compound_pendulum(["mini"], duration=PENDULUM_STEPS * DT)
    spec = parse_engine_spec("mini")

    def worker(expect: list[dict]) -> int:
        stated = {**scenario.model_dump(), "expect": expect}
        return job_estimate(compile_scene(Scenario.model_validate(stated)), spec, 1).worker

    bare = worker([])
    at = worker([{"kind": "joint_position_at", "joint": "pivot", "time": 1.0, "value": 0.0}])
    period = worker([{"kind": "period", "joint": "pivot", "value": PERIOD}])
    assert at == bare
    assert period - bare == PENDULUM_STEPS * GROWING_BYTES_PER_STATE["period"] > 0
