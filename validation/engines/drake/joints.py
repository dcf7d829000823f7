"""A scene's joints in Drake: the joint tree (``CompiledScene.joint_tree``) as Drake joints, the
collision filters between each joint's two bodies, the initial joint velocities and the body
states read back through Drake's own kinematics (docs/engines-drake.md 9).

Each tree joint becomes one Drake joint between two ``FixedOffsetFrame`` s that coincide at
t = 0, so every coordinate is 0 there: the parent's frame F at the anchor with axes A in the
parent's frame (``frame_axes``; on the world body at a fixed scene
body's pose, for a joint to it), the child's frame M at the child's anchor ``-R0ᵀ offset``
with the axes ``R0ᵀ A`` (F's axes seen from the child at q = 0). A hinge's or slider's axis is
the tree's (parent frame) seen in F, ``Aᵀ axis``. A body that is no joint's
child stays a free body (Drake's own floating joint, added at ``Finalize``).
"""

from __future__ import annotations

import numpy as np
from pydrake.geometry import CollisionFilterDeclaration, GeometrySet
from pydrake.math import RigidTransform, RotationMatrix
from pydrake.multibody.tree import (
    BallRpyJoint,
    FixedOffsetFrame,
    JacobianWrtVariable,
    PrismaticJoint,
    RevoluteJoint,
    WeldJoint,
)

from validation.engines.base import JointReport, Trajectory
from validation.reference.articulated import AXIS_TYPES, WORLD

DRAKE_JOINTS = {
    "hinge": lambda name, f, m, axis, limits, damping: RevoluteJoint(
        name, f, m, axis, *limits, damping
    ),
    "slider": lambda name, f, m, axis, limits, damping: PrismaticJoint(
        name, f, m, axis, *limits, damping
    ),
    # Drake has no quaternion ball joint: roll-pitch-yaw coordinates, singular at pitch ±π/2
    "ball": lambda name, f, m, axis, limits, damping: BallRpyJoint(name, f, m, damping),
    "fixed": lambda name, f, m, axis, limits, damping: WeldJoint(name, f, m, RigidTransform()),
}
"""Tree joint type -> its Drake joint between frames F (parent) and M (child); the axis in F,
the position limits (rad or m from t = 0, where the coordinate is 0), damping in N·m·s/rad or
N·s/m (Drake's viscous joint damping). Only the discrete plant enforces the limits (its SAP
solver, as constraints); the continuous plant ignores them (engines-drake.md 9)."""

SCENE_WORDS = {"revolute": "hinge", "prismatic": "slider", "ball_rpy": "ball", "weld": "fixed"}
"""Drake's ``Joint.type_name()`` -> the scene's joint type."""

AXIS_READERS = {
    "revolute": lambda joint: joint.revolute_axis(),
    "prismatic": lambda joint: joint.translation_axis(),
}
"""Drake joint type -> its axis in its frame F (the joints with an axis)."""

UNLIMITED = (-np.inf, np.inf)
"""The limits of a joint that states none (Drake's own default)."""

SHORT = 1e-9
"""Relative: a vector shorter than this (an anchor at the child's centre, no gravity, a
direction along gravity's) sets no axis of a ball's frame."""


def ball_axes(joint, gravity: np.ndarray, turn: np.ndarray) -> np.ndarray:
    """(3, 3) the axes of a ball joint's frame F in its parent's frame (columns x, y, z), from
    ``gravity`` and the axis ``turn`` about which the parent turns (its hinge's; zeros if none),
    both in the parent's axes at t = 0. A ``BallRpyJoint`` is singular at pitch ±π/2, where
    M's x axis turns onto F's z; rotations about F's x (roll) or z (yaw) alone never get there.
    So z is the parent's hinge axis (the child turns relative to a hinged parent mostly about
    it), or else normal to gravity and the child's centre seen from the anchor (a swing from
    rest in that vertical plane); x is along gravity (normal to z), so that a spin of the child
    about the vertical is a roll (engines-drake.md 9)."""
    offset = np.asarray(joint.offset, dtype=float)
    if np.any(turn):
        z = turn
        x = _unit(_normal_part(gravity, z), _unit(_normal_part(offset, z), _normal_to(z)))
    else:
        x = _unit(gravity, _unit(offset, np.array([1.0, 0.0, 0.0])))
        z = _unit(np.cross(x, offset), _normal_to(x))
    return np.column_stack([x, np.cross(z, x), z])


def _normal_part(vector: np.ndarray, unit: np.ndarray) -> np.ndarray:
    """``vector`` less its component along ``unit``."""
    return vector - float(vector @ unit) * unit


def _unit(vector: np.ndarray, otherwise: np.ndarray) -> np.ndarray:
    """``vector`` made unit, or ``otherwise`` when it is (relatively) too short."""
    length = float(np.linalg.norm(vector))
    return vector / length if length > SHORT else otherwise


def _normal_to(vector: np.ndarray) -> np.ndarray:
    """A unit vector normal to the unit ``vector``."""
    trial = np.eye(3)[int(np.argmin(np.abs(vector)))]
    return _unit(np.cross(vector, trial), np.array([1.0, 0.0, 0.0]))


def frame_axes(joint, tree, gravity: np.ndarray) -> np.ndarray:
    """(3, 3) the axes of a joint's frame F in its parent's frame: a ball's ``ball_axes``
    (gravity, world frame, seen in the parent's axes at t = 0; the parent's hinge axis in its
    own frame, R0ᵀ u, when a hinge holds the parent), the parent's own for every other joint."""
    if joint.type != "ball":
        return np.eye(3)
    turn = np.zeros(3)
    if joint.parent == WORLD:
        rotation = np.eye(3)
    else:
        rotation = tree.fixed_rot[joint.parent]
        held_by = next((j for j in tree.joints if j.child == joint.parent), None)
        if held_by is not None and held_by.type == "hinge":
            turn = np.asarray(held_by.rotation).T @ np.asarray(held_by.axis, dtype=float)
    return ball_axes(joint, rotation.T @ np.asarray(gravity, dtype=float), turn)


def add_joints(plant, tree, bodies: list, gravity, limits: dict[str, tuple]) -> list:
    """Every stated joint of ``tree`` (parents first; the floating roots stay Drake's free
    bodies) on ``plant`` between the scene bodies' ``bodies`` (None for a fixed scene body,
    which is world geometry at its pose); the Drake joints in the tree's order. ``gravity``
    (3,) m/s², world frame, sets a ball's axes (``ball_axes``); ``limits`` are the stated
    ones by joint name (hinge and slider)."""
    added = []
    for joint in tree.joints:
        if joint.type == "free":
            continue
        parent_body, parent_pose = _parent(plant, tree, bodies, joint.parent)
        axes = frame_axes(joint, tree, gravity)
        on_parent = plant.AddFrame(
            FixedOffsetFrame(
                f"{joint.name}/parent",
                parent_body.body_frame(),
                parent_pose.multiply(
                    RigidTransform(
                        RotationMatrix.ProjectToRotationMatrix(axes),
                        np.asarray(joint.anchor, dtype=float),
                    )
                ),
            )
        )
        back = np.asarray(joint.rotation, dtype=float).T
        on_child = plant.AddFrame(
            FixedOffsetFrame(
                f"{joint.name}/child",
                bodies[joint.child].body_frame(),
                RigidTransform(
                    RotationMatrix.ProjectToRotationMatrix(back @ axes),
                    -back @ np.asarray(joint.offset, dtype=float),
                ),
            )
        )
        drake_joint = DRAKE_JOINTS[joint.type](
            joint.name,
            on_parent,
            on_child,
            axes.T @ joint.axis,
            limits.get(joint.name, UNLIMITED),
            joint.damping,
        )
        added.append(plant.AddJoint(drake_joint))
    return added


def _parent(plant, tree, bodies: list, parent: int) -> tuple[object, RigidTransform]:
    """(Drake body, the parent's frame in it): the world's own frame, a fixed scene body's
    pose on the world body, a moving body's own frame."""
    if parent == WORLD:
        return plant.world_body(), RigidTransform()
    if bodies[parent] is None:
        rotation = RotationMatrix.ProjectToRotationMatrix(np.asarray(tree.fixed_rot[parent]))
        return plant.world_body(), RigidTransform(rotation, np.asarray(tree.fixed_pos[parent]))
    return bodies[parent], RigidTransform()


def filter_jointed_pairs(scene_graph, tree, geometry: dict[int, tuple]) -> int:
    """Exclude contact between each joint's parent and child body (``geometry``: scene object
    -> (Drake body, pose, shape, geometry id), as the adapter registered them): their shapes
    meet at the anchor by construction. Drake's own adjacency filter misses a joint to a fixed
    scene body (world geometry to Drake). The number of pairs filtered."""
    declaration = CollisionFilterDeclaration()
    pairs = 0
    for joint in tree.joints:
        if joint.type == "free" or joint.parent == WORLD:
            continue
        declaration.ExcludeBetween(
            GeometrySet([geometry[joint.parent][3]]), GeometrySet([geometry[joint.child][3]])
        )
        pairs += 1
    scene_graph.collision_filter_manager().Apply(declaration)
    return pairs


def joint_velocities(plant, context, bodies: list, moving, stated_velocities) -> np.ndarray:
    """(nv,) the plant's generalized velocities from each moving body's stated ``(v, ω)``:
    the least-squares v of ``J v = (ω, v)`` stacked over the moving bodies, ``J`` Drake's own
    ``CalcJacobianSpatialVelocity`` of each body's frame origin (its centre of mass), world
    frame, at the current configuration; exact for velocities the joints allow (the scene's
    checks refuse others)."""
    world = plant.world_frame()
    rows, targets = [], []
    for k in moving:
        rows.append(
            plant.CalcJacobianSpatialVelocity(
                context,
                JacobianWrtVariable.kV,
                bodies[k].body_frame(),
                np.zeros(3),
                world,
                world,
            )
        )
        velocity, angular = stated_velocities[k]
        targets += [np.asarray(angular, dtype=float), np.asarray(velocity, dtype=float)]
    if not rows:
        return np.zeros(plant.num_velocities())
    return np.linalg.lstsq(np.concatenate(rows), np.concatenate(targets), rcond=None)[0]


def kinematic_states(plant, bodies: list, moving, times, raw, fixed_pose) -> Trajectory:
    """Every scene body's state for the raw plant states ``raw (s, nq + nv)`` through Drake's
    own kinematics on a scratch context (``EvalBodyPoseInWorld``,
    ``EvalBodySpatialVelocityInWorld`` of each body frame: its centre of mass); fixed bodies at
    their ``fixed_pose`` (positions (n, 3), quaternions (n, 4)) and at rest. A non-finite raw
    state (an explosion; Drake refuses to take it) gives non-finite moving bodies' states."""
    samples, n = raw.shape[0], fixed_pose[0].shape[0]
    pos = np.repeat(fixed_pose[0][None], samples, axis=0)
    quat = np.repeat(fixed_pose[1][None], samples, axis=0)
    vel, ang_vel = np.zeros((samples, n, 3)), np.zeros((samples, n, 3))
    scratch = plant.CreateDefaultContext()
    for s in range(samples):
        if not np.isfinite(raw[s]).all():
            for array in (pos, quat, vel, ang_vel):
                array[s, moving] = np.nan
            continue
        plant.SetPositionsAndVelocities(scratch, raw[s])
        for k in moving:
            where = plant.EvalBodyPoseInWorld(scratch, bodies[k])
            motion = plant.EvalBodySpatialVelocityInWorld(scratch, bodies[k])
            pos[s, k] = where.translation()
            quat[s, k] = where.rotation().ToQuaternion().wxyz()
            vel[s, k], ang_vel[s, k] = motion.translational(), motion.rotational()
    return Trajectory(np.asarray(times, dtype=float), pos, quat, vel, ang_vel)


def joint_report(plant, context, scenario, tree, bodies: list) -> JointReport:
    """The joints Drake holds, at the state of ``context`` (t = 0 after loading), in the
    scene's order: each one's type (``type_name``), anchor (the origin of its frame F in the
    world, ``CalcPoseInWorld``) and axis (``revolute_axis`` or ``translation_axis``, F's, in
    the world); and Drake's ``CalcMassMatrix`` carried into the joint tree's coordinates,
    ``Tᵀ M T`` with T mapping the tree's ν to Drake's v (``tree_velocities``)."""
    types, anchors, axes = [], [], []
    for stated in scenario.joints:
        joint = plant.GetJointByName(stated.name)
        where = joint.frame_on_parent().CalcPoseInWorld(context)
        types.append(SCENE_WORDS[joint.type_name()])
        anchors.append(where.translation())
        reader = AXIS_READERS.get(joint.type_name())
        axes.append(np.zeros(3) if reader is None else where.rotation().multiply(reader(joint)))
    change = tree_velocities(plant, tree, bodies)
    return JointReport(
        tuple(types),
        np.array(anchors, dtype=float).reshape(-1, 3),
        np.array(axes, dtype=float).reshape(-1, 3),
        change.T @ plant.CalcMassMatrix(context) @ change,
    )


def tree_velocities(plant, tree, bodies: list) -> np.ndarray:
    """(nv Drake, nv tree) T: Drake's v of the joint tree's ν. A hinge's or slider's rate is
    Drake's as it is; a ball's spin relative to its parent in the parent's frame is Drake's
    ``w_FM`` in F after R_PFᵀ (F's axes are fixed in the parent: ``frame_axes``); a floating
    root's (v, ω), world frame, is Drake's (ω, v)."""
    change = np.zeros((plant.num_velocities(), tree.nv))
    for joint in tree.joints:
        start, column = None, joint.v_slice.start
        if joint.type == "free":
            start = bodies[joint.child].floating_velocities_start_in_v()
            change[start : start + 3, column + 3 : column + 6] = np.eye(3)
            change[start + 3 : start + 6, column : column + 3] = np.eye(3)
        elif joint.type in AXIS_TYPES:
            change[plant.GetJointByName(joint.name).velocity_start(), column] = 1.0
        elif joint.type == "ball":
            drake_joint = plant.GetJointByName(joint.name)
            in_body = drake_joint.frame_on_parent().GetFixedPoseInBodyFrame().rotation().matrix()
            parent_in_body = (
                tree.fixed_rot[joint.parent]
                if joint.parent != WORLD and bodies[joint.parent] is None
                else np.eye(3)
            )
            start = drake_joint.velocity_start()
            change[start : start + 3, column : column + 3] = (parent_in_body.T @ in_body).T
    return change
