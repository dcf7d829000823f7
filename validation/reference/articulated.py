"""Bodies joined in a tree, on the reference side: the joint tree every engine and the
reference read, its kinematics and its dynamics in joint coordinates.

The tree (``JointTree``) is built once from the scene as it is stated (each body's pose at
t = 0, each joint's type, parent, child, world anchor and world axis at t = 0): every joint
is placed in its parent's body frame, so the tree holds no engine's convention. A body that is
no joint's child is a root: ``fixed`` (welded to the world), or floating (six coordinates of
its own). Nothing here calls an engine or mini_engine.

Coordinates, per joint, in the tree's order (parents before children):

    type     q (position)                     ν (velocity)
    hinge    θ rad about the axis             θ̇ rad/s
    slider   s m along the axis               ṡ m/s
    ball     unit quaternion Q (w x y z)      w (3,) rad/s, the child's spin relative to
             of the child relative to its     its parent, in the parent's frame
             parent, in the parent's frame
    fixed    -                                -
    free     centre (3,), quaternion (4,)     v (3,) m/s, ω (3,) rad/s, world frame
    (a floating root)

all relative to the configuration at t = 0 (q = 0, Q = identity): a joint's coordinate is what
``joint_position_at`` expects (a ball joint's as the rotation vector of Q).

Kinematics, for a joint between parent P (pose c_P, R_P, or the world) and child C: the anchor
``a_P`` and the axis ``u_P`` are fixed in P's frame; ``r0`` (C's centre relative to the
anchor, P's frame at q = 0) and ``R0`` (C's orientation relative to P at q = 0) place the child:

    hinge   R_C = R_P Rot(u_P, θ) R0      c_C = c_P + R_P (a_P + Rot(u_P, θ) r0)
    slider  R_C = R_P R0                  c_C = c_P + R_P (a_P + u_P s + r0)
    ball    R_C = R_P Q R0                c_C = c_P + R_P (a_P + Q r0)
    fixed   R_C = R_P R0                  c_C = c_P + R_P (a_P + r0)

Velocities and accelerations follow by differentiating these once and twice (``_child_motion``:
a point fixed in a turning frame, ``v = ω × r`` and ``a = α × r + ω × (ω × r)``, plus the
joint's own rate). The dynamics is Lagrange's in the form every multibody text writes it,

    M(q) ν̇ + b(q, ν) = τ_damping,      M(q) = Σ_bodies J_vᵀ m J_v + J_ωᵀ I_world J_ω,
    b(q, ν) = Σ_bodies J_vᵀ (m a⁰ - F) + J_ωᵀ (I_world α⁰ + ω × I_world ω - τ),

where J_v, J_ω are each body's centre and spin Jacobians, a⁰ and α⁰ its accelerations with
ν̇ = 0 (the velocity-product terms), F and τ its gravity, spring and applied loads: M is the
composite-rigid-body mass matrix (summed body by body), b the recursive Newton-Euler bias with
ν̇ = 0 (Featherstone, Rigid Body Dynamics Algorithms, chapters 5-6). ``reference_motion``
integrates it with DOP853 (``validation.reference.newton_euler``'s tolerances).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from validation.reference.loads import Springs, applied_loads
from validation.reference.motion import Motion
from validation.reference.rotation import cross, quat_multiply, quat_to_matrix

WORLD = -1
"""``Joint.parent`` of a joint whose parent is the world."""

POSITION_DIMENSIONS = {"hinge": 1, "slider": 1, "ball": 4, "fixed": 0, "free": 7}
VELOCITY_DIMENSIONS = {"hinge": 1, "slider": 1, "ball": 3, "fixed": 0, "free": 6}
"""Numbers of position and velocity coordinates of each joint type (the table above)."""

AXIS_TYPES = ("hinge", "slider")
"""Joint types with an axis."""

RELATIVE_TOLERANCE = 3e-14
"""DOP853's rtol in joint space, the free-body reference's (``newton_euler``): near the
smallest SciPy accepts. At 1e-12 the joint-space reference of a 2 rad compound pendulum was
2.3e-12 m off MuJoCo's RK4 at dt = 5e-5 s (the sweep's cross-check), the floor of RK4's own
sweep curve from dt = 1 ms on; at 3e-14, 2.5e-13 m, and RK4's curve falls 16x per halving
(5.0e-10, 3.1e-11, 2.0e-12, 1.1e-13 m at dt = 4, 2, 1, 0.5 ms). The right-hand side is a
Python pass over the tree: a 1 s swing integrates in about half a second."""

ABSOLUTE_TOLERANCE = 1e-16
"""DOP853's atol in rad, m, rad/s, m/s (the free-body reference's): round-off of the library's
unit-sized joint states."""


@dataclass(frozen=True)
class Joint:
    """One joint of the tree, placed in its parent's body frame (the world's for ``WORLD``).

    Attributes:
        name: the scene's name (``"<body>:free"`` for a floating root).
        type: one of ``POSITION_DIMENSIONS``.
        parent: the parent body's index, or ``WORLD``. child: the child body's index.
        anchor: (3,) m, the joint point in the parent's frame (from its centre of mass).
        axis: (3,) unit, in the parent's frame (hinge, slider; zeros otherwise).
        offset: (3,) m, the child's centre relative to the anchor, parent's frame, q = 0.
        rotation: (3, 3) the child's orientation relative to the parent's at q = 0.
        damping: N·m·s/rad (hinge, ball) or N·s/m (slider).
        q_slice, v_slice: where the joint's coordinates sit in q and ν.
    """

    name: str
    type: str
    parent: int
    child: int
    anchor: np.ndarray
    axis: np.ndarray
    offset: np.ndarray
    rotation: np.ndarray
    damping: float
    q_slice: slice
    v_slice: slice


@dataclass(frozen=True)
class Pose:
    """Each body's pose: ``pos (n, 3)`` m, centres of mass, and ``rot (n, 3, 3)`` body to world."""

    pos: np.ndarray
    rot: np.ndarray


@dataclass(frozen=True)
class BodyMotion:
    """Each body's ``vel``, ``ang_vel`` (n, 3) (m/s, rad/s) and the accelerations ``acc``,
    ``ang_acc`` (n, 3) (m/s², rad/s²) of a pose under given ν and ν̇, world frame."""

    vel: np.ndarray
    ang_vel: np.ndarray
    acc: np.ndarray
    ang_acc: np.ndarray


@dataclass(frozen=True)
class JointTree:
    """The scene's bodies and joints as one tree (module docstring).

    Attributes:
        joints: every joint, parents before children; floating roots as ``free`` joints.
        mass: (n,) kg. inertia: (n, 3, 3) kg·m², body frame, about the centre of mass.
        fixed: (n,) bool, bodies welded to the world (no joint, no coordinates).
        fixed_pos: (n, 3) m and fixed_rot (n, 3, 3): their poses (and every body's at t = 0).
        nq, nv: the numbers of position and velocity coordinates.
    """

    joints: tuple[Joint, ...]
    mass: np.ndarray
    inertia: np.ndarray
    fixed: np.ndarray
    fixed_pos: np.ndarray
    fixed_rot: np.ndarray
    nq: int
    nv: int
    damping: np.ndarray = field(repr=False)
    """(nv,) the damping of each velocity coordinate (its joint's)."""
    subtree: np.ndarray = field(repr=False)
    """(joints, n) bool: the bodies each joint moves (its child and the child's descendants)."""

    @property
    def bodies(self) -> int:
        return int(self.mass.size)

    def zero(self) -> np.ndarray:
        """(nq,) the configuration at t = 0: every coordinate 0, every quaternion identity."""
        q = np.zeros(self.nq)
        for joint in self.joints:
            if joint.type == "ball":
                q[joint.q_slice.start] = 1.0
            elif joint.type == "free":
                q[joint.q_slice] = _free_position(self, joint)
        return q


@dataclass(frozen=True)
class StatedJoint:
    """A joint as a scene states it (world frame at t = 0); ``parent`` ``WORLD`` or a body."""

    name: str
    type: str
    parent: int
    child: int
    anchor: np.ndarray
    axis: np.ndarray = field(default_factory=lambda: np.zeros(3))
    damping: float = 0.0


# --- building the tree once ----------------------------------------------------------------


def build_tree(
    joints: list[StatedJoint],
    mass: np.ndarray,
    inertia: np.ndarray,
    pos: np.ndarray,
    quat: np.ndarray,
    fixed: np.ndarray,
) -> JointTree:
    """The ``JointTree`` of ``joints`` between ``n`` bodies whose poses at t = 0 are ``pos
    (n, 3)``, ``quat (n, 4)``: each joint placed in its parent's frame, parents first, every
    body that is no joint's child and not ``fixed`` a floating root. Raises ``ValueError``
    naming the joint for a loop or a body with two parents (the scene's checks refuse both
    first, with the file and line)."""
    rot = quat_to_matrix(np.asarray(quat, dtype=float))
    ordered = _parents_first(joints, mass.size)
    placed: list[Joint] = []
    q_at, v_at = 0, 0
    children = {joint.child for joint in joints}
    for body in range(mass.size):
        if body not in children and not fixed[body]:
            placed.append(_floating_root(body, q_at, v_at))
            q_at, v_at = q_at + POSITION_DIMENSIONS["free"], v_at + VELOCITY_DIMENSIONS["free"]
    for stated in ordered:
        joint = _placed(stated, pos, rot, q_at, v_at)
        placed.append(joint)
        q_at += POSITION_DIMENSIONS[joint.type]
        v_at += VELOCITY_DIMENSIONS[joint.type]
    damping = np.zeros(v_at)
    for joint in placed:
        damping[joint.v_slice] = joint.damping
    return JointTree(
        subtree=_subtrees(placed, mass.size),
        joints=tuple(placed),
        mass=np.asarray(mass, dtype=float),
        inertia=np.asarray(inertia, dtype=float),
        fixed=np.asarray(fixed, dtype=bool),
        fixed_pos=np.asarray(pos, dtype=float),
        fixed_rot=rot,
        nq=q_at,
        nv=v_at,
        damping=damping,
    )


def _parents_first(joints: list[StatedJoint], bodies: int) -> list[StatedJoint]:
    """``joints`` ordered so that a body's joint comes after its parent's (breadth first
    from the world and the roots); a body with two parents or a loop is a ``ValueError``."""
    by_child: dict[int, StatedJoint] = {}
    for joint in joints:
        if joint.child in by_child:
            raise ValueError(f"joint '{joint.name}': body {joint.child} already has a parent")
        by_child[joint.child] = joint
    ordered: list[StatedJoint] = []
    placed = {body for body in range(bodies) if body not in by_child}
    pending = list(joints)
    while pending:
        ready = [j for j in pending if j.parent == WORLD or j.parent in placed]
        if not ready:
            raise ValueError(f"joints {[j.name for j in pending]} form a loop")
        ordered += ready
        placed |= {j.child for j in ready}
        pending = [j for j in pending if j not in ready]
    return ordered


def _subtrees(joints: list[Joint], bodies: int) -> np.ndarray:
    """(joints, n) bool: each joint's child and every body below it (children last, so one
    pass from the leaves up collects them)."""
    subtree = np.zeros((len(joints), bodies), dtype=bool)
    joint_of = {joint.child: k for k, joint in enumerate(joints)}
    for k in reversed(range(len(joints))):
        subtree[k, joints[k].child] = True
        parent = joints[k].parent
        if parent in joint_of:  # not the world, nor a fixed body (no joint moves either)
            subtree[joint_of[parent]] |= subtree[k]
    return subtree


def _floating_root(body: int, q_at: int, v_at: int) -> Joint:
    zero = np.zeros(3)
    return Joint(
        name=f"{body}:free",
        type="free",
        parent=WORLD,
        child=body,
        anchor=zero,
        axis=zero,
        offset=zero,
        rotation=np.eye(3),
        damping=0.0,
        q_slice=slice(q_at, q_at + POSITION_DIMENSIONS["free"]),
        v_slice=slice(v_at, v_at + VELOCITY_DIMENSIONS["free"]),
    )


def _placed(stated: StatedJoint, pos: np.ndarray, rot: np.ndarray, q_at: int, v_at: int) -> Joint:
    """``stated`` in its parent's frame, from the bodies' poses at t = 0."""
    if stated.parent == WORLD:
        parent_pos, parent_rot = np.zeros(3), np.eye(3)
    else:
        parent_pos, parent_rot = pos[stated.parent], rot[stated.parent]
    anchor = parent_rot.T @ (np.asarray(stated.anchor, dtype=float) - parent_pos)
    axis = parent_rot.T @ np.asarray(stated.axis, dtype=float)
    return Joint(
        name=stated.name,
        type=stated.type,
        parent=stated.parent,
        child=stated.child,
        anchor=anchor,
        axis=axis,
        offset=parent_rot.T @ (pos[stated.child] - np.asarray(stated.anchor, dtype=float)),
        rotation=parent_rot.T @ rot[stated.child],
        damping=float(stated.damping),
        q_slice=slice(q_at, q_at + POSITION_DIMENSIONS[stated.type]),
        v_slice=slice(v_at, v_at + VELOCITY_DIMENSIONS[stated.type]),
    )


def _free_position(tree: JointTree, joint: Joint) -> np.ndarray:
    """(7,) a floating root's position coordinates at t = 0: its centre and quaternion."""
    body = joint.child
    return np.concatenate([tree.fixed_pos[body], _matrix_to_quat(tree.fixed_rot[body])])


# --- kinematics ----------------------------------------------------------------------------


def axis_rotation(axis: np.ndarray, angle: float) -> np.ndarray:
    """(3, 3) the rotation by ``angle`` rad about the unit ``axis`` (Rodrigues' formula)."""
    k = _skew(axis)
    return np.eye(3) + np.sin(angle) * k + (1.0 - np.cos(angle)) * (k @ k)


def _skew(v: np.ndarray) -> np.ndarray:
    return np.array([[0.0, -v[2], v[1]], [v[2], 0.0, -v[0]], [-v[1], v[0], 0.0]])


def _joint_rotation(joint: Joint, q: np.ndarray) -> np.ndarray:
    """(3, 3) the child's rotation about the anchor relative to the parent, parent's frame."""
    if joint.type == "hinge":
        return axis_rotation(joint.axis, q[joint.q_slice.start])
    if joint.type == "ball":
        quat = q[joint.q_slice]
        return quat_to_matrix(quat / np.linalg.norm(quat))
    return np.eye(3)


def forward_kinematics(tree: JointTree, q: np.ndarray) -> Pose:
    """Every body's pose at configuration ``q (nq,)`` (module docstring's table)."""
    pos = tree.fixed_pos.copy()
    rot = tree.fixed_rot.copy()
    for joint in tree.joints:
        child = joint.child
        if joint.type == "free":
            coordinates = q[joint.q_slice]
            pos[child] = coordinates[:3]
            rot[child] = quat_to_matrix(coordinates[3:] / np.linalg.norm(coordinates[3:]))
            continue
        parent_pos, parent_rot = _parent_pose(joint, pos, rot)
        turn = _joint_rotation(joint, q)
        slide = joint.axis * q[joint.q_slice.start] if joint.type == "slider" else 0.0
        rot[child] = parent_rot @ turn @ joint.rotation
        pos[child] = parent_pos + parent_rot @ (joint.anchor + slide + turn @ joint.offset)
    return Pose(pos, rot)


def _parent_pose(joint: Joint, pos: np.ndarray, rot: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    if joint.parent == WORLD:
        return np.zeros(3), np.eye(3)
    return pos[joint.parent], rot[joint.parent]


def body_motion(tree: JointTree, pose: Pose, nu: np.ndarray, nu_dot: np.ndarray) -> BodyMotion:
    """Each body's velocities and accelerations at ``pose`` (``forward_kinematics``) under
    ``nu (nv,)`` and ``nu_dot (nv,)``, parents first (``_child_motion``)."""
    n = tree.bodies
    vel, ang_vel = np.zeros((n, 3)), np.zeros((n, 3))
    acc, ang_acc = np.zeros((n, 3)), np.zeros((n, 3))
    for joint in tree.joints:
        child = joint.child
        if joint.type == "free":
            rate, rate_dot = nu[joint.v_slice], nu_dot[joint.v_slice]
            vel[child], ang_vel[child] = rate[:3], rate[3:]
            acc[child], ang_acc[child] = rate_dot[:3], rate_dot[3:]
            continue
        parent = _parent_motion(joint, pose, vel, ang_vel, acc, ang_acc)
        motion = _child_motion(joint, parent, pose.pos[child], nu, nu_dot)
        vel[child], ang_vel[child], acc[child], ang_acc[child] = motion
    return BodyMotion(vel, ang_vel, acc, ang_acc)


def _parent_motion(joint, pose, vel, ang_vel, acc, ang_acc) -> tuple[np.ndarray, ...]:
    """(centre, rotation, v, ω, a, α) of the joint's parent; the world's is at rest."""
    if joint.parent == WORLD:
        zero = np.zeros(3)
        return zero, np.eye(3), zero, zero, zero, zero
    p = joint.parent
    return pose.pos[p], pose.rot[p], vel[p], ang_vel[p], acc[p], ang_acc[p]


def _child_motion(joint: Joint, parent, child_pos, nu, nu_dot) -> tuple[np.ndarray, ...]:
    """(v, ω, a, α) of ``joint``'s child: the parent's motion carried to the child through
    the joint, plus the joint's own rate (hinge: ω += u θ̇; slider: v += u ṡ; ball: ω += w)."""
    parent_pos, parent_rot, v_p, w_p, a_p, alpha_p = parent
    anchor = parent_pos + parent_rot @ joint.anchor
    arm_p = anchor - parent_pos  # from the parent's centre to the anchor
    arm_c = child_pos - anchor  # from the anchor to the child's centre
    v_anchor = v_p + cross(w_p, arm_p)
    a_anchor = a_p + cross(alpha_p, arm_p) + cross(w_p, cross(w_p, arm_p))
    relative_w, relative_alpha = np.zeros(3), np.zeros(3)
    slide_v, slide_a = np.zeros(3), np.zeros(3)
    if joint.type in ("hinge", "ball"):
        if joint.type == "hinge":
            direction = parent_rot @ joint.axis
            relative_w = direction * nu[joint.v_slice.start]
            relative_alpha = direction * nu_dot[joint.v_slice.start]
        else:
            relative_w = parent_rot @ nu[joint.v_slice]
            relative_alpha = parent_rot @ nu_dot[joint.v_slice]
        relative_alpha = relative_alpha + cross(w_p, relative_w)  # the axis turns with P
    elif joint.type == "slider":
        direction = parent_rot @ joint.axis
        slide_v = direction * nu[joint.v_slice.start]
        # the slide's own acceleration and its Coriolis term 2 ω_P × u ṡ (u turns with P)
        slide_a = direction * nu_dot[joint.v_slice.start] + 2.0 * cross(w_p, slide_v)
    w_c = w_p + relative_w
    alpha_c = alpha_p + relative_alpha
    if joint.type == "slider":
        # the child moves with P (ω_C = ω_P) plus the slide: carry from the anchor point of P
        v_c = v_anchor + cross(w_p, arm_c) + slide_v
        a_c = a_anchor + cross(alpha_p, arm_c) + cross(w_p, cross(w_p, arm_c)) + slide_a
    else:
        v_c = v_anchor + cross(w_c, arm_c)
        a_c = a_anchor + cross(alpha_c, arm_c) + cross(w_c, cross(w_c, arm_c))
    return v_c, w_c, a_c, alpha_c


def jacobians(tree: JointTree, pose: Pose) -> tuple[np.ndarray, np.ndarray]:
    """(n, 3, nv) each: the centre-velocity and spin Jacobians, ``v = J_v ν``, ``ω = J_ω ν``.
    Each coordinate moves its joint's subtree as a rigid whole: a rotation rate about the
    world direction u through the point a gives every body below ``(u × (c - a), u)``, a slide
    along u gives ``(u, 0)`` (the geometric Jacobian)."""
    j_v, j_w = np.zeros((tree.bodies, 3, tree.nv)), np.zeros((tree.bodies, 3, tree.nv))
    for joint, moved in zip(tree.joints, tree.subtree, strict=True):
        if joint.type == "fixed":
            continue
        centres = pose.pos[moved]
        if joint.type == "free":
            slides, turns, point = np.eye(3), np.eye(3), pose.pos[joint.child]
        else:
            parent_pos, parent_rot = _parent_pose(joint, pose.pos, pose.rot)
            point = parent_pos + parent_rot @ joint.anchor
            directions = (
                (parent_rot @ joint.axis)[None] if joint.type in AXIS_TYPES else parent_rot.T
            )
            slides = directions if joint.type == "slider" else np.zeros((0, 3))
            turns = directions if joint.type in ("hinge", "ball") else np.zeros((0, 3))
        columns = range(joint.v_slice.start, joint.v_slice.stop)
        for column, direction in zip(columns, [*slides, *turns], strict=True):
            if column - joint.v_slice.start < len(slides):
                j_v[moved, :, column] = direction
            else:
                j_w[moved, :, column] = direction
                j_v[moved, :, column] = cross(direction[None], centres - point)
    return j_v, j_w


def world_inertia(tree: JointTree, pose: Pose) -> np.ndarray:
    """(n, 3, 3) kg·m², ``R I Rᵀ`` of every body at ``pose``."""
    return np.einsum("nij,njk,nlk->nil", pose.rot, tree.inertia, pose.rot)


def mass_matrix(tree: JointTree, q: np.ndarray) -> np.ndarray:
    """(nv, nv) kg, kg·m, kg·m²: ``M(q) = Σ J_vᵀ m J_v + J_ωᵀ R I Rᵀ J_ω`` over the moving
    bodies, the composite-rigid-body mass matrix summed body by body."""
    pose = forward_kinematics(tree, q)
    return _mass_matrix(tree, pose, *jacobians(tree, pose))


def _mass_matrix(tree: JointTree, pose: Pose, j_v: np.ndarray, j_w: np.ndarray) -> np.ndarray:
    moving = ~tree.fixed
    inertia = world_inertia(tree, pose)
    translation = np.einsum("n,nik,nil->kl", tree.mass * moving, j_v, j_v)
    rotation = np.einsum("nik,nij,njl->kl", j_w[moving], inertia[moving], j_w[moving])
    return translation + rotation


@dataclass(frozen=True)
class Loads:
    """What pushes the tree besides its joints: ``gravity (3,)`` m/s², ``springs``, and each
    body's constant applied ``force`` and ``torque`` (n, 3), world frame."""

    gravity: np.ndarray
    springs: Springs
    force: np.ndarray
    torque: np.ndarray


def bias_forces(tree: JointTree, q: np.ndarray, nu: np.ndarray, loads: Loads) -> np.ndarray:
    """(nv,) ``b(q, ν)`` of ``M ν̇ + b = τ_joint``: the generalized forces of the bodies'
    velocity-product accelerations (ν̇ = 0), their gyroscopic terms, gravity, springs and
    applied loads (module docstring), joint damping left out (``joint_forces``)."""
    pose = forward_kinematics(tree, q)
    return _bias_forces(tree, pose, *jacobians(tree, pose), nu, loads)


def _bias_forces(tree, pose, j_v, j_w, nu, loads: Loads) -> np.ndarray:
    motion = body_motion(tree, pose, nu, np.zeros(tree.nv))
    moving = ~tree.fixed
    force, torque = applied_loads(
        loads.springs, moving, loads.force, loads.torque, pose.pos, pose.rot,
        motion.vel, motion.ang_vel,
    )  # fmt: skip
    inertia = world_inertia(tree, pose)
    mass = (tree.mass * moving)[:, None]
    linear = mass * (motion.acc - loads.gravity) - force
    spin = np.einsum("nij,nj->ni", inertia, motion.ang_vel)
    angular = np.einsum("nij,nj->ni", inertia, motion.ang_acc) + cross(motion.ang_vel, spin)
    angular = np.where(moving[:, None], angular - torque, 0.0)
    return np.einsum("nik,ni->k", j_v, linear) + np.einsum("nik,ni->k", j_w, angular)


def joint_forces(tree: JointTree, nu: np.ndarray) -> np.ndarray:
    """(nv,) the joints' own generalized forces: viscous damping ``-d ν``."""
    return -tree.damping * nu


def acceleration(tree: JointTree, q: np.ndarray, nu: np.ndarray, loads: Loads) -> np.ndarray:
    """(nv,) ν̇ = M⁻¹ (τ_joint - b) (``np.linalg.solve``: M is symmetric positive definite),
    the pose and Jacobians computed once for both."""
    pose = forward_kinematics(tree, q)
    j_v, j_w = jacobians(tree, pose)
    rhs = joint_forces(tree, nu) - _bias_forces(tree, pose, j_v, j_w, nu, loads)
    return np.linalg.solve(_mass_matrix(tree, pose, j_v, j_w), rhs)


def position_rate(tree: JointTree, q: np.ndarray, nu: np.ndarray) -> np.ndarray:
    """(nq,) q̇ from ν: θ̇ = ν, ṡ = ν; a ball's Q̇ = ½ (0, w) ⊗ Q (w in the parent's frame,
    turning Q from the left); a floating root's ċ = v, q̇ = ½ (0, ω) ⊗ q."""
    rate = np.zeros(tree.nq)
    for joint in tree.joints:
        qs, vs = joint.q_slice, joint.v_slice
        if joint.type in AXIS_TYPES:
            rate[qs] = nu[vs]
        elif joint.type == "ball":
            rate[qs] = 0.5 * quat_multiply(np.concatenate([[0.0], nu[vs]]), q[qs])
        elif joint.type == "free":
            spin = np.concatenate([[0.0], nu[vs][3:]])
            rate[qs] = np.concatenate([nu[vs][:3], 0.5 * quat_multiply(spin, q[qs][3:])])
    return rate


def energy(tree: JointTree, q: np.ndarray, nu: np.ndarray, loads: Loads) -> float:
    """J: ``½ νᵀ M ν - Σ m g·c`` (springs and applied loads are not counted here)."""
    pose = forward_kinematics(tree, q)
    moving = ~tree.fixed
    height = -np.einsum("n,ni,i->", tree.mass * moving, pose.pos, loads.gravity)
    return 0.5 * float(nu @ mass_matrix(tree, q) @ nu) + float(height)


def initial_velocities(
    tree: JointTree, vel: np.ndarray, ang_vel: np.ndarray
) -> tuple[np.ndarray, float]:
    """(ν0 (nv,), residual m/s) from the bodies' stated velocities ``vel``, ``ang_vel (n, 3)``
    at t = 0: the least-squares ν of ``J ν = (v, ω)`` over the moving bodies, and the largest
    velocity the joints cannot produce (0 when the stated state satisfies the joints; a scene
    whose residual is not round-off is refused by its checks, which name the body)."""
    pose = forward_kinematics(tree, tree.zero())
    j_v, j_w = jacobians(tree, pose)
    moving = ~tree.fixed
    jacobian = np.concatenate([j_v[moving], j_w[moving]]).reshape(-1, tree.nv)
    stated = np.concatenate([vel[moving], ang_vel[moving]]).reshape(-1)
    if tree.nv == 0:
        return np.zeros(0), float(np.abs(stated).max(initial=0.0))
    nu0 = np.linalg.lstsq(jacobian, stated, rcond=None)[0]
    return nu0, float(np.abs(jacobian @ nu0 - stated).max(initial=0.0))


# --- reading joint coordinates back from body poses ----------------------------------------


def joint_coordinates(tree: JointTree, pos: np.ndarray, rot: np.ndarray) -> dict[str, np.ndarray]:
    """Each stated joint's coordinate at body poses ``pos (s, n, 3)``, ``rot (s, n, 3, 3)``
    (an engine's observed states): hinge θ (s,) rad, slider s (s,) m, ball the rotation
    vector (s, 3) rad of Q; read from the parent's and the child's poses alone, so they hold
    for any engine's states, joint violation included (a hinge's angle is the rotation of
    R_Pᵀ R_C R0ᵀ about its axis, unwrapped along the states, which start at t = 0 where it
    is 0; a slider's the anchors' separation along its axis)."""
    coordinates = {}
    for joint in tree.joints:
        if joint.type in ("free", "fixed"):
            continue
        parent_pos, parent_rot = _parent_poses(joint, pos, rot)
        relative = np.einsum("sji,sjk,lk->sil", parent_rot, rot[:, joint.child], joint.rotation)
        if joint.type == "hinge":  # continuous along the states: a swing past π goes on
            coordinates[joint.name] = np.unwrap(_rotation_vector(relative) @ joint.axis)
        elif joint.type == "ball":
            coordinates[joint.name] = _rotation_vector(relative)
        else:  # c_C = c_P + R_P (a_P + u s + r0)
            local = np.einsum("sji,sj->si", parent_rot, pos[:, joint.child] - parent_pos)
            coordinates[joint.name] = (local - joint.anchor - joint.offset) @ joint.axis
    return coordinates


def joint_violations(tree: JointTree, pos: np.ndarray, rot: np.ndarray) -> tuple[np.ndarray, ...]:
    """How far body poses ``pos (s, n, 3)``, ``rot (s, n, 3, 3)`` (an engine's observed states)
    break each stated joint, from the two bodies' poses alone: ``separation (s, j)`` m, the
    distance between the anchor as a point of the parent and as a point of the child (a
    slider's across its axis only), and ``misalignment (s, j)`` rad, the angle between the
    hinge's axis as the parent and the child carry it, or the whole relative rotation a slider
    or fixed joint forbids (none for a ball); ``reach (j,)`` m, the child's centre's distance
    from the anchor (what a misalignment moves it by, per radian). Joints in tree order,
    floating roots left out."""
    stated = [joint for joint in tree.joints if joint.type != "free"]
    states = pos.shape[0]
    separation = np.zeros((states, len(stated)))
    misalignment = np.zeros((states, len(stated)))
    for k, joint in enumerate(stated):
        parent_pos, parent_rot = _parent_poses(joint, pos, rot)
        child_rot = rot[:, joint.child]
        anchor_parent = parent_pos + np.einsum("sij,j->si", parent_rot, joint.anchor)
        anchor_child = pos[:, joint.child] - np.einsum(
            "sij,kj,k->si", child_rot, joint.rotation, joint.offset
        )  # the child's anchor is -R0ᵀ r0 in its frame
        gap = anchor_child - anchor_parent
        axis_parent = np.einsum("sij,j->si", parent_rot, joint.axis)
        if joint.type == "slider":
            gap = gap - axis_parent * np.einsum("si,si->s", gap, axis_parent)[:, None]
        separation[:, k] = np.linalg.norm(gap, axis=1)
        if joint.type == "hinge":
            axis_child = np.einsum("sij,kj,k->si", child_rot, joint.rotation, joint.axis)
            sine = np.linalg.norm(np.cross(axis_parent, axis_child), axis=1)
            misalignment[:, k] = np.arctan2(sine, np.einsum("si,si->s", axis_parent, axis_child))
        elif joint.type in ("slider", "fixed"):
            relative = np.einsum("sji,sjk,lk->sil", parent_rot, child_rot, joint.rotation)
            misalignment[:, k] = np.linalg.norm(_rotation_vector(relative), axis=1)
    reach = np.array([np.linalg.norm(joint.offset) for joint in stated])
    return separation, misalignment, reach


def _parent_poses(joint: Joint, pos: np.ndarray, rot: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    states = pos.shape[0]
    if joint.parent == WORLD:
        return np.zeros((states, 3)), np.broadcast_to(np.eye(3), (states, 3, 3))
    return pos[:, joint.parent], rot[:, joint.parent]


def _rotation_vector(matrix: np.ndarray) -> np.ndarray:
    """(s, 3) the rotation vectors (axis x angle, angle in [0, π]) of ``matrix (s, 3, 3)``."""
    skew = np.stack(
        [
            matrix[:, 2, 1] - matrix[:, 1, 2],
            matrix[:, 0, 2] - matrix[:, 2, 0],
            matrix[:, 1, 0] - matrix[:, 0, 1],
        ],
        axis=-1,
    )
    sine = 0.5 * np.linalg.norm(skew, axis=-1)
    cosine = 0.5 * (np.trace(matrix, axis1=1, axis2=2) - 1.0)
    angle = np.arctan2(sine, cosine)
    scale = np.where(sine > 1e-300, angle / np.maximum(2.0 * sine, 1e-300), 0.5)
    return skew * scale[:, None]


def _matrix_to_quat(matrix: np.ndarray) -> np.ndarray:
    """(4,) w x y z of a rotation matrix (Shepperd's method: the largest diagonal term first)."""
    trace = np.trace(matrix)
    diagonal = np.diag(matrix)
    k = int(np.argmax([trace, *diagonal]))
    if k == 0:
        w = 0.5 * np.sqrt(1.0 + trace)
        return np.array(
            [
                w,
                (matrix[2, 1] - matrix[1, 2]) / (4 * w),
                (matrix[0, 2] - matrix[2, 0]) / (4 * w),
                (matrix[1, 0] - matrix[0, 1]) / (4 * w),
            ]
        )
    i = k - 1
    j, m = (i + 1) % 3, (i + 2) % 3
    s = 0.5 * np.sqrt(1.0 + matrix[i, i] - matrix[j, j] - matrix[m, m])
    quat = np.zeros(4)
    quat[1 + i] = s
    quat[0] = (matrix[m, j] - matrix[j, m]) / (4 * s)
    quat[1 + j] = (matrix[j, i] + matrix[i, j]) / (4 * s)
    quat[1 + m] = (matrix[m, i] + matrix[i, m]) / (4 * s)
    return quat if quat[0] >= 0 else -quat


# --- the reference motion ------------------------------------------------------------------


def reference_motion(
    tree: JointTree, q0: np.ndarray, nu0: np.ndarray, loads: Loads, times: np.ndarray
) -> tuple[Motion, np.ndarray, np.ndarray]:
    """The tree's motion from ``(q0, ν0)`` sampled at ``times (s,)``: DOP853 on
    ``(q̇, ν̇) = (position_rate, acceleration)``; returns the bodies' ``Motion`` and the
    joint-space samples ``q (s, nq)``, ``ν (s, nv)``."""
    times = np.asarray(times, dtype=float)
    solution = joint_space_solution(tree, q0, nu0, loads, float(times[-1]), times)
    q_samples, nu_samples = solution.y[: tree.nq].T, solution.y[tree.nq :].T
    return body_states(tree, times, solution.y.T), q_samples, nu_samples


def joint_space_solution(
    tree: JointTree,
    q0: np.ndarray,
    nu0: np.ndarray,
    loads: Loads,
    end: float,
    times: np.ndarray | None = None,
):
    """SciPy's DOP853 solution of the tree from ``(q0, ν0)`` at t = 0 to ``end`` s, sampled at
    ``times``, or (None) with its dense output; its states are ``(q, ν)``, flat."""
    from scipy.integrate import solve_ivp  # only here: the scene's checks build trees too,
    # and ``physval check`` imports no SciPy (tests/test_architecture.py)

    nq = tree.nq

    def rhs(_t: float, state: np.ndarray) -> np.ndarray:
        q, nu = state[:nq], state[nq:]
        return np.concatenate([position_rate(tree, q, nu), acceleration(tree, q, nu, loads)])

    solution = solve_ivp(
        rhs,
        (0.0, end),
        np.concatenate([q0, nu0]),
        method="DOP853",
        t_eval=times,
        dense_output=times is None,
        rtol=RELATIVE_TOLERANCE,
        atol=ABSOLUTE_TOLERANCE,
    )
    if not solution.success:
        raise RuntimeError(f"the joint-space reference failed: {solution.message}")
    return solution


def body_states(tree: JointTree, times: np.ndarray, states: np.ndarray) -> Motion:
    """Each body's ``Motion`` at ``times (s,)`` from the joint-space states ``(s, nq + nv)``."""
    return _body_states(tree, times, states[:, : tree.nq], states[:, tree.nq :])


def _body_states(tree: JointTree, times, q_samples, nu_samples) -> Motion:
    """Each body's ``Motion`` at the joint-space samples."""
    states, n = times.size, tree.bodies
    pos, quat = np.zeros((states, n, 3)), np.zeros((states, n, 4))
    vel, ang_vel = np.zeros((states, n, 3)), np.zeros((states, n, 3))
    still = np.zeros(tree.nv)
    for s in range(states):
        pose = forward_kinematics(tree, q_samples[s])
        motion = body_motion(tree, pose, nu_samples[s], still)
        pos[s], vel[s], ang_vel[s] = pose.pos, motion.vel, motion.ang_vel
        quat[s] = np.array([_matrix_to_quat(matrix) for matrix in pose.rot])
    return Motion(times, pos, quat, vel, ang_vel)
