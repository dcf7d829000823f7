"""A scene's ``models`` read by PyBullet's own loaders (``model_loader=native``, issue 36):
``loadURDF`` or ``loadMJCF``, placed, set to the model's initial joint state, read back in the
scene's terms (``validation.scenario.urdf.ModelLayout``).

Frames (docs/engines.md 2.6). ``getLinkState``'s first two outputs are a link's *inertial*
frame (its centre of mass with the principal axes, Bullet's diagonalization of the file's
inertia); outputs 4-5 are the file's link frame (URDF ``<link>``, MJCF ``<body>``). A base's
pose (``getBasePositionAndOrientation``) is its inertial frame too; its link frame is that
times the inverse of ``getDynamicsInfo``'s local inertial frame. A scene body is its link
frame times ``ModelLayout.body_in_link``: the scene body's centre (the file's inertial origin)
and axes (the file's inertial rotation), whatever frame Bullet keeps its inertia in.

What the loaders do with the file, measured (docs/engines.md 2.6): ``loadURDF`` recomputes
every link's inertia from its collision shapes unless ``URDF_USE_INERTIA_FROM_FILE``
(``inertia_flags``); it keeps ``<dynamics damping>`` as btMultiBody's ``jointDamping`` (an
explicit ``-c q̇``), puts a velocity motor on every joint (``release_motors``) and gives the
multibody Bullet's link damping 0.04 (the profile's ``changeDynamics`` settings replace it);
a fixed base holds mass 0. ``loadMJCF`` makes each jointed MJCF body a massless link on the
joint and a fixed link carrying the body's geoms and mass, drops the MJCF default joint
damping, and loads each worldbody geom as a static body of its own (``_world_geoms``).

Contacts. ``collisions: false``: every link in no collision group (``switch_off_collisions``).
``collisions: true``: the loader's own collision shapes and filter (its default group and
mask: every link with a shape meets every other object; no self-collision, as
``URDF_USE_SELF_COLLISION`` is not set, so a model's links do not meet each other, where
physval's reading lets links that share no joint touch); a URDF cylinder is Bullet's convex
hull of it (``URDF_USE_IMPLICIT_CYLINDER`` is not set: the loader's default, what a PyBullet
user gets); meshes as Bullet reads them (a scene with a mesh collision shape does not load:
physval's reading refuses it). The file's contact values (a URDF's ``<contact>``
``lateral_friction``/``restitution``, an MJCF geom's ``friction``) are replaced: the adapter's
``changeDynamics`` sets every model link's restitution and friction, as every scene body's,
to the values whose products give the scene's pairs (the link's scene values
``urdf.LINK_CONTACT``).
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

from validation.engines.frames import matrix_to_quat
from validation.engines.pybullet.trees import BASE
from validation.reference.rotation import quat_to_matrix
from validation.scenario.urdf import IDENTITY, Frame, ModelLayout

LOADERS = {"urdf": "loadURDF", "mjcf": "loadMJCF"}
"""A model file's format -> PyBullet's loader."""

HELD_FRICTION = 0.0
"""N·m or N: a loaded joint's dry friction as PyBullet's step applies it. ``loadURDF`` keeps
``<dynamics friction>`` in ``getJointInfo``'s jointFriction (index 7), but nothing in the
step reads it once ``release_motors`` has switched the velocity motors off: measured on
pybullet_data's pendulum5.urdf (friction 1.0 on every joint) against copies with friction 0
and 100, the joint angles after 1 s of swing agree to the last digit. The file's friction is
dropped: the ``model_fields`` tier reads PyBullet's as this."""

NO_COLLISIONS = (0, 0)
"""``setCollisionFilterGroupMask``'s group and mask of a model link that collides with
nothing (``collisions: false``): no group, and a mask that accepts none."""


def _pybullet():
    """PyBullet, already imported quietly by the adapter (``adapter._import_quietly``)."""
    import pybullet

    return pybullet


@dataclass(frozen=True)
class Part:
    """Where one scene body of a model is in PyBullet: its multibody, link (``BASE`` for the
    base) and the scene body's frame in that link's frame (``ModelLayout.body_in_link``)."""

    body: int
    link: int
    in_link: Frame
    welded: bool
    """A fixed base: PyBullet holds it static, with mass 0 (``useFixedBase``)."""


@dataclass(frozen=True)
class FileJoint:
    """A scene joint of a model as PyBullet holds it: multibody, joint index (the child
    link's), and the file's initial coordinate (the scene's t = 0); ``index`` None for the
    weld of a fixed base (PyBullet has no joint: the base is fixed)."""

    body: int
    index: int | None
    initial: float


@dataclass(frozen=True)
class NativeModel:
    """One model as loaded: its layout, multibodies, and every scene body and joint of it."""

    layout: ModelLayout
    ids: tuple[int, ...]
    parts: dict[str, Part]
    joints: dict[str, FileJoint]
    removed: tuple[str, ...]
    """Bodies the loader made that hold no scene body (MJCF worldbody geoms), removed."""


def inertia_flags(mode: str) -> int:
    """``loadURDF``'s flags for an ``urdf_inertia`` mode (``declaration.INERTIA_MODES``)."""
    return _pybullet().URDF_USE_INERTIA_FROM_FILE if mode == "file" else 0


def _base_frame(layout: ModelLayout) -> Frame:
    w, x, y, z = layout.spec.orientation
    return Frame(
        quat_to_matrix(np.array([w, x, y, z], dtype=float)), np.asarray(layout.spec.position, float)
    )


def _xyzw(rotation: np.ndarray) -> list[float]:
    w, x, y, z = matrix_to_quat(rotation)
    return [float(x), float(y), float(z), float(w)]


def _matrix(xyzw) -> np.ndarray:
    x, y, z, w = xyzw
    return quat_to_matrix(np.array([w, x, y, z], dtype=float))


def load_files(layout: ModelLayout, inertia: str, client: int) -> tuple[int, ...]:
    """The model file through PyBullet's loader, placed at the model's pose: ``loadURDF`` with
    ``basePosition``/``baseOrientation`` (x y z w) and ``useFixedBase``; ``loadMJCF`` (which
    takes no pose) with each of its bodies moved by the model's frame afterwards."""
    pybullet = _pybullet()
    base = _base_frame(layout)
    _add_search_paths(layout, client)
    try:
        return _loaded(layout, base, inertia, client)
    except pybullet.error as error:  # Bullet says why on stderr only (a missing mesh, ...)
        raise ValueError(
            f"PyBullet's {LOADERS[layout.format]} cannot load {layout.path} ({error}; a mesh "
            "the file names may be missing)"
        ) from None


def _loaded(layout: ModelLayout, base: Frame, inertia: str, client: int) -> tuple[int, ...]:
    """``load_files``' calls (``base``: the model's frame in the world)."""
    pybullet = _pybullet()
    if layout.format == "urdf":
        body = pybullet.loadURDF(
            str(layout.path),
            basePosition=base.translation.tolist(),
            baseOrientation=_xyzw(base.rotation),
            useFixedBase=bool(layout.spec.fixed_base),
            flags=inertia_flags(inertia),
            physicsClientId=client,
        )
        return (body,)
    ids = tuple(pybullet.loadMJCF(str(layout.path), physicsClientId=client))
    for body in ids:
        position, orientation = pybullet.getBasePositionAndOrientation(body, physicsClientId=client)
        placed = base * Frame(_matrix(orientation), np.asarray(position))
        pybullet.resetBasePositionAndOrientation(
            body, placed.translation.tolist(), _xyzw(placed.rotation), physicsClientId=client
        )
    return ids


def _add_search_paths(layout: ModelLayout, client: int) -> None:
    """``package://NAME/...`` in the file: Bullet strips ``package://`` and looks for
    ``NAME/...`` beside the file and in its one additional search path, so the first
    ``--package-path NAME=DIR`` sets DIR's parent (PyBullet keeps a single such path)."""
    if layout.package_paths:
        folder = Path(layout.package_paths[0][1]).parent
        _pybullet().setAdditionalSearchPath(str(folder), physicsClientId=client)


def _names(ids: tuple[int, ...], client: int) -> tuple[dict, dict]:
    """(link name -> (body, link index), joint name -> (body, joint index)) over ``ids``."""
    pybullet = _pybullet()
    links, joints = {}, {}
    for body in ids:
        links[pybullet.getBodyInfo(body, physicsClientId=client)[0].decode()] = (body, BASE)
        for index in range(pybullet.getNumJoints(body, physicsClientId=client)):
            info = pybullet.getJointInfo(body, index, physicsClientId=client)
            links[info[12].decode()] = (body, index)
            joints[info[1].decode()] = (body, index)
    return links, joints


def load_model(layout: ModelLayout, inertia: str, client: int) -> NativeModel:
    """The model loaded (``load_files``), every scene body and joint found by the file's link
    and joint names, the loader's bodies that hold none removed (``_world_geoms``), and each
    file joint set to the model's initial position and velocity (``resetJointState``: the
    file's coordinate). ValueError naming the link or joint PyBullet's loader did not make."""
    pybullet = _pybullet()
    ids = load_files(layout, inertia, client)
    links, file_joints = _names(ids, client)
    parts = {}
    for name, link, in_link in zip(layout.bodies, layout.links, layout.body_in_link, strict=True):
        if link not in links:
            raise ValueError(f"{layout.path.name}: PyBullet's loader made no link {link!r}")
        body, index = links[link]
        welded = index == BASE and layout.spec.fixed_base
        parts[name] = Part(body, index, in_link, welded)
    joints = {}
    for name, file_joint in zip(layout.joints, layout.file_joints, strict=True):
        if file_joint is None:
            joints[name] = FileJoint(parts[layout.bodies[0]].body, None, 0.0)
            continue
        if file_joint not in file_joints:
            raise ValueError(f"{layout.path.name}: PyBullet's loader made no joint {file_joint!r}")
        body, index = file_joints[file_joint]
        joints[name] = FileJoint(body, index, layout.initial_position(file_joint))
        if pybullet.getJointInfo(body, index, physicsClientId=client)[3] >= 0:  # movable
            pybullet.resetJointState(
                body,
                index,
                targetValue=layout.initial_position(file_joint),
                targetVelocity=layout.initial_velocity(file_joint),
                physicsClientId=client,
            )
    used = {part.body for part in parts.values()}
    removed = _world_geoms(ids, used, client)
    kept = tuple(body for body in ids if body in used)
    return NativeModel(layout, kept, parts, joints, removed)


def _world_geoms(ids: tuple[int, ...], used: set[int], client: int) -> tuple[str, ...]:
    """Remove the loader's bodies that hold no scene body (``loadMJCF`` makes each worldbody
    geom, a floor or a rail, a static body of its own: the scene has its own ground); their
    names."""
    pybullet = _pybullet()
    removed = []
    for body in ids:
        if body not in used:
            removed.append(pybullet.getBodyInfo(body, physicsClientId=client)[0].decode())
            pybullet.removeBody(body, physicsClientId=client)
    return tuple(removed)


def movable_joints(body: int, client: int) -> list[int]:
    """The joint indices of ``body`` that have coordinates (PyBullet's ``qIndex`` >= 0), in
    PyBullet's order: the order of ``calculateMassMatrix``'s rows."""
    pybullet = _pybullet()
    count = pybullet.getNumJoints(body, physicsClientId=client)
    return [
        j for j in range(count) if pybullet.getJointInfo(body, j, physicsClientId=client)[3] >= 0
    ]


def release_motors(model: NativeModel, client: int) -> None:
    """Switch off the velocity motor PyBullet puts on every joint it loads (a damped hinge
    held at rest: docs/engines.md 2.6): ``VELOCITY_CONTROL`` with force 0."""
    pybullet = _pybullet()
    for body in model.ids:
        joints = movable_joints(body, client)
        pybullet.setJointMotorControlArray(
            body,
            joints,
            pybullet.VELOCITY_CONTROL,
            forces=[0.0] * len(joints),
            physicsClientId=client,
        )


def switch_off_collisions(model: NativeModel, client: int) -> None:
    """``collisions: false``: no link of the model collides with anything (``NO_COLLISIONS``)."""
    pybullet = _pybullet()
    for body in model.ids:
        for link in range(BASE, pybullet.getNumJoints(body, physicsClientId=client)):
            pybullet.setCollisionFilterGroupMask(body, link, *NO_COLLISIONS, physicsClientId=client)


# --- reading back -------------------------------------------------------------------------


def link_frame(body: int, link: int, client: int) -> Frame:
    """The world frame of a link (the file's link frame): its inertial frame's pose (a base's
    ``getBasePositionAndOrientation``, a link's ``getLinkState`` outputs 0-1 with forward
    kinematics) times the inverse of its local inertial frame (``getDynamicsInfo`` 3-4).
    ``getLinkState``'s own link frame (outputs 4-5) is float32-rounded: 1.2e-7 m off on the
    Kuka (docs/engines.md 2.6)."""
    pybullet = _pybullet()
    if link == BASE:
        position, orientation = pybullet.getBasePositionAndOrientation(body, physicsClientId=client)
    else:
        state = pybullet.getLinkState(
            body, link, computeForwardKinematics=1, physicsClientId=client
        )
        position, orientation = state[0], state[1]
    info = pybullet.getDynamicsInfo(body, link, physicsClientId=client)
    local = Frame(_matrix(info[4]), np.asarray(info[3]))
    inverse = Frame(local.rotation.T, -local.rotation.T @ local.translation)
    return Frame(_matrix(orientation), np.asarray(position)) * inverse


@dataclass(frozen=True)
class HeldJoint:
    """A model joint as PyBullet holds it, world frame at the current state."""

    type: int
    """PyBullet's joint type (``JOINT_REVOLUTE``, ...)."""
    anchor: np.ndarray
    axis: np.ndarray
    limits: np.ndarray
    """(2,) relative to the scene's t = 0; NaN without a limit (Bullet's lower > upper)."""
    damping: float


def held_joint(joint: FileJoint, client: int) -> HeldJoint:
    """``getJointInfo``'s type, axis (in the child's *inertial* frame: measured on the A1,
    whose hips' inertial frames Bullet rotates to diagonalize the file's inertia), limits and
    damping, the
    anchor the child link frame's origin (the URDF joint frame's, where the joint is); a fixed
    base's weld: a fixed joint at the base link frame's origin."""
    pybullet = _pybullet()
    unlimited = np.full(2, np.nan)
    if joint.index is None:
        origin = link_frame(joint.body, BASE, client).translation
        return HeldJoint(pybullet.JOINT_FIXED, origin, np.zeros(3), unlimited, 0.0)
    info = pybullet.getJointInfo(joint.body, joint.index, physicsClientId=client)
    frame = link_frame(joint.body, joint.index, client)
    kind, lower, upper = info[2], info[8], info[9]
    moving = kind in (pybullet.JOINT_REVOLUTE, pybullet.JOINT_PRISMATIC)
    limits = np.array([lower, upper]) - joint.initial if moving and lower <= upper else unlimited
    inertial = inertial_state(Part(joint.body, joint.index, IDENTITY, False), client)[1]
    axis = inertial @ np.asarray(info[13]) if moving else np.zeros(3)
    return HeldJoint(kind, frame.translation, axis, limits, float(info[6]))


def inertial_state(part: Part, client: int) -> tuple[np.ndarray, ...]:
    """The part's inertial frame as PyBullet holds it: centre (3,), rotation (3, 3), the
    centre's velocity (3,) and the angular velocity (3,), world frame."""
    pybullet = _pybullet()
    if part.link == BASE:
        position, orientation = pybullet.getBasePositionAndOrientation(
            part.body, physicsClientId=client
        )
        velocity, angular = pybullet.getBaseVelocity(part.body, physicsClientId=client)
    else:
        state = pybullet.getLinkState(
            part.body,
            part.link,
            computeLinkVelocity=1,
            computeForwardKinematics=1,
            physicsClientId=client,
        )
        position, orientation, velocity, angular = state[0], state[1], state[6], state[7]
    return (
        np.asarray(position, float),
        _matrix(orientation),
        np.asarray(velocity, float),
        np.asarray(angular, float),
    )


def scene_body_state(part: Part, client: int) -> list[float]:
    """The scene body's 13 numbers (the adapter's raw row): its centre (link frame times
    ``in_link``), its axes as a quaternion x y z w, that point's velocity and the angular
    velocity, world frame."""
    frame = link_frame(part.body, part.link, client) * part.in_link
    centre, _, velocity, angular = inertial_state(part, client)
    point_velocity = velocity + np.cross(angular, frame.translation - centre)
    return [*frame.translation, *_xyzw(frame.rotation), *point_velocity, *angular]


def held_inertia(part: Part, client: int) -> tuple[float, np.ndarray, np.ndarray]:
    """The part's mass, centre (3,) and world inertia (3, 3) as PyBullet holds them:
    ``getDynamicsInfo``'s mass and principal moments in the inertial frame's pose."""
    pybullet = _pybullet()
    info = pybullet.getDynamicsInfo(part.body, part.link, physicsClientId=client)
    centre, rotation, _, _ = inertial_state(part, client)
    return info[0], centre, rotation @ np.diag(info[2]) @ rotation.T
