"""Scenes with joints through the harness: each engine that declares joints builds the scene's
joint tree, its observed states keep the joints and follow the closed forms, and the metrics
a jointed scene cannot define are left out.

The closed forms: a compound pendulum's period (the complete elliptic integral) read back
from each engine's observed poses (``articulated.joint_coordinates``), and a double pendulum
against the reference side's own joint-space DOP853 integration.
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest
from scipy.special import ellipk

from validation.engines.registry import create_adapter
from validation.measure.resolution import FLOAT32_UNIT_ROUNDOFF
from validation.measure.runner import run_engine
from validation.reference.articulated import (
    Loads,
    joint_coordinates,
    joint_violations,
    reference_motion,
)
from validation.reference.rotation import quat_to_matrix
from validation.scenario import Scenario
from validation.scenario.compiled import compile_scene
from validation.scenario.definability import defined_metrics, scene_traits
from validation.scenario.engine_spec import not_installed, parse_engine_spec

G = 9.81
DT = 1e-3
AMPLITUDE = 2.0
"""rad: the compound pendulum's release angle (its period 31 % above the small-angle one)."""

PIVOT = (0.0, 0.0, 2.0)
BAR_HALF = 0.5


def compound_pendulum(engines: list[str], duration: float) -> Scenario:
    """A 1 kg bar (1 m) hinged about y at its top end, released from rest at ``AMPLITUDE``."""
    turn = [math.cos(AMPLITUDE / 2), 0.0, math.sin(AMPLITUDE / 2), 0.0]
    centre = [-BAR_HALF * math.sin(AMPLITUDE), 0.0, PIVOT[2] - BAR_HALF * math.cos(AMPLITUDE)]
    return Scenario.model_validate(
        {
            "name": "compound_pendulum",
            "dt": DT,
            "duration": duration,
            "engines": engines,
            "bodies": [
                {
                    "name": "bar",
                    "shape": {"type": "box", "half_extents": [0.02, 0.02, BAR_HALF]},
                    "mass": 1.0,
                    "position": centre,
                    "orientation": turn,
                }
            ],
            "joints": [
                {
                    "name": "pivot",
                    "type": "hinge",
                    "parent": "world",
                    "child": "bar",
                    "anchor": list(PIVOT),
                    "axis": [0.0, 1.0, 0.0],
                }
            ],
        }
    )


PIVOT_INERTIA = (0.04**2 + 1.0**2) / 12 + BAR_HALF**2
PERIOD = 4 * math.sqrt(PIVOT_INERTIA / (G * BAR_HALF)) * ellipk(math.sin(AMPLITUDE / 2) ** 2)
"""s: T = 4 √(I_O / (m g d)) K(sin(θ0/2)), 2.177 s."""

TURNING_ACCELERATION = G * BAR_HALF * math.sin(AMPLITUDE) / PIVOT_INERTIA
"""rad/s²: α at the turning points (13.3), where the period's halves end."""

SAMPLING = 0.5 * TURNING_ACCELERATION * (DT / 2) ** 2
"""rad: the nearest step to T/2 or T is up to dt/2 away, where the rate is 0: ½ α (dt/2)² =
1.7e-6 rad."""

DRAKE_ACCURACY = 1e-4
"""Drake's continuous profile's default target accuracy (its ``SimulatorConfig``)."""

RAPIER_SUBSTEPS = 4
"""Rapier's state updates per step (engines-rapier.md 3), each rounding to float32."""

FLOAT32_ANGLE_FLOOR = round(PERIOD / DT) * RAPIER_SUBSTEPS * FLOAT32_UNIT_ROUNDOFF * 2 * AMPLITUDE
"""rad, 2.1e-3: what float32 can resolve of a joint angle up to 2 θ0 carried over T's steps of
4 substeps (validation/measure/resolution.py's floor for a carried value)."""

ANGLE_TOLERANCE = {
    "mini": 1e-3,
    "mujoco": 1e-3,
    "mujoco(integrator=RK4)": 2 * SAMPLING,
    "drake": 1e-3,
    "drake(profile=continuous)": 2 * SAMPLING + DRAKE_ACCURACY * AMPLITUDE,
    "pybullet": 1e-3,
    "rapier": 1e-3 + FLOAT32_ANGLE_FLOOR,
    "rapier(joints=impulse)": 1e-2,
}
"""rad at T/2 and T. First-order schemes add their phase error over the swing (measured 2.8e-5
and 6e-5 rad in mini at dt = 1 ms, 4.3e-6 in Drake's discrete plant, 4.3e-6 and 6.6e-7 in
PyBullet's btMultiBody; the energy error, 1e-3 of the scale, bounds the period's); RK4 adds O(dt⁴), far below the sampling; Drake's
error-controlled RK3 holds each step's error to its accuracy relative to the swing (measured
1.3e-6). Rapier's multibody (symplectic Euler substeps in float32) takes the first-order bound
plus its float32 floor (measured 3.3e-6 and 1.5e-6 rad). Rapier's impulse joints are an engine
finding asserted at its measured size: they dissipate 0.16 % of the energy per period and lag
3.9e-3 rad at T/2, 7.8e-3 rad at T (engines-rapier.md 9)."""


def installed(tolerances: dict[str, float]) -> list:
    """The engine specs of ``tolerances``, sorted; one of an optional extra that is not
    installed here (Rapier, Drake) is skipped with the install line."""
    return [
        pytest.param(spec, marks=pytest.mark.skipif(bool(reason), reason=str(reason)))
        for spec in sorted(tolerances)
        for reason in [not_installed(parse_engine_spec(spec).name)]
    ]


def recorded(engine: str, scenario: Scenario):
    scene = compile_scene(scenario)
    run = run_engine(scene, parse_engine_spec(engine))
    assert run.status == "ok", (engine, run.status, run.message)
    return scene, run.recording.trajectory


@pytest.mark.parametrize("engine", installed(ANGLE_TOLERANCE))
def test_a_large_swing_comes_back_at_the_elliptic_period(engine):
    scenario = compound_pendulum([engine], duration=round(PERIOD / DT) * DT)
    scene, trajectory = recorded(engine, scenario)
    angle = joint_coordinates(scene.joint_tree, trajectory.pos, quat_to_matrix(trajectory.quat))
    swing = angle["pivot"]
    half = int(np.argmin(np.abs(trajectory.t - PERIOD / 2)))
    # relative to the release: -2 θ0 at the far turning point, 0 back at the start
    assert abs(swing[half] + 2 * AMPLITUDE) < ANGLE_TOLERANCE[engine], swing[half]
    assert abs(swing[-1]) < ANGLE_TOLERANCE[engine], swing[-1]


def test_mujocos_reduced_coordinates_keep_the_joint_exactly_and_minis_impulses_to_baumgartes_bound():
    scenario = compound_pendulum(["mini", "mujoco"], duration=1.0)
    scene = compile_scene(scenario)
    for engine, bound in (("mujoco", 1e-12), ("mini", 1.04e-4)):
        _, trajectory = recorded(engine, scenario)
        separation, misalignment, _ = joint_violations(
            scene.joint_tree, trajectory.pos, quat_to_matrix(trajectory.quat)
        )
        # mini: the drift of one unconstrained step over β, ω²d dt²/β (tests/test_mini_joints.py)
        assert separation.max() < bound, (engine, separation.max())
        assert misalignment.max() < 1e-9, (engine, misalignment.max())


def double_pendulum(engines: list[str]) -> Scenario:
    """Two 1 kg balls on massless-looking links: a hinge about y at the world point (0, 0, 2)
    and a hinge about x (crossed axes: a hinge inside a hinge) at the first ball's centre; the
    first starts turning at 1.5 rad/s."""
    arm = 0.6
    return Scenario.model_validate(
        {
            "name": "double_pendulum",
            "dt": DT,
            "duration": 1.0,
            "engines": engines,
            "gravity": [0.0, 0.0, -G],
            "bodies": [
                {
                    "name": "upper",
                    "shape": {"type": "sphere", "radius": 0.05},
                    "mass": 1.0,
                    "position": [arm, 0.0, 2.0],
                    "velocity": [0.0, 0.0, -1.5 * arm],
                    "angular_velocity": [0.0, 1.5, 0.0],
                },
                {
                    "name": "lower",
                    "shape": {"type": "sphere", "radius": 0.05},
                    "mass": 1.0,
                    "position": [arm, arm, 2.0],
                    "velocity": [0.0, 0.0, -1.5 * arm],
                    "angular_velocity": [0.0, 1.5, 0.0],
                },
            ],
            "joints": [
                {"name": "shoulder", "type": "hinge", "parent": "world", "child": "upper",
                 "anchor": [0.0, 0.0, 2.0], "axis": [0.0, 1.0, 0.0]},
                {"name": "elbow", "type": "hinge", "parent": "upper", "child": "lower",
                 "anchor": [arm, 0.0, 2.0], "axis": [1.0, 0.0, 0.0]},
            ],
        }
    )  # fmt: skip


FLOAT32_POSITION_FLOOR = round(1.0 / DT) * RAPIER_SUBSTEPS * FLOAT32_UNIT_ROUNDOFF * 2.2
"""m, 5.2e-4: what float32 can resolve of a position up to 2.2 m from the origin (the balls)
carried over 1 s of 4 substeps a step (validation/measure/resolution.py's floor)."""

POSITION_TOLERANCE = {
    "mujoco": 5e-3,
    "mujoco(integrator=RK4)": 1e-6,
    "mini": 5e-3,
    "drake": 5e-3,
    "drake(profile=continuous)": DRAKE_ACCURACY * 0.6,
    "pybullet": 5e-3,
    "rapier": 5e-3 + FLOAT32_POSITION_FLOOR,
    "rapier(joints=impulse)": 2.5e-2,
}
"""m over 1 s against the reference's DOP853: first-order schemes drift by O(dt)·|a|·t
(~|g|·1 s·1 ms = 1e-2 at most; measured below 5e-3, Drake's discrete 1.5e-3, PyBullet 1.5e-3), RK4 by O(dt⁴),
Drake's RK3 by its accuracy relative to the 0.6 m arm (measured 1.7e-8). Rapier's multibody: the
first-order bound plus its float32 floor (measured 3.8e-4 m). Rapier's impulse joints: an engine
finding at its measured size, 2.0e-2 m (they dissipate, engines-rapier.md 9)."""


def off_the_reference(scenario: Scenario, scene, trajectory) -> float:
    """m: the largest distance of any body's recorded centre (``trajectory``) from the
    reference's joint-space DOP853 motion from the same stated state (the joints allow it)."""
    tree = scene.joint_tree
    from validation.reference.articulated import initial_velocities

    stated = scenario.bodies
    nu0, residual = initial_velocities(
        tree, np.array([b.velocity for b in stated]), np.array([b.angular_velocity for b in stated])
    )
    assert residual < 1e-12, residual
    loads = Loads(scene.gravity, scene.springs, scene.force, scene.torque)
    motion, _, _ = reference_motion(tree, tree.zero(), nu0, loads, trajectory.t[1:])
    return float(np.abs(trajectory.pos[1:] - motion.pos).max())


@pytest.mark.parametrize("engine", installed(POSITION_TOLERANCE))
def test_a_hinge_inside_a_hinge_follows_the_joint_space_reference(engine):
    scenario = double_pendulum([engine])
    difference = off_the_reference(scenario, *recorded(engine, scenario))
    assert difference < POSITION_TOLERANCE[engine], (engine, difference)


def test_a_jointed_scene_defines_the_joint_metrics_and_not_the_free_body_ones():
    scene = compile_scene(double_pendulum(["mini"]))
    defined = defined_metrics(scene_traits(scene))
    assert "joint_violation" in defined and "energy_drift" in defined, defined
    assert not {"linear_momentum_drift", "angular_momentum_drift", "position_error"} & defined
    free = compile_scene(double_pendulum(["mini"]).model_copy(update={"joints": []}))
    assert "joint_violation" not in defined_metrics(scene_traits(free))


def test_jointed_bodies_never_touch_each_other():
    """The bar's end and the ball overlap at the elbow by construction: no contact in mini,
    none in the measurement."""
    scenario = double_pendulum(["mini"])
    bodies = [
        {**b.model_dump(), "shape": {"type": "sphere", "radius": 0.4}} for b in scenario.bodies
    ]
    overlapping = scenario.model_copy(
        update={"bodies": [type(scenario.bodies[0]).model_validate(b) for b in bodies]}
    )
    scene = compile_scene(overlapping)
    found = scene.contacts(scene.start.pos, scene.start.quat, 1e-6)
    assert found.depth.size == 0, found
    adapter = create_adapter(parse_engine_spec("mini"))
    adapter.load(scene)
    from mini_engine.collision import detect_contacts
    from mini_engine.rotation import quat_to_matrix as mini_matrix

    state = adapter.state
    contacts = detect_contacts(adapter.model, state.pos, mini_matrix(state.quat), 1e-6)
    assert contacts.count == 0, contacts


ORDER_TOLERANCE = 0.1
"""The fitted order of a first-order scheme over dt = 4 to 0.5 ms: measured 0.938 (mini) and
0.9995 (MuJoCo Euler); 0.1 is the fit's spread between the two schemes' sub-leading terms."""


def test_the_sweep_measures_jointed_scenes_against_the_joint_space_reference(tmp_path):
    """``physval sweep`` on a compound pendulum: errors against the tree's own DOP853 (the
    ``dop853`` reference), first order for the Euler schemes."""
    import pandas as pd
    import yaml

    from validation.cli import main

    scene = tmp_path / "pendulum.yaml"
    data = compound_pendulum(["mini", "mujoco"], duration=0.5).model_dump(exclude_defaults=True)
    scene.write_text(yaml.safe_dump(data))
    out = tmp_path / "sweep"
    grid = ["--dt", "0.004,0.002,0.001,0.0005", "--engines", "mini, mujoco"]
    code = main(["sweep", str(scene), *grid, "--out", str(out)])
    assert code == 0, code
    rows = pd.read_csv(out / "sweep.csv")
    orders = rows[rows["metric"] == "convergence_order"]
    assert set(orders["expected_kind"]) == {"dop853"}, orders
    assert (abs(orders["value"] - 1.0) < ORDER_TOLERANCE).all(), orders[["engine", "value"]]


def test_stability_finds_each_engines_largest_stable_step_on_the_stiff_chain(tmp_path):
    """``physval stability`` on the library's stiff chain: MuJoCo's Euler loses energy control
    between the probed steps and is unstable above them; the bisection brackets that step."""
    import pandas as pd

    from validation.cli import main

    scene = Path(__file__).resolve().parents[1] / "scenarios" / "joints" / "stiff_chain.yaml"
    out = tmp_path / "stability.csv"
    assert main(["stability", str(scene), "--engines", "mujoco", "--out", str(out)]) == 0
    row = pd.read_csv(out).iloc[0]
    assert row["status"] == "ok" and row["stable_dt"] < row["unstable_dt"], row.to_dict()
    assert row["unstable_dt"] - row["stable_dt"] < 0.02 * row["stable_dt"], row.to_dict()


def test_the_joint_violation_row_is_the_worst_step_of_every_joint():
    """The ``joint_violation`` row of mini's double pendulum (a maximal-coordinate engine, whose
    joints drift) is the largest over every recorded step of each joint's anchor separation or
    misalignment times its child's reach, read from the bodies' poses alone."""
    from validation.measure.metrics import Context, joint_violation

    scenario = double_pendulum(["mini"])
    scene = compile_scene(scenario)
    run = run_engine(scene, parse_engine_spec("mini"), keep="states")
    assert run.status == "ok", run.message
    row = joint_violation(Context(scene, run.recording))
    trajectory = run.recording.trajectory
    separation, misalignment, reach = joint_violations(
        scene.joint_tree, trajectory.pos, quat_to_matrix(trajectory.quat)
    )
    worst = float(np.maximum(separation, misalignment * reach).max())
    assert worst > 1e-8, worst  # mini's joints do drift here: the row can see it
    assert math.isclose(row.value, worst, rel_tol=1e-12), (row.value, worst)


def test_a_hinge_tilted_off_its_axis_about_its_anchor_reads_as_its_reach_times_the_angle():
    """The compound pendulum's bar turned 1e-3 rad about x (off the hinge's y) about the pivot:
    the anchor stays put, so the whole violation is the misalignment times the bar's reach."""
    from validation.engines.base import Trajectory
    from validation.measure.states import joint_violation as violation_of

    scene = compile_scene(compound_pendulum(["mini"], duration=0.1))
    start = scene.start
    tilt = 1e-3
    turn = np.array([math.cos(tilt / 2), math.sin(tilt / 2), 0.0, 0.0])
    from validation.reference.rotation import quat_multiply

    pivot = np.array(PIVOT)
    arm = start.pos[0, 0] - pivot
    pos = (pivot + quat_to_matrix(turn) @ arm)[None, None]
    quat = quat_multiply(turn, start.quat[0, 0])[None, None]
    still = np.zeros((1, 1, 3))
    moved = Trajectory(np.zeros(1), pos, quat, still, still)
    assert math.isclose(float(violation_of(scene, moved)[0]), tilt * BAR_HALF, rel_tol=1e-6)
