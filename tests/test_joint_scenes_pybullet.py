"""PyBullet's joints (engines.md 2.7): every joint type in a btMultiBody rooted at the world,
at a fixed body and at a floating body against the reference side's joint-space DOP853, the joints held to
round-off, joint damping as btMultiBody applies it, and a joint's parent and child never in
contact while every other pair of the scene still is.

(The compound pendulum and the crossed-axis double pendulum run PyBullet in
tests/test_joint_scenes.py.)"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest

from validation.engines.registry import create_adapter
from validation.measure.runner import run_engine
from validation.reference.articulated import (
    Loads,
    body_motion,
    forward_kinematics,
    joint_violations,
    reference_motion,
)
from validation.reference.rotation import quat_to_matrix
from validation.scenario import Scenario
from validation.scenario.compiled import compile_scene
from validation.scenario.engine_spec import parse_engine_spec

G = 9.81
DT = 1e-3
ENGINE = "pybullet"


def _box(name: str, half, position, mass=1.0, **extra) -> dict:
    return {
        "name": name,
        "shape": {"type": "box", "half_extents": list(half)},
        "mass": mass,
        "position": list(position),
        **extra,
    }


def _sphere(name: str, radius, position, mass=1.0, **extra) -> dict:
    return {
        "name": name,
        "shape": {"type": "sphere", "radius": radius},
        "mass": mass,
        "position": list(position),
        **extra,
    }


def _scenario(name, bodies, joints, duration=1.0, gravity=(0.0, 0.0, -G)) -> Scenario:
    return Scenario.model_validate(
        {
            "name": name,
            "dt": DT,
            "duration": duration,
            "engines": [ENGINE],
            "gravity": list(gravity),
            "bodies": bodies,
            "joints": joints,
        }
    )


def moving(scenario: Scenario, nu0: np.ndarray) -> Scenario:
    """``scenario`` with every body's stated velocity the one joint-space velocity ``nu0``
    gives (so the joints allow it by construction)."""
    tree = compile_scene(scenario).joint_tree
    motion = body_motion(tree, forward_kinematics(tree, tree.zero()), nu0, np.zeros(tree.nv))
    bodies = [
        body.model_copy(update={"velocity": tuple(v), "angular_velocity": tuple(w)})
        for body, v, w in zip(scenario.bodies, motion.vel, motion.ang_vel, strict=True)
    ]
    return scenario.model_copy(update={"bodies": bodies})


def world_root_tree() -> Scenario:
    """An arm on a damped ball joint at a world point, swinging down and turning about x; a
    bead on a damped slider along the arm, a tip welded across it."""
    scenario = _scenario(
        "pybullet_world_root",
        [
            _box("arm", (0.3, 0.03, 0.03), (0.3, 0.0, 2.0)),
            _sphere("bead", 0.05, (0.5, 0.0, 2.0), mass=0.5),
            _sphere("tip", 0.05, (0.3, 0.0, 2.15), mass=0.3),
        ],
        [
            {"name": "shoulder", "type": "ball", "parent": "world", "child": "arm",
             "anchor": [0.0, 0.0, 2.0], "damping": 0.05},
            {"name": "rail", "type": "slider", "parent": "arm", "child": "bead",
             "anchor": [0.5, 0.0, 2.0], "axis": [1.0, 0.0, 0.0], "damping": 0.2},
            {"name": "weld", "type": "fixed", "parent": "arm", "child": "tip",
             "anchor": [0.3, 0.0, 2.1]},
        ],
    )  # fmt: skip
    return moving(scenario, np.array([1.0, 0.0, 0.5, -0.3]))


def fixed_root_tree() -> Scenario:
    """``world_root_tree`` hung from a fixed post instead (the post a fixed base)."""
    scenario = world_root_tree()
    post = _box("post", (0.05, 0.05, 0.05), (0.0, 0.0, 2.0), fixed=True)
    bodies = [type(scenario.bodies[0]).model_validate(post), *scenario.bodies]
    joints = [
        joint.model_copy(update={"parent": "post"}) if joint.parent == "world" else joint
        for joint in scenario.joints
    ]
    return scenario.model_copy(
        update={"name": "pybullet_fixed_root", "bodies": bodies, "joints": joints}
    )


def floating_root_tree() -> Scenario:
    """A free hub thrown up spinning about z, a paddle on a hinge about the hub's y axis."""
    scenario = _scenario(
        "pybullet_floating_root",
        [
            _box("hub", (0.1, 0.1, 0.1), (0.0, 0.0, 1.0), mass=2.0),
            _box("paddle", (0.2, 0.02, 0.1), (0.35, 0.0, 1.0)),
        ],
        [
            {"name": "pin", "type": "hinge", "parent": "hub", "child": "paddle",
             "anchor": [0.15, 0.0, 1.0], "axis": [0.0, 1.0, 0.0], "damping": 0.01},
        ],
    )  # fmt: skip
    return moving(scenario, np.array([0.2, 0.0, 3.0, 0.0, 0.5, 3.0, 1.0]))


POSITION_TOLERANCE = 2e-2
"""m over 1 s at dt = 1 ms against the reference's DOP853: btMultiBody's first-order scheme
drifts by O(dt)·|a|·t, |a| up to 2g for the bead sliding out along the swinging arm
(2·9.81·1 s·1 ms = 2e-2); measured 1.3e-2 m (the bead; the arm 1.0e-3) and 4.9e-3 m (the
floating root: g·t·dt/2, semi-implicit Euler's free-fall error, engines.md 1.6)."""

FIRST_ORDER = (0.4, 0.6)
"""The error at dt/2 over the error at dt, of the positions, velocities, spins and orientations:
1/2 for a first-order scheme that integrates the reference's model (measured 0.499 to 0.501); a
model that differs (a spin read in the wrong frame, a wrong inertia) keeps its error as dt
shrinks."""

JOINT_TOLERANCE = 1e-12
"""m and rad: reduced coordinates keep every joint by construction; the observed poses break
them by round-off alone (measured below 3e-15 m, 2e-15 rad)."""


def recorded(scenario: Scenario):
    scene = compile_scene(scenario)
    run = run_engine(scene, parse_engine_spec(ENGINE))
    assert run.status == "ok", (run.status, run.message)
    return scene, run.recording.trajectory


def reference(scene, trajectory):
    tree = scene.joint_tree
    stated = scene.scenario.bodies
    from validation.reference.articulated import initial_velocities

    nu0, residual = initial_velocities(
        tree, np.array([b.velocity for b in stated]), np.array([b.angular_velocity for b in stated])
    )
    assert residual < 1e-12, residual
    loads = Loads(scene.gravity, scene.springs, scene.force, scene.torque)
    return reference_motion(tree, tree.zero(), nu0, loads, trajectory.t[1:])[0]


def errors_against(motion, trajectory) -> np.ndarray:
    """Largest |engine - reference| of positions, velocities, spins and rotation matrices."""
    rotation = quat_to_matrix(trajectory.quat[1:].reshape(-1, 4))
    return np.array(
        [
            np.abs(trajectory.pos[1:] - motion.pos).max(),
            np.abs(trajectory.vel[1:] - motion.vel).max(),
            np.abs(trajectory.ang_vel[1:] - motion.ang_vel).max(),
            np.abs(rotation - quat_to_matrix(motion.quat.reshape(-1, 4))).max(),
        ]
    )


@pytest.mark.parametrize("build", [world_root_tree, fixed_root_tree, floating_root_tree])
def test_every_joint_type_follows_the_joint_space_reference_and_holds(build):
    errors = []
    for dt in (DT, DT / 2):
        scene, trajectory = recorded(build().model_copy(update={"dt": dt}))
        for stated, observed in (
            ("velocity", trajectory.vel),
            ("angular_velocity", trajectory.ang_vel),
        ):
            wanted = [getattr(body, stated) for body in scene.scenario.bodies]
            assert np.abs(observed[0] - wanted).max() < 1e-12, stated
        motion = reference(scene, trajectory)
        errors.append(errors_against(motion, trajectory))
        moved = np.abs(motion.pos[-1] - motion.pos[0]).max()
        assert moved > 20 * POSITION_TOLERANCE, moved  # the test sees a real motion
        separation, misalignment, _ = joint_violations(
            scene.joint_tree, trajectory.pos, quat_to_matrix(trajectory.quat)
        )
        assert separation.max() < JOINT_TOLERANCE, separation.max()
        assert misalignment.max() < JOINT_TOLERANCE, misalignment.max()
    assert errors[0][0] < POSITION_TOLERANCE, errors
    ratio = errors[1] / errors[0]  # positions, velocities, spins, orientations
    assert np.all((FIRST_ORDER[0] < ratio) & (ratio < FIRST_ORDER[1])), ratio


SPIN = 2.0
"""rad/s: the damped wheel's initial rate."""

WHEEL_DAMPING = 0.5
"""N·m·s/rad on a wheel of unit moment about its hinge: the rate decays at 0.5 /s."""


def test_joint_damping_is_btmultibodys_explicit_torque():
    """A wheel (unit moment about its axle) on a damped hinge in zero gravity: ω_n = ω0 (1 -
    c dt / I)^n, the explicit Euler step of the torque -c ω (engines.md 2.7), and so within
    O(dt) of the exact exp(-c t / I)."""
    radius = math.sqrt(2.5)  # a 1 kg solid sphere of moment 2/5 m r² = 1
    scenario = _scenario(
        "damped_wheel",
        [_sphere("wheel", radius, (0.0, 0.0, 0.0), angular_velocity=[0.0, 0.0, SPIN])],
        [{"name": "axle", "type": "hinge", "parent": "world", "child": "wheel",
          "anchor": [0.0, 0.0, 0.0], "axis": [0.0, 0.0, 1.0], "damping": WHEEL_DAMPING}],
        gravity=(0.0, 0.0, 0.0),
    )  # fmt: skip
    _, trajectory = recorded(scenario)
    steps = np.rint(trajectory.t / DT)
    explicit = SPIN * (1.0 - WHEEL_DAMPING * DT) ** steps
    assert np.abs(trajectory.ang_vel[:, 0, 2] - explicit).max() < 1e-12
    exact = SPIN * np.exp(-WHEEL_DAMPING * trajectory.t)
    assert np.abs(trajectory.ang_vel[-1, 0, 2] - explicit[-1]) < 1e-12
    assert np.abs(trajectory.ang_vel[-1, 0, 2] - exact[-1]) > 1e-5  # first order, not exact


def contacts(adapter, a: str, b: str) -> int:
    """PyBullet's contact points between scene bodies ``a`` and ``b`` after the last step."""
    from validation.engines.pybullet.adapter import pybullet

    names = [body.name for body in adapter.scenario.bodies]
    i, j = names.index(a), names.index(b)
    return len(
        pybullet.getContactPoints(
            adapter.ids[i],
            adapter.ids[j],
            adapter.links[i],
            adapter.links[j],
            physicsClientId=adapter.client,
        )
    )


def test_a_joints_parent_and_child_never_touch_while_every_other_pair_does():
    """Big overlapping spheres: two pendulums from the world (one multibody, siblings), the
    second with a child, and a free ball dropped into the chain. Every overlapping pair has
    contact points after a step except the joints' parent-child pairs."""
    scenario = _scenario(
        "overlapping_chain",
        [
            _sphere("left", 0.3, (-0.25, 0.0, 1.0)),
            _sphere("right", 0.3, (0.25, 0.0, 1.0)),
            _sphere("below", 0.3, (0.1, 0.0, 0.6)),
            _sphere("ball", 0.3, (0.0, 0.0, 0.5)),
        ],
        [
            {"name": "a", "type": "hinge", "parent": "world", "child": "left",
             "anchor": [-0.25, 0.0, 1.5], "axis": [0.0, 1.0, 0.0]},
            {"name": "b", "type": "hinge", "parent": "world", "child": "right",
             "anchor": [0.25, 0.0, 1.5], "axis": [0.0, 1.0, 0.0]},
            {"name": "c", "type": "ball", "parent": "right", "child": "below",
             "anchor": [0.25, 0.0, 0.8]},
        ],
        duration=10 * DT,
    )  # fmt: skip
    adapter = create_adapter(parse_engine_spec(ENGINE))
    try:
        adapter.load(compile_scene(scenario))
        adapter.advance(1)
        assert contacts(adapter, "right", "below") == 0  # a joint's parent and child
        for pair in (("left", "right"), ("left", "below"), ("ball", "below"), ("ball", "left")):
            assert contacts(adapter, *pair) > 0, pair  # siblings, a cousin, a free body
    finally:
        adapter.close()


LIMIT = 0.205
"""rad or m: the upper limit, not a whole number of steps' travel from the start."""


@pytest.mark.parametrize(
    ("kind", "mass", "speed"),
    [("slider", 1.0, 3.0), ("hinge", 1000.0, 10.0)],  # a 1000 kg·m² wheel: Bullet's default
)  # limit force let it through (engines.md 2.5)
def test_a_limit_stops_its_joint_inelastically_within_a_steps_travel(kind, mass, speed):
    """A body on a limited joint in zero gravity, moving at ``speed`` toward ``LIMIT``: it
    passes the limit by less than one step's travel (the stop comes a step late, engines.md
    2.5), then rests there (e = 0: no bounce, no correction)."""
    motion = {"velocity": [0.0, 0.0, speed]} if kind == "slider" else {}
    motion |= {"angular_velocity": [0.0, 0.0, speed]} if kind == "hinge" else {}
    scenario = _scenario(
        "limited",
        [_sphere("bead", math.sqrt(2.5), (0.0, 0.0, 0.0), mass=mass, **motion)],
        [{"name": "joint", "type": kind, "parent": "world", "child": "bead",
          "anchor": [0.0, 0.0, 0.0], "axis": [0.0, 0.0, 1.0], "limits": [-0.1, LIMIT]}],
        duration=0.1,
        gravity=(0.0, 0.0, 0.0),
    )  # fmt: skip
    scene, trajectory = recorded(scenario)
    from validation.reference.articulated import joint_coordinates

    coordinate = joint_coordinates(
        scene.joint_tree, trajectory.pos, quat_to_matrix(trajectory.quat)
    )["joint"]
    rate = (trajectory.vel if kind == "slider" else trajectory.ang_vel)[:, 0, 2]
    assert LIMIT < coordinate.max() < LIMIT + speed * DT, coordinate.max()
    stopped = int(np.argmax(coordinate > LIMIT))
    assert np.abs(rate[stopped + 1 :]).max() < 1e-12, rate[stopped:]
    assert np.ptp(coordinate[stopped + 1 :]) < 1e-12


def joint_mismatches(scene) -> list:
    """What the parity gate finds between the joints PyBullet built for ``scene`` and the
    scene's (``joint_parity.compare_joints``, right after loading)."""
    from validation.engines.joint_parity import compare_joints

    adapter = create_adapter(parse_engine_spec(ENGINE))
    try:
        adapter.load(scene)
        return compare_joints(adapter, scene)
    finally:
        adapter.close()


def test_pybullet_reports_the_joints_it_built():
    """The parity gate's readback (``joint_report``) on a tree whose links' principal axes are
    not their body axes (a stated full inertia, a turned body), with an oblique hinge, a ball
    and a slider under a floating root: every type, anchor, axis and M(q0) entry is the
    scene's (``joint_parity.compare_joints``: no mismatch at 1e-9)."""

    tilted = [math.cos(0.3), 0.2, math.sin(0.3) * 0.8, 0.1]
    norm = math.sqrt(sum(c * c for c in tilted))
    full = [[0.02, 0.004, -0.003], [0.004, 0.03, 0.002], [-0.003, 0.002, 0.025]]
    scenario = _scenario(
        "reported",
        [
            _box("hub", (0.1, 0.1, 0.1), (0.0, 0.0, 1.0), mass=2.0, inertia=full),
            _box("flap", (0.2, 0.05, 0.02), (0.3, 0.1, 1.0), inertia=full,
                 orientation=[c / norm for c in tilted]),
            _sphere("bob", 0.05, (0.3, 0.1, 0.6), mass=0.5, inertia=full),
            _sphere("bead", 0.05, (0.0, 0.4, 1.0), mass=0.5),
        ],
        [
            {"name": "hinge", "type": "hinge", "parent": "hub", "child": "flap",
             "anchor": [0.1, 0.05, 1.0], "axis": [0.6, 0.0, 0.8]},
            {"name": "ball", "type": "ball", "parent": "flap", "child": "bob",
             "anchor": [0.3, 0.1, 0.8]},
            {"name": "slider", "type": "slider", "parent": "hub", "child": "bead",
             "anchor": [0.0, 0.2, 1.0], "axis": [0.0, 0.8, 0.6]},
        ],
    )  # fmt: skip
    assert joint_mismatches(compile_scene(scenario)) == []


LIBRARY = sorted((Path(__file__).resolve().parents[1] / "scenarios" / "joints").glob("*.yaml"))


@pytest.mark.parametrize("path", LIBRARY, ids=lambda p: p.stem)
def test_pybullets_joints_are_the_library_scenes(path):
    """The parity gate's readback on every library scene with joints: no mismatch."""
    from validation.scenario.load import load_scenario

    assert joint_mismatches(compile_scene(load_scenario(path))) == []
