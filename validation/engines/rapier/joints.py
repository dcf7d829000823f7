"""The scene's joints in Rapier: the joint tree (``CompiledScene.joint_tree``) as multibody
joints (reduced coordinates, the default) or impulse joints (constraints between free rigid
bodies, ``joints=impulse``).

Every joint is a ``GenericJoint`` whose locked axes make it a hinge, slider, ball or weld, placed
by two full frames so that the child's pose at joint coordinate 0 is its stated pose (Rapier's
multibody places a link by its frames alone, engines-rapier.md 9):

    frame1 = (a_P, F)            in the parent's body frame (the world's for ``WORLD``)
    frame2 = (-R0ᵀ r0, R0ᵀ F)    in the child's body frame

with ``F`` a rotation taking Rapier's joint x axis to the scene's axis ``u_P`` (``axis_frame``;
identity for a ball or a weld). Then ``R_C = R_P F Rot_x(θ) Fᵀ R0 = R_P Rot(u_P, θ) R0`` and the child's
anchor meets the parent's, the reference's kinematics (``validation.reference.articulated``)
with the same sign of θ and s: a scene's limits go to Rapier as they are.

A joint to the world hangs from one fixed body at the world origin, without a collider
(``JointBuilder._world_body``), never observed. The parent and the child of a joint never collide
(``contacts_enabled(False)``); every other pair, in one multibody or not, keeps its contacts.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import rapier3d

from validation.engines.base import JointReport
from validation.engines.frames import matrix_to_quat
from validation.engines.rapier.readback import rotation_matrix, world_inertia
from validation.reference.articulated import AXIS_TYPES, WORLD, Joint, JointTree

X = np.array([1.0, 0.0, 0.0])
"""Rapier's joint axis in the joint frame (a revolute's ``ANG_X``, a prismatic's ``LIN_X``)."""


@dataclass(frozen=True)
class JointType:
    """How a scene joint type is a ``GenericJoint``: its locked axes and its free axes (where
    damping and limits act)."""

    locked: rapier3d.JointAxesMask
    free: tuple[rapier3d.JointAxis, ...]


JOINT_TYPES: dict[str, JointType] = {
    "hinge": JointType(rapier3d.JointAxesMask.LOCKED_REVOLUTE_AXES, (rapier3d.JointAxis.ANG_X,)),
    "slider": JointType(rapier3d.JointAxesMask.LOCKED_PRISMATIC_AXES, (rapier3d.JointAxis.LIN_X,)),
    "ball": JointType(
        rapier3d.JointAxesMask.LOCKED_SPHERICAL_AXES,
        (rapier3d.JointAxis.ANG_X, rapier3d.JointAxis.ANG_Y, rapier3d.JointAxis.ANG_Z),
    ),
    "fixed": JointType(rapier3d.JointAxesMask.LOCKED_FIXED_AXES, ()),
}
"""Scene joint type -> Rapier's axes (the joint frame's x is the scene's axis)."""

LOCKED_TYPES = {kind.locked.bits: name for name, kind in JOINT_TYPES.items()}
"""A ``GenericJoint``'s locked axes (bits) -> the scene's joint type."""


def _rotation(matrix: np.ndarray) -> rapier3d.Rotation3:
    w, x, y, z = (float(c) for c in matrix_to_quat(matrix))
    return rapier3d.Rotation3(w, x, y, z)


def _isometry(translation: np.ndarray, matrix: np.ndarray) -> rapier3d.Isometry3:
    return rapier3d.Isometry3(tuple(float(t) for t in translation), _rotation(matrix))


def axis_frame(axis: np.ndarray) -> np.ndarray:
    """(3, 3) a rotation whose first column is the unit ``axis`` (identity for no axis): the
    axis, the coordinate axis after its largest component made perpendicular to it, and their
    cross product. For an axis along ±x, ±y or ±z this is a signed permutation whose
    quaternion float32 holds exactly (components 0, ±½, ±1: a y axis is the 120° turn
    (½, ½, ½, ½)); the shortest turn from x, a 90° one, is √½ each, rounded, and its rounding
    accumulates down a chain (engines-rapier.md 9)."""
    if not np.any(axis):
        return np.eye(3)
    following = np.roll(np.eye(3), -1, axis=0)[int(np.argmax(np.abs(axis)))]
    across = following - (following @ axis) * axis
    across /= np.linalg.norm(across)
    return np.column_stack([axis, across, np.cross(axis, across)])


def joint_frames(joint: Joint) -> tuple[rapier3d.Isometry3, rapier3d.Isometry3]:
    """(frame1 in the parent's body frame, frame2 in the child's) of one tree joint (module
    docstring)."""
    frame = axis_frame(joint.axis)
    back = joint.rotation.T
    return _isometry(joint.anchor, frame), _isometry(-back @ joint.offset, back @ frame)


def generic_joint(
    joint: Joint, limits: tuple[float, float] | None, motor_damping: bool
) -> rapier3d.GenericJoint:
    """The ``GenericJoint`` of one tree joint: its frames, no contact between its two bodies,
    the scene's limits on its free axis; with ``motor_damping`` (impulse joints) its damping
    as a velocity motor of target 0 on each free axis, force-based (a torque or force
    ``-c · rate``: Rapier's way to damp an impulse joint, engines-rapier.md 9)."""
    kind = JOINT_TYPES[joint.type]
    frame1, frame2 = joint_frames(joint)
    builder = (
        rapier3d.GenericJointBuilder(kind.locked)
        .local_frame1(frame1)
        .local_frame2(frame2)
        .contacts_enabled(False)
    )
    if limits is not None:
        builder = builder.limits(kind.free[0], float(limits[0]), float(limits[1]))
    if motor_damping and joint.damping > 0.0:
        for axis in kind.free:
            builder = builder.motor_velocity(axis, 0.0, float(joint.damping))
            builder = builder.motor_model(axis, rapier3d.MotorModel.FORCE_BASED)
    return builder.build()


class JointBuilder:
    """Inserts a scene's joint tree into a ``PhysicsWorld`` as one kind of Rapier joint, sets
    what Rapier's joint state needs (the multibodies' damping and initial velocities) and reads
    the joints back.

    Attributes:
        kind: one of ``declaration.JOINT_KINDS``.
        built: scene joint name -> (its handle in Rapier's joint set, its parent's body handle).
    """

    def __init__(self, world, kind: str):
        self.world = world
        self.kind = kind
        self.world_body = None
        self.built: dict[str, tuple] = {}

    def build(
        self,
        tree: JointTree,
        handles: list,
        limits: dict[str, tuple[float, float] | None],
        velocities: tuple[np.ndarray, np.ndarray],
    ) -> None:
        """Every stated joint of ``tree`` between the bodies ``handles`` (scenario order),
        parents first; for multibodies, then their damping and their generalized velocities
        from the bodies' stated ``velocities`` (v (n, 3), ω (n, 3))."""
        impulse = self.kind == "impulse"
        inserted = []
        for joint in tree.joints:
            if joint.type == "free":
                continue
            parent = self._world_body() if joint.parent == WORLD else handles[joint.parent]
            data = generic_joint(joint, limits.get(joint.name), motor_damping=impulse)
            if impulse:
                handle = self.world.impulse_joints.insert(parent, handles[joint.child], data)
            else:
                handle = self.world.multibody_joints.insert(parent, handles[joint.child], data)
                if handle is None:
                    raise RuntimeError(f"Rapier refused joint {joint.name!r} into a multibody")
                inserted.append(joint)
            self.built[joint.name] = (handle, parent)
        if inserted:
            damping = {handles[j.child]: j.damping for j in inserted}
            for multibody in self._multibodies(handles).values():
                # the links' poses and Jacobians (before the first step Rapier counts a
                # fixed root's six coordinates and has no Jacobian yet)
                multibody.forward_kinematics(self.world.rigid_bodies, True)
                set_damping(multibody, damping)
                set_velocities(multibody, tree, handles, velocities)

    def link_velocities(self, handles: list) -> dict[int, np.ndarray]:
        """Scene body index -> (6,) its centre's velocity and world ω, for every moving
        multibody link among ``handles`` (a floating root included), from the multibody's own
        state: ``body_jacobian`` at the current coordinates (after ``forward_kinematics``,
        which recomputes the links' poses from the coordinates they already came from) times
        the generalized velocity. The links' rigid bodies carry the velocity of one substep
        earlier (engines-rapier.md 9)."""
        row = {h: k for k, h in enumerate(handles)}
        found = {}
        for multibody in self._multibodies(handles).values():
            multibody.forward_kinematics(self.world.rigid_bodies, False)
            nu = np.array(multibody.generalized_velocity(), dtype=float)
            for link in _links(multibody):
                body = row.get(link.rigid_body)
                if body is not None and not (link.is_root() and link.ndofs == 0):  # not fixed
                    jacobian = np.array(multibody.body_jacobian(link.link_id), dtype=float)
                    found[body] = jacobian @ nu
        return found

    def report(self, tree: JointTree, stated: list, handles: list) -> JointReport:
        """The joints as Rapier holds them, in the scene's order (``stated``): each one's type
        (its locked axes), its anchor (frame1's origin on the parent's pose) and its axis
        (frame1's x, hinge and slider), its limits on its free axis (NaN where it has none),
        its damping and armature (``joint_dynamics``); for multibodies M(q0) in the tree's
        coordinates (``mass_matrix``), none for impulse joints (no joint coordinates)."""
        bodies = self.world.rigid_bodies
        joints = (
            self.world.impulse_joints if self.kind == "impulse" else self.world.multibody_joints
        )
        types, anchors, axes, limits = [], [], [], []
        for joint in stated:
            handle, parent = self.built[joint.name]
            data = joints[handle].data
            body = bodies[parent]
            turn = rotation_matrix(body.rotation)
            frame = data.local_frame1
            kind = LOCKED_TYPES.get(data.locked_axes.bits, f"locked axes {data.locked_axes.bits}")
            types.append(kind)
            anchors.append(
                np.array(body.translation.to_tuple()) + turn @ frame.translation.to_tuple()
            )
            axis = turn @ rotation_matrix(frame.rotation) @ X
            axes.append(axis if kind in AXIS_TYPES else np.zeros(3))
            limits.append(_limits(data, kind))
        damping, armature = self.joint_dynamics(tree, stated, handles)
        matrix = None if self.kind == "impulse" else self.mass_matrix(tree, handles)
        return JointReport(
            tuple(types),
            np.array(anchors),
            np.array(axes),
            matrix,
            limits=np.array(limits, dtype=float).reshape(-1, 2),
            damping=damping,
            armature=armature,
        )

    def joint_dynamics(
        self, tree: JointTree, stated: list, handles: list
    ) -> tuple[np.ndarray, np.ndarray]:
        """((j,) damping, (j,) armature) of the ``stated`` joints as Rapier holds them: a
        multibody's per coordinate (``Multibody.damping``, ``armature``, at its child link's
        coordinate), an impulse joint's damping its velocity motor's (``generic_joint``) and
        no armature."""
        damping, armature = np.zeros(len(stated)), np.zeros(len(stated))
        if self.kind == "impulse":
            for k, joint in enumerate(stated):
                handle, _ = self.built[joint.name]
                data = self.world.impulse_joints[handle].data
                free = JOINT_TYPES[joint.type].free
                motor = data.motor(free[0]) if free else None
                damping[k] = 0.0 if motor is None else float(motor.damping)
            return damping, armature
        child = {handles[j.child]: j.name for j in tree.joints if j.type != "free"}
        row = {joint.name: k for k, joint in enumerate(stated)}
        for multibody in self._multibodies(handles).values():
            values, inertias = multibody.damping(), multibody.armature()
            for link in _links(multibody):
                name = child.get(link.rigid_body)
                if link.ndofs and name in row:
                    damping[row[name]] = float(values[link.assembly_id])
                    armature[row[name]] = float(inertias[link.assembly_id])
        return damping, armature

    def mass_matrix(self, tree: JointTree, handles: list) -> np.ndarray:
        """(nv, nv) M(q0) in the joint tree's coordinates from Rapier's own model: per
        multibody ``Σ Jᵀ diag(m, I_world) J`` over its links (``body_jacobian``: the link's
        centre velocity then world ω; ``mass``, ``mass_properties``), its coordinates placed
        at the tree's. Rapier's coordinates are the tree's (engines-rapier.md 9): a hinge's or
        slider's rate along frame1's x, which is the scene's axis; a ball's spin relative to
        its parent in the parent's frame; a floating root's v and ω in the world frame."""
        bodies = self.world.rigid_bodies
        where = {handles[j.child]: j.v_slice for j in tree.joints}
        full = np.zeros((tree.nv, tree.nv))
        for multibody in self._multibodies(handles).values():
            index = np.zeros(multibody.ndofs, dtype=int)
            blocks = np.zeros((multibody.ndofs, multibody.ndofs))
            for link in _links(multibody):
                if link.ndofs:
                    index[link.assembly_id : link.assembly_id + link.ndofs] = np.arange(tree.nv)[
                        where[link.rigid_body]
                    ]
                body = bodies[link.rigid_body]
                if not body.is_dynamic:
                    continue
                jacobian = np.array(multibody.body_jacobian(link.link_id), dtype=float)
                inertia = np.zeros((6, 6))
                inertia[:3, :3] = float(body.mass) * np.eye(3)
                inertia[3:, 3:] = world_inertia(body)
                blocks += jacobian.T @ inertia @ jacobian
            full[np.ix_(index, index)] = blocks
        return full

    def _world_body(self):
        """The fixed body that stands for the world (identity pose, no collider), made once."""
        if self.world_body is None:
            self.world_body = self.world.add_body(rapier3d.RigidBody.fixed())
        return self.world_body

    def _multibodies(self, handles: list) -> dict:
        """Each multibody among the scene's bodies, once: root body handle -> ``Multibody``."""
        found = {}
        joints = self.world.multibody_joints
        for handle in handles:
            link = joints.rigid_body_link(handle)
            if link is not None:
                multibody = joints.get_multibody(link.multibody)
                found[multibody.root_handle] = multibody
        return found


def _limits(data, kind: str) -> tuple[float, float]:
    """A hinge's or slider's limits on its free axis as the joint holds them; NaN where it has
    none (or its type has no axis)."""
    if kind not in AXIS_TYPES:
        return (np.nan, np.nan)
    found = data.limits(JOINT_TYPES[kind].free[0])
    return (np.nan, np.nan) if found is None else (float(found.min), float(found.max))


def _links(multibody):
    return (multibody.get_link(k) for k in range(multibody.num_links))


def set_damping(multibody, damping: dict) -> None:
    """The multibody's damping per generalized velocity: each link's joint's (``damping``:
    child body handle -> N·m·s/rad or N·s/m), 0 on a floating root's six (Rapier's default is
    0.1 on every one, engines-rapier.md 9)."""
    values = [0.0] * multibody.ndofs
    for link in _links(multibody):
        value = 0.0 if link.is_root() else float(damping.get(link.rigid_body, 0.0))
        values[link.assembly_id : link.assembly_id + link.ndofs] = [value] * link.ndofs
    multibody.set_damping(values)


def set_velocities(
    multibody, tree: JointTree, handles: list, velocities: tuple[np.ndarray, np.ndarray]
) -> None:
    """The multibody's generalized velocity from its links' stated velocities (v, ω (n, 3)),
    through Rapier's own Jacobians at the initial configuration (``body_jacobian``: the link's
    centre velocity, then its world ω): the least-squares ν of ``J ν = (v, ω)``, exact for
    the velocities the scene's checks let through (the joints allow them)."""
    if multibody.ndofs == 0:
        return
    row = {h: k for k, h in enumerate(handles)}
    vel, ang_vel = velocities
    rows, stated = [], []
    for link in _links(multibody):
        body = row.get(link.rigid_body)
        if body is None or tree.fixed[body]:
            continue
        rows.append(np.array(multibody.body_jacobian(link.link_id), dtype=float))
        stated.append(np.concatenate([vel[body], ang_vel[body]]))
    nu = np.linalg.lstsq(np.concatenate(rows), np.concatenate(stated), rcond=None)[0]
    multibody.set_generalized_velocity([float(v) for v in nu])
