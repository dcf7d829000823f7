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

from dataclasses import dataclass

import numpy as np
from pydrake.common.eigen_geometry import Quaternion
from pydrake.geometry import CollisionFilterDeclaration, GeometrySet
from pydrake.math import RigidTransform, RollPitchYaw, RotationMatrix
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
from validation.reference.rotation import quat_to_matrix

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


def pose(position, quat) -> RigidTransform:
    """A world pose from a position (3,) m and a quaternion w x y z (normalized here)."""
    q = np.asarray(quat, dtype=float)
    return RigidTransform(Quaternion(q / np.linalg.norm(q)), np.asarray(position, dtype=float))


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


def add_joints(
    plant, tree, bodies: list, gravity, limits: dict[str, tuple], placed=None, skip=()
) -> list:
    """Every stated joint of ``tree`` (parents first; the floating roots stay Drake's free
    bodies) on ``plant`` between the scene bodies' ``bodies`` (None for a fixed scene body,
    which is world geometry at its pose; ``placed``: each body's frame in its Drake body's,
    identity when None, a native model's ``in_link``); the Drake joints in the tree's order,
    but for the joints named in ``skip`` (a native model's own). ``gravity`` (3,) m/s², world
    frame, sets a ball's axes (``ball_axes``); ``limits`` are the stated ones by joint name
    (hinge and slider)."""
    placed = placed or [RigidTransform()] * len(bodies)
    added = []
    for joint in tree.joints:
        if joint.type == "free" or joint.name in skip:
            continue
        parent_body, parent_pose = _parent(plant, tree, bodies, joint.parent, placed)
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
                placed[joint.child].multiply(
                    RigidTransform(
                        RotationMatrix.ProjectToRotationMatrix(back @ axes),
                        -back @ np.asarray(joint.offset, dtype=float),
                    )
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


def _parent(plant, tree, bodies: list, parent: int, placed) -> tuple[object, RigidTransform]:
    """(Drake body, the parent's frame in it): the world's own frame, a fixed scene body's
    pose on the world body, a moving body's frame in its Drake body (``placed``)."""
    if parent == WORLD:
        return plant.world_body(), RigidTransform()
    if bodies[parent] is None:
        rotation = RotationMatrix.ProjectToRotationMatrix(np.asarray(tree.fixed_rot[parent]))
        return plant.world_body(), RigidTransform(rotation, np.asarray(tree.fixed_pos[parent]))
    return bodies[parent], placed[parent]


def filter_jointed_pairs(scene_graph, tree, geometry: dict[int, tuple]) -> int:
    """Exclude contact between each joint's parent and child body (``geometry``: scene object
    -> (Drake body, pose, shape, geometry id), as the adapter registered them): their shapes
    meet at the anchor by construction. Drake's own adjacency filter misses a joint to a fixed
    scene body (world geometry to Drake). A native model's bodies have no entry (their
    geometry is the file's: ``models.filter_model_geometry``). The number of pairs filtered."""
    declaration = CollisionFilterDeclaration()
    pairs = 0
    for joint in tree.joints:
        if joint.type == "free" or not {joint.parent, joint.child} <= geometry.keys():
            continue
        declaration.ExcludeBetween(
            GeometrySet([geometry[joint.parent][3]]), GeometrySet([geometry[joint.child][3]])
        )
        pairs += 1
    scene_graph.collision_filter_manager().Apply(declaration)
    return pairs


@dataclass(frozen=True)
class Placement:
    """Where the scene's bodies and joints are in Drake: ``bodies`` (n,) the Drake body of each
    scene body (None for a fixed one), ``placed`` (n,) each scene body's frame (its centre of
    mass, its axes) in that Drake body's frame (identity but for a native model's links),
    ``joints`` scene joint name -> Drake joint."""

    bodies: list
    placed: list
    joints: dict

    def point(self, k: int) -> np.ndarray:
        """(3,) m: scene body k's centre of mass in its Drake body's frame."""
        return np.asarray(self.placed[k].translation(), dtype=float)


def joint_velocities(
    plant, context, placement: Placement, moving, stated_velocities, known=None
) -> np.ndarray:
    """(nv,) the plant's generalized velocities from each moving body's stated ``(v, ω)``:
    the least-squares v of ``J v = (ω, v)`` stacked over the moving bodies, ``J`` Drake's own
    ``CalcJacobianSpatialVelocity`` of each body's centre of mass, world frame, at the current
    configuration; exact for velocities the joints allow (the scene's checks refuse others).
    ``known`` (nv,) bool: velocities already set in ``context`` (a native model's), kept, and
    the bodies they move left out of the fit."""
    world = plant.world_frame()
    current = plant.GetVelocities(context)
    known = np.zeros(current.size, dtype=bool) if known is None else known
    rows, targets = [], []
    for k in moving:
        jacobian = plant.CalcJacobianSpatialVelocity(
            context,
            JacobianWrtVariable.kV,
            placement.bodies[k].body_frame(),
            placement.point(k),
            world,
            world,
        )
        if not np.any(jacobian[:, ~known]):
            continue  # moved by the known velocities alone
        velocity, angular = stated_velocities[k]
        rows.append(jacobian)
        targets += [np.asarray(angular, dtype=float), np.asarray(velocity, dtype=float)]
    if not rows:
        return current
    stacked = np.concatenate(rows)
    rest = np.concatenate(targets) - stacked[:, known] @ current[known]
    solved = current.copy()
    solved[~known] = np.linalg.lstsq(stacked[:, ~known], rest, rcond=None)[0]
    return solved


def body_states(plant, context, placement: Placement, moving, fixed_pose) -> tuple:
    """Every scene body's (pos, quat, vel, ang_vel) at the state of ``context`` through Drake's
    own kinematics: each Drake body's pose and spatial velocity (``EvalBodyPoseInWorld``,
    ``EvalBodySpatialVelocityInWorld``) carried to the scene body's frame (``placement``);
    fixed bodies at their ``fixed_pose`` (positions (n, 3), quaternions (n, 4)) and at rest."""
    pos, quat = fixed_pose[0].copy(), fixed_pose[1].copy()
    vel, ang_vel = np.zeros_like(pos), np.zeros_like(pos)
    for k in moving:
        link = plant.EvalBodyPoseInWorld(context, placement.bodies[k])
        where = link.multiply(placement.placed[k])
        motion = plant.EvalBodySpatialVelocityInWorld(context, placement.bodies[k]).Shift(
            link.rotation().multiply(placement.point(k))
        )
        pos[k] = where.translation()
        quat[k] = where.rotation().ToQuaternion().wxyz()
        vel[k], ang_vel[k] = motion.translational(), motion.rotational()
    return pos, quat, vel, ang_vel


def kinematic_states(plant, placement: Placement, moving, times, raw, fixed_pose) -> Trajectory:
    """Every scene body's state for the raw plant states ``raw (s, nq + nv)`` (``body_states``
    on a scratch context). A non-finite raw state (an explosion; Drake refuses to take it)
    gives non-finite moving bodies' states."""
    samples, n = raw.shape[0], fixed_pose[0].shape[0]
    pos, quat = np.zeros((samples, n, 3)), np.zeros((samples, n, 4))
    vel, ang_vel = np.zeros((samples, n, 3)), np.zeros((samples, n, 3))
    scratch = plant.CreateDefaultContext()
    for s in range(samples):
        if not np.isfinite(raw[s]).all():
            pos[s], quat[s] = fixed_pose
            for array in (pos, quat, vel, ang_vel):
                array[s, moving] = np.nan
            continue
        plant.SetPositionsAndVelocities(scratch, raw[s])
        pos[s], quat[s], vel[s], ang_vel[s] = body_states(
            plant, scratch, placement, moving, fixed_pose
        )
    return Trajectory(np.asarray(times, dtype=float), pos, quat, vel, ang_vel)


def joint_report(plant, context, scenario, tree, placement: Placement) -> JointReport:
    """The joints Drake holds, at the state of ``context`` (t = 0 after loading), in the
    scene's order: each one's type (``type_name``), anchor (the origin of its frame M in the
    world, ``CalcPoseInWorld``: the scene's anchor is the child's joint frame at t = 0, which
    a native model's slider has moved from F by its initial position) and axis
    (``revolute_axis`` or ``translation_axis``, F's, in the world); limits relative to the
    coordinate at t = 0 (``default_positions``; NaN rows where unlimited or not a hinge or
    slider), damping (``default_damping_vector``) and armature (the reflected inertia of an
    actuator on the joint, ``joint_armature``); and Drake's ``CalcMassMatrix`` carried into
    the joint tree's coordinates, ``Tᵀ M T`` with T mapping the tree's ν to Drake's v
    (``tree_velocities``)."""
    types, anchors, axes, limits, damping = [], [], [], [], []
    armature = joint_armature(plant)
    for stated in scenario.joints:
        joint = placement.joints[stated.name]
        where = joint.frame_on_parent().CalcPoseInWorld(context)
        types.append(SCENE_WORDS[joint.type_name()])
        anchors.append(joint.frame_on_child().CalcPoseInWorld(context).translation())
        reader = AXIS_READERS.get(joint.type_name())
        axes.append(np.zeros(3) if reader is None else where.rotation().multiply(reader(joint)))
        limits.append(_limits(joint) if reader is not None else (np.nan, np.nan))
        damping.append(float(np.max(joint.default_damping_vector(), initial=0.0)))
    change, _ = tree_velocities(plant, context, tree, placement)
    return JointReport(
        tuple(types),
        np.array(anchors, dtype=float).reshape(-1, 3),
        np.array(axes, dtype=float).reshape(-1, 3),
        change.T @ plant.CalcMassMatrix(context) @ change,
        limits=np.array(limits, dtype=float).reshape(-1, 2),
        damping=np.array(damping, dtype=float),
        armature=np.array([armature.get(placement.joints[j.name].index(), 0.0)
                           for j in scenario.joints], dtype=float),
    )  # fmt: skip


def _limits(joint) -> tuple[float, float]:
    """(lower, upper) of a one-coordinate joint relative to its coordinate at t = 0; NaN when
    Drake holds it unlimited (±inf)."""
    start = float(joint.default_positions()[0])
    lower, upper = float(joint.position_lower_limits()[0]), float(joint.position_upper_limits()[0])
    if not (np.isfinite(lower) or np.isfinite(upper)):
        return (np.nan, np.nan)
    return (lower - start, upper - start)


def joint_armature(plant) -> dict:
    """Drake joint index -> the reflected inertia (rotor inertia × gear ratio², kg·m² or kg)
    of the actuators on it (``JointActuator.default_reflected_inertia``): what Drake adds to
    that joint's diagonal of M (its armature)."""
    found: dict = {}
    for index in plant.GetJointActuatorIndices():
        actuator = plant.get_joint_actuator(index)
        joint = actuator.joint().index()
        found[joint] = found.get(joint, 0.0) + float(actuator.default_reflected_inertia())
    return found


def tree_velocities(plant, context, tree, placement: Placement) -> tuple[np.ndarray, object]:
    """(T (nv Drake, nv tree), drift (ν -> (nv Drake,))): Drake's v = T ν of the joint tree's
    ν at the configuration of ``context``, and Ṫ ν. A hinge's or slider's rate is Drake's as it
    is; a ball's spin relative to its parent in the parent's frame is Drake's ``w_FM`` in F
    after R_PFᵀ (F's axes are fixed in the parent: ``frame_axes``); a floating root's (v, ω),
    world frame, at its centre of mass is Drake's (ω, v) at the Drake body's origin: v_o =
    v - ω × r with r the centre seen from that origin (0 unless a native model's link), so
    T depends on q and Ṫ ν = (0, -ω × (ω × r))."""
    change = np.zeros((plant.num_velocities(), tree.nv))
    lever = []  # (velocity start in Drake's v, ω columns of the tree, r world)
    for joint in tree.joints:
        start, column = None, joint.v_slice.start
        if joint.type == "free":
            body = placement.bodies[joint.child]
            start = body.floating_velocities_start_in_v()
            r = (
                plant.EvalBodyPoseInWorld(context, body)
                .rotation()
                .multiply(placement.point(joint.child))
            )
            change[start : start + 3, column + 3 : column + 6] = np.eye(3)
            change[start + 3 : start + 6, column : column + 3] = np.eye(3)
            change[start + 3 : start + 6, column + 3 : column + 6] = _skew(r)
            lever.append((start, slice(column + 3, column + 6), r))
        elif joint.type in AXIS_TYPES:
            change[placement.joints[joint.name].velocity_start(), column] = 1.0
        elif joint.type == "ball":
            drake_joint = placement.joints[joint.name]
            start = drake_joint.velocity_start()
            axes = _parent_axes(tree, placement, joint, drake_joint)
            change[start : start + 3, column : column + 3] = axes.T

    def drift(nu: np.ndarray) -> np.ndarray:
        rate = np.zeros(plant.num_velocities())
        for start, spin, r in lever:
            omega = nu[spin]
            rate[start + 3 : start + 6] = -np.cross(omega, np.cross(omega, r))
        return rate

    return change, drift


def _parent_axes(tree, placement: Placement, joint, drake_joint) -> np.ndarray:
    """(3, 3) A: the axes of a ball's frame F in its parent scene body's frame (Drake holds F
    in the parent's Drake body: the world's for a fixed scene body, at its pose)."""
    in_body = drake_joint.frame_on_parent().GetFixedPoseInBodyFrame().rotation().matrix()
    parent_in_body = np.eye(3)  # the parent's axes in its Drake body's frame
    if joint.parent != WORLD and placement.bodies[joint.parent] is None:
        parent_in_body = tree.fixed_rot[joint.parent]
    elif joint.parent != WORLD:
        parent_in_body = placement.placed[joint.parent].rotation().matrix()
    return parent_in_body.T @ in_body


def set_tree_positions(plant, context, tree, placement: Placement, start, q) -> None:
    """``context`` at the joint tree's configuration ``q`` (relative to t = 0): Drake's
    positions ``start`` (those at t = 0) plus each hinge's or slider's coordinate; a ball's Q
    (parent's frame) as Drake's roll-pitch-yaw of R_FM = Aᵀ Q A, A F's axes in the parent's
    frame (F and M coincide at t = 0); a floating root's centre and quaternion as its Drake
    body's pose (the scene body's frame carried back through ``placement``)."""
    positions = np.array(start, dtype=float)
    for joint in tree.joints:
        if joint.type in AXIS_TYPES:
            positions[placement.joints[joint.name].position_start()] += q[joint.q_slice][0]
    plant.SetPositions(context, positions)
    for joint in tree.joints:
        coordinates = q[joint.q_slice]
        if joint.type == "ball":
            drake_joint = placement.joints[joint.name]
            axes = _parent_axes(tree, placement, joint, drake_joint)
            turned = axes.T @ quat_to_matrix(coordinates) @ axes
            drake_joint.set_angles(
                context,
                RollPitchYaw(RotationMatrix.ProjectToRotationMatrix(turned)).vector(),
            )
        elif joint.type == "free":
            plant.SetFreeBodyPose(
                context,
                placement.bodies[joint.child],
                pose(coordinates[:3], coordinates[3:]).multiply(
                    placement.placed[joint.child].inverse()
                ),
            )


def _skew(v: np.ndarray) -> np.ndarray:
    """(3, 3) the matrix of ``v ×``."""
    return np.array([[0.0, -v[2], v[1]], [v[2], 0.0, -v[0]], [-v[1], v[0], 0.0]])
