"""Joints in Drake, measured (docs/engines-drake.md 9): every joint type against the reference
side's joint-space motion, the joints kept exactly (reduced coordinates), the stated state read
back at t = 0, a joint's two bodies never colliding while other pairs still do, and the
capabilities each profile declares. The compound and double pendulums of
``tests/test_joint_scenes.py`` run in Drake too. pydrake is a test dependency (as in
``tests/test_engine_drake.py``): without it these tests fail rather than skip."""

from __future__ import annotations

import numpy as np
import pytest
from test_engine_drake import start_errors
from test_joint_scenes import double_pendulum

from validation.engines.registry import create_adapter
from validation.measure.runner import run_engine
from validation.reference.articulated import (
    Loads,
    initial_velocities,
    joint_coordinates,
    joint_violations,
    reference_motion,
)
from validation.reference.rotation import quat_to_matrix
from validation.scenario import Scenario
from validation.scenario.compiled import compile_scene
from validation.scenario.engine_spec import parse_engine_spec

DISCRETE = "drake"
CONTINUOUS = "drake(profile=continuous)"
PROFILES = (DISCRETE, CONTINUOUS)

DT = 1e-3
G = 9.81

ROUND_OFF = 1e-12
"""m, m/s, rad/s: a state read back straight after it was set (a pose through Drake's frames
and a Jacobian's least squares: a few double epsilons of unit-sized numbers)."""

REDUCED_COORDINATES = 1e-12
"""m and rad: Drake's joints are coordinates of a tree, so the joints hold to round-off
(measured 5.2e-16 m on the compound pendulum, 9.9e-16 m and 1e-15 rad on the chain here, both
profiles)."""

CHAIN_TOLERANCE = {DISCRETE: G * 1.0 * DT, CONTINUOUS: 1e-4 * 0.6}
"""m over 1 s against the reference's DOP853. Discrete: semi-implicit Euler is first order,
O(dt)·|a|·t ≈ |g|·1 s·1 ms = 9.8e-3 (measured 6.4e-3 on the chain; its carriage 2.7e-3, about
a·t·dt/2 of its damped slide; the rod of the ball tests 2.1e-3). Continuous: RK3 holds its
local error to Drake's default accuracy 1e-4, relative to the motion's scale (the 0.6 m arm):
6e-5 (measured 3.9e-7)."""


def jointed(name: str, engines: list[str], bodies: list, joints: list, **fields) -> Scenario:
    """A scene at ``DT`` under gravity -g z (1 s unless ``fields`` say otherwise)."""
    scene = {"dt": DT, "duration": 1.0, "gravity": [0.0, 0.0, -G], **fields}
    return Scenario.model_validate(
        {"name": name, "engines": engines, "bodies": bodies, "joints": joints, **scene}
    )


ARM_TILT = [float(np.cos(0.15)), float(np.sin(0.15)), 0.0, 0.0]
"""The arm turned 0.3 rad about its hinge's axis x, and the welded box turned about a skew
axis: the joints' child frames carry rotations R0 other than the identity."""
TIP_TILT = (np.array([0.9, 0.2, -0.3, 0.25]) / np.linalg.norm([0.9, 0.2, -0.3, 0.25])).tolist()


def chain_scene(engines: list[str]) -> Scenario:
    """Every joint type with damping: an arm hinged to the world about x (damped), a ball on a
    ball joint at its far end (hanging off the arm's plane, so the motion is 3-D), a box welded
    to the ball, a carriage on a damped slider along a tilted axis, moving along it, and a box
    jointed to nothing, thrown tumbling (a free body of a jointed scene)."""
    slope = [0.6, 0.0, -0.8]
    return jointed(
        "drake_joint_chain",
        engines,
        [
            {"name": "arm", "shape": {"type": "box", "half_extents": [0.02, 0.3, 0.02]},
             "mass": 1.0, "position": [0.0, 0.3, 2.0], "orientation": ARM_TILT},
            {"name": "ball", "shape": {"type": "sphere", "radius": 0.05},
             "mass": 0.5, "position": [0.1, 0.6, 1.72]},
            {"name": "tip", "shape": {"type": "box", "half_extents": [0.03, 0.03, 0.03]},
             "mass": 0.2, "position": [0.1, 0.7, 1.62], "orientation": TIP_TILT},
            {"name": "carriage", "shape": {"type": "sphere", "radius": 0.05},
             "mass": 2.0, "position": [-1.0, 0.0, 1.0],
             "velocity": [0.5 * s for s in slope]},
            {"name": "loose", "shape": {"type": "box", "half_extents": [0.1, 0.2, 0.3]},
             "mass": 2.0, "position": [3.0, 0.0, 2.0], "orientation": TIP_TILT,
             "velocity": [1.0, 0.0, 2.0], "angular_velocity": [0.3, -0.2, 0.5]},
        ],
        [
            {"name": "shoulder", "type": "hinge", "parent": "world", "child": "arm",
             "anchor": [0.0, 0.0, 2.0], "axis": [1.0, 0.0, 0.0], "damping": 0.05},
            {"name": "wrist", "type": "ball", "parent": "arm", "child": "ball",
             "anchor": [0.0, 0.6, 2.0], "damping": 0.01},
            {"name": "weld", "type": "fixed", "parent": "ball", "child": "tip",
             "anchor": [0.1, 0.6, 1.72]},
            {"name": "rail", "type": "slider", "parent": "world", "child": "carriage",
             "anchor": [-1.0, 0.0, 1.0], "axis": slope, "damping": 0.3},
        ],
    )  # fmt: skip


def recorded(engine: str, scenario: Scenario):
    scene = compile_scene(scenario)
    run = run_engine(scene, parse_engine_spec(engine))
    assert run.status == "ok", (engine, run.status, run.message)
    return scene, run.recording.trajectory


def off_reference(scenario: Scenario, scene, trajectory) -> float:
    """m: the largest distance of any body from the reference's joint-space DOP853 motion
    (``articulated.reference_motion`` from the stated velocities) over the recorded run."""
    tree, stated = scene.joint_tree, scenario.bodies
    nu0, _ = initial_velocities(
        tree, np.array([b.velocity for b in stated]), np.array([b.angular_velocity for b in stated])
    )
    loads = Loads(scene.gravity, scene.springs, scene.force, scene.torque)
    motion, _, _ = reference_motion(tree, tree.zero(), nu0, loads, trajectory.t[1:])
    return float(np.abs(trajectory.pos[1:] - motion.pos).max())


@pytest.mark.parametrize("engine", PROFILES)
def test_every_joint_type_follows_the_joint_space_reference_and_holds_exactly(engine):
    scenario = chain_scene([engine])
    scene, trajectory = recorded(engine, scenario)
    difference = off_reference(scenario, scene, trajectory)
    assert difference < CHAIN_TOLERANCE[engine], (engine, difference)
    separation, misalignment, _ = joint_violations(
        scene.joint_tree, trajectory.pos, quat_to_matrix(trajectory.quat)
    )
    assert separation.max() < REDUCED_COORDINATES, separation.max()
    assert misalignment.max() < REDUCED_COORDINATES, misalignment.max()


def loaded(engine: str, scenario: Scenario):
    adapter = create_adapter(parse_engine_spec(engine))
    adapter.load(compile_scene(scenario))
    return adapter


@pytest.mark.parametrize("engine", PROFILES)
def test_the_stated_poses_and_velocities_read_back_at_the_start(engine):
    """Each joint's zero is the stated configuration and the joint velocities come from the
    stated body velocities: a double pendulum turning at 1.5 rad/s reads back as stated."""
    for name, errors in start_errors(engine, double_pendulum([engine])).items():
        assert max(errors.values()) < ROUND_OFF, (name, errors)


OVERLAP_RADIUS = 0.3
"""m: every shape of the contact scene, so that each jointed pair overlaps at its anchor."""


def overlapping_scene(engines: list[str]) -> Scenario:
    """A fixed post with a bar hinged to it (Drake's parent is then its world body, which its
    own adjacency filter leaves out), a ball hinged to the bar, and a loose ball overlapping
    the hinged ball but jointed to nothing; no gravity, all at rest."""

    def ball(name, position, **fields):
        shape = {"type": "sphere", "radius": OVERLAP_RADIUS}
        return {"name": name, "shape": shape, "mass": 1.0, "position": position, **fields}

    return jointed(
        "drake_joint_contacts",
        engines,
        [
            ball("post", [0.0, 0.0, 1.0], fixed=True),
            ball("bar", [0.4, 0.0, 1.0]),
            ball("hanging", [0.8, 0.0, 1.0]),
            ball("loose", [0.8, 0.4, 1.0]),
        ],
        [
            {"name": "base", "type": "hinge", "parent": "post", "child": "bar",
             "anchor": [0.2, 0.0, 1.0], "axis": [0.0, 0.0, 1.0]},
            {"name": "elbow", "type": "hinge", "parent": "bar", "child": "hanging",
             "anchor": [0.6, 0.0, 1.0], "axis": [0.0, 0.0, 1.0]},
        ],
        duration=0.01,
        gravity=[0.0, 0.0, 0.0],
    )  # fmt: skip


def touching_pairs(adapter) -> set[tuple[str, str]]:
    """The scene-body pairs Drake's own geometry query finds in contact now (its point-pair
    penetration, after its collision filters)."""
    names = {entry[3]: adapter.scenario.bodies[k].name for k, entry in adapter.geometry.items()}
    query = adapter.plant.get_geometry_query_input_port().Eval(adapter.context)
    return {
        tuple(sorted((names[pair.id_A], names[pair.id_B])))
        for pair in query.ComputePointPairPenetration()
    }


@pytest.mark.parametrize("engine", PROFILES)
def test_a_joints_two_bodies_never_collide_while_other_pairs_do(engine):
    """Every neighbour overlaps by 0.2 m: the jointed pairs (post-bar, bar-hanging) are
    filtered, the loose ball still touches the hanging one and the bar (not jointed to it)."""
    adapter = loaded(engine, overlapping_scene([engine]))
    try:
        found = touching_pairs(adapter)
        recorded_filters = adapter.provenance().settings["jointed_pairs_filtered"]
    finally:
        adapter.close()
    assert recorded_filters == 2, recorded_filters
    assert not {("bar", "post"), ("bar", "hanging")} & found, found
    assert {("hanging", "loose"), ("bar", "loose")} <= found, found


def test_both_profiles_declare_joints_and_only_the_discrete_one_their_limits():
    from validation.engines.drake.declaration import capabilities_for

    discrete = capabilities_for({}).features
    continuous = capabilities_for({"profile": "continuous"}).features
    assert {"joints", "joint_limits"} <= discrete, discrete
    assert "joints" in continuous and "joint_limits" not in continuous, continuous


LEVER = 0.3
"""m: the limited pendulum's bob from its hinge."""

LIMIT_SAG = 0.5 * G * DT**2
"""m: a position constraint solved once per step lets its body go on unconstrained for at most
one step before it acts, ½ g dt² = 4.9e-6 m under gravity (LIMIT_SAG / LEVER rad at the bob).
Measured: SAP holds the hinge 1.6e-8 rad and the slider 5.0e-9 m past their limits."""


def limited_scene(engines: list[str]) -> Scenario:
    """A pendulum released level (its hinge about y: it falls to positive angles) limited to
    [-0.5, 0.2] rad, and a carriage on a vertical slider limited to [-0.1, 0.3] m, falling (uneven
    limits: a coordinate of the wrong sign meets the other one)."""
    return jointed(
        "drake_joint_limits",
        engines,
        [
            {"name": "bob", "shape": {"type": "sphere", "radius": 0.05}, "mass": 1.0,
             "position": [LEVER, 0.0, 0.0]},
            {"name": "carriage", "shape": {"type": "sphere", "radius": 0.05}, "mass": 1.0,
             "position": [5.0, 0.0, 0.0]},
        ],
        [
            {"name": "pivot", "type": "hinge", "parent": "world", "child": "bob",
             "anchor": [0.0, 0.0, 0.0], "axis": [0.0, 1.0, 0.0], "limits": [-0.5, 0.2]},
            {"name": "rail", "type": "slider", "parent": "world", "child": "carriage",
             "anchor": [5.0, 0.0, 0.0], "axis": [0.0, 0.0, 1.0], "limits": [-0.1, 0.3]},
        ],
        duration=0.5,
    )  # fmt: skip


def test_the_discrete_plant_holds_a_hinge_and_a_slider_at_their_limits():
    """The pendulum reaches its upper limit and the carriage its lower one within 0.5 s (free,
    they would be at 1.2 rad and -1.2 m); neither passes its limit by more than one step's
    free fall, and both rest there at the end."""
    scene, trajectory = recorded(DISCRETE, limited_scene([DISCRETE]))
    coordinates = joint_coordinates(
        scene.joint_tree, trajectory.pos, quat_to_matrix(trajectory.quat)
    )
    swing, slide = coordinates["pivot"], coordinates["rail"]
    assert swing.max() < 0.2 + LIMIT_SAG / LEVER, swing.max()
    assert slide.min() > -0.1 - LIMIT_SAG, slide.min()
    assert abs(swing[-1] - 0.2) < LIMIT_SAG / LEVER, swing[-1]
    assert abs(slide[-1] + 0.1) < LIMIT_SAG, slide[-1]


def test_a_scene_with_limits_is_unsupported_in_the_continuous_plant():
    """Drake's continuous plant ignores joint limits (the pendulum above swings to 3.14 rad),
    so that profile refuses the scene rather than run it without them."""
    run = run_engine(compile_scene(limited_scene([CONTINUOUS])), parse_engine_spec(CONTINUOUS))
    assert run.status == "unsupported" and "joint_limits" in run.message, (
        run.status,
        run.message,
    )


def ball_rod(engines: list[str], position, half_extents, velocity, angular_velocity) -> Scenario:
    """A 1 m rod hanging from the world point (0, 0, 2) by a ball joint at its end."""
    return jointed(
        "drake_ball_rod",
        engines,
        [
            {"name": "rod", "shape": {"type": "box", "half_extents": half_extents},
             "mass": 1.0, "position": position, "velocity": velocity,
             "angular_velocity": angular_velocity},
        ],
        [{"name": "socket", "type": "ball", "parent": "world", "child": "rod",
          "anchor": [0.0, 0.0, 2.0]}],
    )  # fmt: skip


@pytest.mark.parametrize("engine", PROFILES)
def test_a_ball_joint_falls_through_a_quarter_turn_and_spins_about_gravity(engine):
    """A rod released level falls to hanging (a quarter turn about the horizontal normal to it,
    which is pitch π/2 of a ``BallRpyJoint`` whose frame took the parent's axes: Drake raises
    there), once from rest and once spinning about the vertical at 3 rad/s."""
    for velocity, spin in (([0.0, 0.0, 0.0], [0.0, 0.0, 0.0]), ([0.0, 1.5, 0.0], [0.0, 0.0, 3.0])):
        scenario = ball_rod([engine], [0.5, 0.0, 2.0], [0.5, 0.02, 0.02], velocity, spin)
        scene, trajectory = recorded(engine, scenario)
        difference = off_reference(scenario, scene, trajectory)
        assert difference < CHAIN_TOLERANCE[engine], (engine, spin, difference)


def test_a_ball_joint_at_its_singularity_is_an_error_row_naming_it():
    """The ball's frame keeps one pitch singularity: the rod's downward axis turned onto the
    horizontal normal to the plane of gravity and the rod (a hanging rod kicked sideways to
    level). Drake raises there, and the run is one ``error`` row with Drake's words."""
    scenario = ball_rod(
        [DISCRETE], [0.0, 0.0, 1.5], [0.02, 0.02, 0.5], [0.0, 3.0, 0.0], [6.0, 0.0, 0.0]
    )
    run = run_engine(compile_scene(scenario), parse_engine_spec(DISCRETE))
    assert run.status == "error" and "singularity" in run.message, (run.status, run.message)


def test_a_non_finite_plant_state_reads_as_non_finite_body_states():
    """Drake refuses a non-finite state (``SetPositionsAndVelocities``), so an exploded jointed
    run's last state reads as non-finite moving bodies (the run is then ``unstable`` with the
    states before it, as a free body's, engines-drake.md 8.1), not an engine error."""
    adapter = loaded(DISCRETE, chain_scene([DISCRETE]))
    try:
        raw = np.stack([adapter._raw_state(), np.full_like(adapter._raw_state(), np.nan)])
        states = adapter._states(np.array([0.0, DT]), raw)
    finally:
        adapter.close()
    assert np.isfinite(states.pos[0]).all() and np.isnan(states.pos[1]).all(), states.pos


POST_TURN = [float(np.cos(0.2)), 0.0, 0.0, float(np.sin(0.2))]
"""The limited arm's fixed post, turned 0.4 rad about z."""


def test_a_ball_on_a_hinged_arm_stopped_by_its_limit_keeps_off_the_singularity():
    """A bar hinged to a fixed post swings down onto its 1 rad limit, and the ball hanging
    from its end by a ball joint whips round it, relative to the bar, about the hinge's axis.
    With the ball's frame along the bar's own axes, or gravity's, that turn is the pitch, and
    Drake raised its singularity at 0.985 s; with z along the bar's hinge axis it is a yaw, and
    the run is ``ok`` with the joints held."""
    half_turn = [float(np.cos(np.pi / 4)), 0.0, float(np.sin(np.pi / 4)), 0.0]
    # the post turned about z: the hinge's axis is y in the world, not along the post's axes
    # (the parity gate then checks that Drake's axis is read back into the world)
    scenario = jointed(
        "drake_ball_on_a_limited_arm",
        [DISCRETE],
        [
            {"name": "post", "shape": {"type": "box", "half_extents": [0.05, 0.05, 0.05]},
             "mass": 1.0, "position": [0.0, 0.0, 2.0], "fixed": True, "orientation": POST_TURN},
            {"name": "bar", "shape": {"type": "box", "half_extents": [0.02, 0.02, 0.25]},
             "mass": 1.0, "position": [0.25, 0.0, 2.0], "orientation": half_turn},
            {"name": "bob", "shape": {"type": "sphere", "radius": 0.05}, "mass": 0.5,
             "position": [0.5, 0.0, 1.8]},
        ],
        [
            {"name": "pivot", "type": "hinge", "parent": "post", "child": "bar",
             "anchor": [0.0, 0.0, 2.0], "axis": [0.0, 1.0, 0.0], "damping": 0.01,
             "limits": [-0.5, 1.0]},
            {"name": "socket", "type": "ball", "parent": "bar", "child": "bob",
             "anchor": [0.5, 0.0, 2.0]},
        ],
    )  # fmt: skip
    scene, trajectory = recorded(DISCRETE, scenario)
    separation, _, _ = joint_violations(
        scene.joint_tree, trajectory.pos, quat_to_matrix(trajectory.quat)
    )
    assert separation.max() < REDUCED_COORDINATES, separation.max()
