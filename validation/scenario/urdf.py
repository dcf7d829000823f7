"""Robot models in a scene: ``models:`` entries read from URDF or MJCF files and expanded, at
load, into the scene's own bodies and joints (issue 36, the ``model_loader=physval`` path).

The URDF reader (plain ``xml.etree``) takes from a URDF:

- links: ``<inertial>`` (origin xyz rpy, mass, inertia ixx..izz); of the visual and collision
  geometry only the mesh files (which must exist: ``validation/scenario/packages.py``);
- joints: revolute and continuous (a physval hinge), prismatic (a slider), fixed; origin
  xyz rpy, axis, limits (revolute and prismatic) and dynamics damping. Floating and planar
  joints are refused.

An MJCF file (``.xml``) is read by ``validation/scenario/mjcf.py`` into the same links and
joints (``validation/scenario/robot.py``); everything below serves both.

Bodies are placed at each link's inertial frame: a physval body's position is its centre of
mass, so its frame is the link's ``<inertial>`` origin with the inertial rotation (rpy)
folded into its orientation, and its inertia is the URDF's matrix as written (about the
inertial frame's axes). A link without ``<inertial>`` or with zero mass cannot be a body
(physval masses are positive): mounted by a fixed joint (or the root of a fixed base) it
carries nothing, so it is dropped and its children are mounted on its parent (the world for a
fixed root) through the composed frames; on any other joint, or as a free root, it is refused.

Forward kinematics poses every body from the model's ``position``, ``orientation`` and
``joint_positions``; ``joint_velocities`` give the bodies' velocities through the same
chain, so the stated velocities satisfy the joints. A joint not in ``joint_positions`` starts
at 0, or at the limit nearest 0 when its limits exclude 0 (the A1's knees). Limits (in the
file: absolute) become physval's (relative to t = 0) by subtracting the joint's initial
position.

Joint friction (URDF ``<dynamics friction>``, MJCF ``frictionloss``) is read, but physval's
scene joints have none: it is kept in ``ModelLayout.frictions`` for the ``model_fields`` tier
(an engine that drops the file's friction differs there), not in the expanded joints.

Shapes. With ``collisions: false`` (the default) each body gets a ``PLACEHOLDER_RADIUS``
sphere with the link's inertia stated explicitly and ``collides: false``: no model link
touches anything, in any engine (the capability ``non_colliding``). With ``collisions: true``
each link's collision geometry (URDF ``<collision>``'s ``<origin>`` and ``<geometry>``
sphere, box, cylinder or PyBullet's capsule; MJCF geoms, ``validation/scenario/mjcf.py``)
becomes its body's shape (``SHAPES``), placed by the shape's ``offset`` and ``orientation``
in the body's frame (the link's inertial frame: the inertial frame's inverse times the
element's origin) with ``collides: true``; its friction and restitution are the scene's
body defaults (0; ``pairs`` may set them). One shape per body, so the model is refused at
``models[i].collisions``, one line naming the link, when a link has several collision
elements, a mesh (or any geometry without a scene shape), or is massless with geometry (it
would be folded into its parent's body); a link without a collision element keeps the
placeholder with ``collides: false``.
"""

from __future__ import annotations

import importlib.util
import xml.etree.ElementTree as ElementTree
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from pydantic import ValidationError

from validation.scenario.mjcf import read_mjcf
from validation.scenario.packages import missing_file
from validation.scenario.robot import (
    IDENTITY,
    MASSLESS,
    Frame,
    Geometry,
    Joint,
    Link,
    Robot,
    rotation_class,
    xml_root,
)
from validation.scenario.schema import BodySpec, ModelSpec

PLACEHOLDER_RADIUS = 0.01
"""m: the sphere each model body is given (its inertia is the link's, stated explicitly); a
link's size, not its contact shape."""

SHAPES = {
    "sphere": lambda sizes: {"type": "sphere", "radius": sizes[0]},
    "box": lambda sizes: {"type": "box", "half_extents": list(sizes)},
    "cylinder": lambda sizes: {"type": "cylinder", "radius": sizes[0], "half_length": sizes[1]},
    "capsule": lambda sizes: {"type": "capsule", "radius": sizes[0], "half_length": sizes[1]},
}
"""A collision element's kind (``robot.Geometry``) -> the scene shape it becomes under
``collisions: true``; any other kind (a mesh, a plane, an ellipsoid) refuses the model."""

LINK_CONTACT = {"restitution": 0.0, "friction": 0.0}
"""A model link's contact values as a scene body (the scene's body defaults; a ``pairs:``
entry may set a pair's): the native loaders give the file's shapes the pairs these make
(``validation/engines/*/`` ``native.py``, ``models.py``), so native and physval runs of a
scene meet the same contacts."""

PACKAGE_PREFIX = "pkg:"
"""A ``file`` that starts with this names a path inside an installed Python package."""

FORMAT_NAMES = {"urdf": "URDF", "mjcf": "MJCF"}
"""A ``ModelLayout.format`` -> the name messages give it."""

FIXED_BASE_JOINT = "fixed_base"
"""The name (after the model's prefix) of the fixed joint that holds a fixed base's root link
to the world."""

JOINT_KINDS = {"revolute": "hinge", "continuous": "hinge", "prismatic": "slider", "fixed": "fixed"}
"""URDF joint type -> physval joint type (others are refused)."""

LIMITED_KINDS = ("revolute", "prismatic")
"""URDF joint types whose ``<limit lower upper>`` bound the motion."""

FREE_ROOT_HINT = {
    "urdf": "set fixed_base: true",
    "mjcf": "set fixed_base: true, or make the one top-level <body> free with a <freejoint/>",
}
"""What to do about a ``fixed_base: false`` whose root has no mass, per format."""


PACKAGE_PATHS: dict[str, str] = {}
"""``package://NAME`` -> DIR, the run's ``--package-path`` flags (set by the command before any
scene is loaded; carried to the workers in each ``ModelLayout``)."""


class ModelError(ValueError):
    """A model that cannot be read; ``field`` is the ``models[i]`` field it belongs to."""

    def __init__(self, field: str, message: str):
        super().__init__(message)
        self.field = field


@dataclass(frozen=True)
class ModelLayout:
    """How one ``models`` entry maps onto the scene: what a native loader (an engine reading
    the file itself, ``model_loader=native``) needs to name and place its own bodies and
    joints in the scene's terms. Rebuilt from the file by ``model_layouts``; the same reading
    as the expansion.

    Attributes:
        name: the model's name, the prefix of its bodies and joints.
        path: the model file, resolved. format: ``"urdf"`` or ``"mjcf"``.
        spec: the scene's entry (position, orientation, fixed_base, joint_positions,
            joint_velocities, collisions).
        bodies: the scene's body names from this model, in scene order.
        links: the file's link (URDF ``<link>``, MJCF ``<body>``) of each body.
        body_in_link: each body's frame (origin at its centre of mass, axes the scene body's)
            in its link's frame: a native engine's link pose times this is the scene body's.
        joints: the scene's joint names from this model, in scene order.
        file_joints: each one's name in the file; None for the weld of a fixed base.
        root_link: the file's root link.
        package_paths: ``(NAME, DIR)`` pairs that resolve ``package://NAME/...`` in the file
            (the run's ``--package-path``), beside the file's own folder
            (``validation.scenario.packages.resolve`` finds a mesh with them).
        starts: ``(file joint, coordinate at t = 0)`` of every movable joint: the scene's
            ``joint_positions`` entry, else 0 clamped into the joint's limits.
        frictions: each of ``joints``' dry friction in the file (N·m or N; URDF ``<dynamics
            friction>``, MJCF ``frictionloss``; 0 for a weld): physval's scene joints have no
            friction, so this is the only place it is kept (the ``model_fields`` tier).
    """

    name: str
    path: Path
    format: str
    spec: ModelSpec
    bodies: tuple[str, ...]
    links: tuple[str, ...]
    body_in_link: tuple[Frame, ...]
    joints: tuple[str, ...]
    file_joints: tuple[str | None, ...]
    root_link: str
    package_paths: tuple[tuple[str, str], ...] = ()
    starts: tuple[tuple[str, float], ...] = ()
    frictions: tuple[float, ...] = ()

    def friction(self, joint: str) -> float:
        """The file's dry friction of the scene joint ``joint`` (one of ``joints``)."""
        return self.frictions[self.joints.index(joint)] if self.frictions else 0.0

    def initial_position(self, file_joint: str) -> float:
        """The file joint's coordinate at t = 0 (rad or m, the file's convention): the scene's
        ``joint_positions`` entry, else 0, or the limit nearest 0 when the joint's limits
        exclude 0. A tree coordinate (``CompiledScene.joint_tree``, relative to t = 0) is the
        file's coordinate minus this."""
        return float(dict(self.starts).get(file_joint, 0.0))

    def initial_velocity(self, file_joint: str) -> float:
        """The file joint's rate at t = 0 (rad/s or m/s): ``joint_velocities``, else 0."""
        return float(self.spec.joint_velocities.get(f"{self.name}/{file_joint}", 0.0))


# --- reading ------------------------------------------------------------------------------


def _numbers(text: str | None, count: int, default: float = 0.0) -> np.ndarray:
    values = (text or "").split()
    if not values:
        return np.full(count, default)
    if len(values) != count:
        raise ValueError(f"expected {count} numbers; got {text!r}")
    return np.array([float(v) for v in values])


def _origin(element: ElementTree.Element | None) -> Frame:
    origin = None if element is None else element.find("origin")
    if origin is None:
        return IDENTITY
    rpy = _numbers(origin.get("rpy"), 3)
    return Frame(
        rotation_class().from_euler("xyz", rpy).as_matrix(), _numbers(origin.get("xyz"), 3)
    )


def _half(numbers: np.ndarray) -> tuple[float, ...]:
    return tuple(float(v) / 2.0 for v in numbers)


URDF_GEOMETRY = {
    "sphere": lambda e: (float(e.get("radius", "0")),),
    "box": lambda e: _half(_numbers(e.get("size"), 3)),
    "cylinder": lambda e: (float(e.get("radius", "0")), float(e.get("length", "0")) / 2.0),
    "capsule": lambda e: (float(e.get("radius", "0")), float(e.get("length", "0")) / 2.0),
}
"""A URDF ``<geometry>`` child -> its sizes in physval's terms (``robot.Geometry``): a box's
``size`` is its full extents, a cylinder's ``length`` its full length along z (``capsule``,
PyBullet's extension, the same); any other (``mesh``) has no sizes."""


def _geometry(collision: ElementTree.Element) -> Geometry:
    """A ``<collision>``'s geometry and its frame in the link (``<origin>``)."""
    shape = next(iter(collision.find("geometry")), None)
    if shape is None:
        raise ValueError("a <collision> with an empty <geometry>")
    read = URDF_GEOMETRY.get(shape.tag)
    return Geometry(shape.tag, read(shape) if read else (), _origin(collision))


def _link(element: ElementTree.Element) -> Link:
    geometry = tuple(_geometry(c) for c in element.findall("collision"))
    inertial = element.find("inertial")
    if inertial is None:
        return Link(element.get("name", ""), *MASSLESS, geometry)
    mass = float(inertial.find("mass").get("value", "0"))
    if mass < 0:
        raise ValueError(f"link {element.get('name')!r} has a negative mass {mass}")
    values = inertial.find("inertia")
    get = (lambda key: float(values.get(key, "0"))) if values is not None else (lambda key: 0.0)
    xx, yy, zz, xy, xz, yz = (get(k) for k in ("ixx", "iyy", "izz", "ixy", "ixz", "iyz"))
    inertia = np.array([[xx, xy, xz], [xy, yy, yz], [xz, yz, zz]])
    return Link(element.get("name", ""), _origin(inertial), mass, inertia, geometry)


def _joint(element: ElementTree.Element) -> Joint:
    name, kind = element.get("name", ""), element.get("type", "")
    if kind not in JOINT_KINDS:
        raise ValueError(
            f"joint {name!r} is {kind!r}: physval reads {', '.join(JOINT_KINDS)} joints"
        )
    axis = _numbers(
        element.find("axis").get("xyz") if element.find("axis") is not None else None, 3
    )
    if not axis.any():
        axis = np.array([1.0, 0.0, 0.0])  # the URDF default
    limit = element.find("limit")
    limits = None
    if kind in LIMITED_KINDS and limit is not None:
        limits = (float(limit.get("lower", "0")), float(limit.get("upper", "0")))
        if not limits[0] < limits[1]:
            raise ValueError(f"joint {name!r} has limits {list(limits)}: expected lower < upper")
    dynamics = element.find("dynamics")
    dynamic = (lambda key: float(dynamics.get(key, "0"))) if dynamics is not None else _zero
    return Joint(
        name,
        JOINT_KINDS[kind],
        element.find("parent").get("link", ""),
        element.find("child").get("link", ""),
        _origin(element),
        axis / np.linalg.norm(axis),
        limits,
        dynamic("damping"),
        friction=dynamic("friction"),
    )


def _zero(key: str) -> float:
    return 0.0


def read_urdf(path: Path) -> Robot:
    """The links and joints of the URDF at ``path``; ValueError saying what is wrong."""
    root = xml_root(path)
    try:
        links = {e.get("name", ""): _link(e) for e in root.findall("link")}
        joints = [_joint(e) for e in root.findall("joint")]
        robot = Robot(links, joints, "urdf").assemble()
    except (AttributeError, TypeError, ValueError) as error:
        raise ValueError(f"{path.name}: {error}") from None
    robot.meshes = [
        mesh.get("filename", "")
        for link in root.findall("link")
        for part in (*link.findall("visual"), *link.findall("collision"))
        for mesh in part.iter("mesh")
    ]
    return robot


READERS = {".urdf": ("urdf", read_urdf), ".xml": ("mjcf", read_mjcf)}
"""A model file's suffix -> its ``ModelLayout.format`` and its reader."""


def model_path(file: str, scene: Path) -> Path:
    """``file`` resolved: ``pkg:NAME/path`` inside the installed package NAME's folder,
    anything else relative to the scene file's folder."""
    if not file.startswith(PACKAGE_PREFIX):
        return scene.parent / file
    package, _, inside = file[len(PACKAGE_PREFIX) :].partition("/")
    try:
        spec = importlib.util.find_spec(package)
    except (ImportError, ValueError):
        spec = None
    if spec is None or not spec.submodule_search_locations:
        raise ValueError(f"no installed Python package {package!r} (from {file!r})")
    return Path(next(iter(spec.submodule_search_locations))) / inside


# --- expansion ----------------------------------------------------------------------------


def _motion(joint: Joint, q: float) -> Frame:
    """The child link's frame in the joint frame at coordinate ``q``."""
    if joint.kind == "hinge":
        return Frame(rotation_class().from_rotvec(joint.axis * q).as_matrix(), np.zeros(3))
    if joint.kind == "slider":
        return Frame(np.eye(3), joint.axis * q)
    return IDENTITY


@dataclass
class _Placed:
    """A link's world frame and the velocity of its frame origin at t = 0."""

    frame: Frame
    velocity: np.ndarray
    angular_velocity: np.ndarray
    body: str | None  # the physval body it is part of (None: the world)


def _quaternion(rotation: np.ndarray) -> list[float]:
    x, y, z, w = rotation_class().from_matrix(rotation).as_quat()
    return [float(w), float(x), float(y), float(z)]


def _valid_body(link: Link, body: dict) -> dict:
    """``body`` (a link's scene entry) when the schema takes it; else ``ModelError`` at
    ``file`` naming the link (a URDF's inertia no rigid body has, say), not the expanded
    ``bodies[k]`` the scene file does not show."""
    try:
        BodySpec.model_validate(body)
    except ValidationError as error:
        first = error.errors(include_url=False)[0]
        reason = first["ctx"]["error"] if "ctx" in first else first["msg"]
        field = ".".join(str(part) for part in first["loc"])
        raise ModelError("file", f"link {link.name!r}: {field}: {reason}") from None
    return body


def _start(joint: Joint, stated: float | None) -> float:
    """A movable joint's coordinate at t = 0: ``stated`` (the scene's ``joint_positions``),
    else 0 moved into the joint's limits (the limit nearest 0 when they exclude it)."""
    if stated is not None:
        return stated
    return 0.0 if joint.limits is None else float(np.clip(0.0, *joint.limits))


class _Expansion:
    """One model's bodies and joints, built parents first."""

    def __init__(self, model: ModelSpec, robot: Robot):
        self.model, self.robot = model, robot
        self.path = Path()
        self.bodies: list[dict] = []
        self.joints: list[dict] = []
        self.links: list[str] = []
        self.body_in_link: list[Frame] = []
        self.file_joints: list[str | None] = []
        self.frictions: list[float] = []
        self.starts: dict[str, float] = {}

    def name(self, text: str) -> str:
        return f"{self.model.name}/{text}"

    def run(self) -> None:
        base = Frame(
            rotation_class()
            .from_quat([*self.model.orientation[1:], self.model.orientation[0]])
            .as_matrix(),
            np.array(self.model.position, dtype=float),
        )
        root = self.robot.links[self.robot.root]
        placed = _Placed(base, np.zeros(3), np.zeros(3), None)
        if root.mass > 0:
            self.add_body(root, placed)
            if self.model.fixed_base:
                self.file_joints.append(None)
                self.frictions.append(0.0)
                self.joints.append(
                    {
                        "name": self.name(FIXED_BASE_JOINT),
                        "type": "fixed",
                        "parent": "world",
                        "child": placed.body,
                        "anchor": base.translation.tolist(),
                    }
                )
        elif self.model.fixed_base:
            self.fold(root)
        else:
            raise ModelError(
                "fixed_base",
                f"the root link {root.name!r} has no mass: a free root needs one "
                f"({FREE_ROOT_HINT[self.robot.format]})",
            )
        self.descend(root.name, placed)

    def shape(self, link: Link) -> tuple[dict, bool]:
        """The body's shape and whether it collides: the link's one collision element placed
        in the body's frame (the link's inertial frame) under ``collisions: true``; else, or
        for a link without one, the ``PLACEHOLDER_RADIUS`` sphere that touches nothing.
        ``ModelError`` at ``collisions`` for a link of several elements or of a kind with no
        scene shape (``SHAPES``)."""
        placeholder = {"type": "sphere", "radius": PLACEHOLDER_RADIUS}
        if not self.model.collisions or not link.geometry:
            return placeholder, False
        if len(link.geometry) > 1:
            raise ModelError(
                "collisions",
                f"link {link.name!r} has {len(link.geometry)} collision elements: physval "
                "gives a body one shape",
            )
        (geometry,) = link.geometry
        if geometry.kind not in SHAPES:
            raise ModelError(
                "collisions",
                f"link {link.name!r}'s collision geometry is {geometry.kind!r}: physval's "
                f"shapes are {', '.join(SHAPES)}",
            )
        inverse = Frame(
            link.inertial.rotation.T, -link.inertial.rotation.T @ link.inertial.translation
        )
        in_body = inverse * geometry.frame
        shape = SHAPES[geometry.kind](geometry.sizes)
        shape["offset"] = in_body.translation.tolist()
        shape["orientation"] = _quaternion(in_body.rotation)
        return shape, True

    def fold(self, link: Link) -> None:
        """A massless link about to be folded into its parent (or the world): refused under
        ``collisions: true`` when it has collision geometry (it would be a second shape of
        its parent's body, or a shape of the world)."""
        if self.model.collisions and link.geometry:
            raise ModelError(
                "collisions",
                f"link {link.name!r} has no mass: its collision geometry would belong to the "
                "body it is folded into (physval gives a body one shape)",
            )

    def add_body(self, link: Link, placed: _Placed) -> None:
        shape, collides = self.shape(link)
        frame = placed.frame * link.inertial
        centre_velocity = placed.velocity + np.cross(
            placed.angular_velocity, frame.translation - placed.frame.translation
        )
        self.bodies.append(
            _valid_body(
                link,
                {
                    "name": self.name(link.name),
                    "shape": shape,
                    "collides": collides,
                    **LINK_CONTACT,
                    "mass": link.mass,
                    "inertia": link.inertia.tolist(),
                    "position": frame.translation.tolist(),
                    "orientation": _quaternion(frame.rotation),
                    "velocity": centre_velocity.tolist(),
                    "angular_velocity": placed.angular_velocity.tolist(),
                },
            )
        )
        placed.body = self.name(link.name)
        self.links.append(link.name)
        self.body_in_link.append(link.inertial)

    def descend(self, parent: str, above: _Placed) -> None:
        for joint in self.robot.children.get(parent, []):
            self.place(joint, above)

    def place(self, joint: Joint, above: _Placed) -> None:
        """The joint's child link posed and moving (the joint frame turned or slid by its
        coordinate, the child's frame carried along from the pivot), and added as a body
        with its joint, or folded into its parent when it has no mass."""
        name = self.name(joint.name)
        q = 0.0
        if joint.kind != "fixed":
            q = self.starts[joint.name] = _start(joint, self.model.joint_positions.get(name))
        rate = self.model.joint_velocities.get(name, 0.0)
        at_joint = above.frame * joint.origin
        pivot = at_joint * _motion(joint, q)
        frame = pivot * joint.child_in_joint
        axis = at_joint.rotation @ joint.axis
        pivot_velocity = above.velocity + np.cross(
            above.angular_velocity, pivot.translation - above.frame.translation
        )
        if joint.kind == "slider":
            pivot_velocity = pivot_velocity + axis * rate
        angular_velocity = above.angular_velocity + (axis * rate if joint.kind == "hinge" else 0.0)
        placed = _Placed(
            frame,
            pivot_velocity + np.cross(angular_velocity, frame.translation - pivot.translation),
            angular_velocity,
            above.body,
        )
        link = self.robot.links[joint.child]
        if link.mass <= 0:
            if joint.kind != "fixed":
                raise ModelError(
                    "file", f"link {link.name!r} has no mass but moves on joint {joint.name!r}"
                )
            self.fold(link)
            self.descend(link.name, placed)  # a massless fixed link carries nothing
            return
        limits = None
        if joint.limits is not None:
            limits = (joint.limits[0] - q, joint.limits[1] - q)
            if not limits[0] <= 0.0 <= limits[1]:
                raise ModelError(
                    "joint_positions",
                    f"{name}: {q} is outside the {FORMAT_NAMES[self.robot.format]}'s "
                    f"limits {list(joint.limits)}",
                )
        self.add_body(link, placed)
        record = {
            "name": name,
            "type": joint.kind,
            "parent": above.body or "world",
            "child": placed.body,
            "anchor": pivot.translation.tolist(),
            "damping": joint.damping,
        }
        if joint.kind != "fixed":
            record["axis"] = axis.tolist()
        if limits is not None:
            record["limits"] = list(limits)
        self.joints.append(record)
        self.file_joints.append(joint.name if joint.in_file else None)
        self.frictions.append(joint.friction)
        self.descend(link.name, placed)


def _movable_joints(model: ModelSpec, robot: Robot) -> list[str]:
    return [model.name + "/" + j.name for j in robot.joints if j.kind != "fixed"]


def expand_model(
    model: ModelSpec, scene: Path, meshes: bool = True
) -> tuple[list[dict], list[dict]]:
    """The bodies and joints of ``model`` (a scene's ``models`` entry, read relative to the
    scene file ``scene``), as scene entries; ``ModelError`` at the field that is wrong.
    ``meshes``: check that the mesh files the model names exist (False: a scene that loaded,
    read again where the run's ``--package-path`` may not be set, as in a worker)."""
    expansion = _expanded(model, scene, meshes)
    return expansion.bodies, expansion.joints


def _expanded(model: ModelSpec, scene: Path, meshes: bool) -> _Expansion:
    try:
        path = model_path(model.file, scene)
    except ValueError as error:
        raise ModelError("file", str(error)) from None
    if path.suffix.lower() not in READERS:
        raise ModelError("file", f"expected a URDF (.urdf) or MJCF (.xml) file; got {path.name!r}")
    if not path.is_file():
        raise ModelError("file", f"no such file: {path}")
    try:
        robot = READERS[path.suffix.lower()][1](path)
    except ValueError as error:
        raise ModelError("file", str(error)) from None
    missing = missing_file(robot.meshes, path, PACKAGE_PATHS) if meshes else None
    if missing:
        raise ModelError("file", f"{path.name}: {missing}")
    movable = _movable_joints(model, robot)
    for key, stated in (
        ("joint_positions", model.joint_positions),
        ("joint_velocities", model.joint_velocities),
    ):
        unknown = sorted(set(stated) - set(movable))
        if unknown:
            raise ModelError(
                key,
                f"no movable joint {unknown[0]!r} in {path.name}; its joints: "
                + ", ".join(movable),
            )
    expansion = _Expansion(model, robot)
    expansion.path = path
    expansion.run()
    return expansion


def expand_models(
    data: dict, scene: Path, meshes: bool = True
) -> tuple[dict, list[tuple[tuple, str]]]:
    """``data`` (a scene document) with its ``models`` expanded into ``bodies`` and
    ``joints``, and the problems found (location, message). Entries the schema refuses are
    left for the schema to report; ``meshes`` as in ``expand_model``."""
    entries = data.get("models")
    if not isinstance(entries, list) or not entries:
        return data, []
    try:
        models = [ModelSpec.model_validate(entry) for entry in entries]
    except ValidationError:
        return data, []
    bodies = list(data.get("bodies") or [])
    joints = list(data.get("joints") or [])
    problems = []
    for i, model in enumerate(models):
        if any(other.name == model.name for other in models[:i]):
            problems.append(
                (("models", i, "name"), f"expected a unique model name; {model.name!r} is taken")
            )
            continue
        try:
            more_bodies, more_joints = expand_model(model, scene, meshes)
        except ModelError as error:
            problems.append((("models", i, error.field), f"{error}"))
            continue
        bodies += more_bodies
        joints += more_joints
    if problems:
        return data, problems  # the scene as written: its own problems are reported with these
    return {**data, "bodies": bodies, "joints": joints}, problems


def model_layouts(scenario) -> tuple[ModelLayout, ...]:
    """Each of the scenario's ``models`` as a ``ModelLayout`` (the file read again, as the
    scene's load read it: a scene that loaded reads the same)."""
    scene = Path(scenario.source or ".")
    layouts = []
    for model in scenario.models:
        expansion = _expanded(model, scene, meshes=False)
        layouts.append(
            ModelLayout(
                name=model.name,
                path=expansion.path,
                format=expansion.robot.format,
                spec=model,
                bodies=tuple(b["name"] for b in expansion.bodies),
                links=tuple(expansion.links),
                body_in_link=tuple(expansion.body_in_link),
                joints=tuple(j["name"] for j in expansion.joints),
                file_joints=tuple(expansion.file_joints),
                root_link=expansion.robot.root,
                package_paths=tuple(sorted(PACKAGE_PATHS.items())),
                starts=tuple(expansion.starts.items()),
                frictions=tuple(expansion.frictions),
            )
        )
    return tuple(layouts)


def with_joint_state(scenario, positions: dict[str, float], velocities: dict[str, float]):
    """The scenario with its models re-expanded at other joint positions and velocities
    (prefixed joint names -> rad or m, rad/s or m/s; a model joint not named keeps its
    stated value): the same scene at another configuration, for the tiers' probes of engines
    that cannot be set to a state (``validation.measure.tiers``)."""
    from validation.scenario.schema import Scenario

    layouts = model_layouts(scenario)
    owned_bodies = {name for layout in layouts for name in layout.bodies}
    owned_joints = {name for layout in layouts for name in layout.joints}
    data = scenario.model_dump()
    data["bodies"] = [b for b in data["bodies"] if b["name"] not in owned_bodies]
    data["joints"] = [j for j in data["joints"] if j["name"] not in owned_joints]
    for entry in data["models"]:
        prefix = entry["name"] + "/"
        for key, stated in (("joint_positions", positions), ("joint_velocities", velocities)):
            mine = {k: v for k, v in stated.items() if k.startswith(prefix)}
            entry[key] = {**entry[key], **mine}
    expanded, problems = expand_models(data, Path(scenario.source or "."), meshes=False)
    if problems:
        location, message = problems[0]
        raise ModelError(str(location[-1]), message)
    return Scenario.model_validate({**expanded, "source": scenario.source})
