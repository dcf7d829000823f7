"""Robot models in a scene: ``models:`` entries read from URDF files and expanded, at load,
into the scene's own bodies and joints (issue 36, the ``model_loader=physval`` path).

The reader (plain ``xml.etree``) takes from a URDF:

- links: ``<inertial>`` (origin xyz rpy, mass, inertia ixx..izz); visual and collision
  geometry is not read;
- joints: revolute and continuous (a physval hinge), prismatic (a slider), fixed; origin
  xyz rpy, axis, limits (revolute and prismatic) and dynamics damping. Floating and planar
  joints are refused.

Bodies are placed at each link's inertial frame: a physval body's position is its centre of
mass, so its frame is the link's ``<inertial>`` origin with the inertial rotation (rpy)
folded into its orientation, and its inertia is the URDF's matrix as written (about the
inertial frame's axes). A link without ``<inertial>`` or with zero mass cannot be a body
(physval masses are positive): mounted by a fixed joint (or the root of a fixed base) it
carries nothing, so it is dropped and its children are mounted on its parent (the world for a
fixed root) through the composed frames; on any other joint, or as a free root, it is refused.

Forward kinematics poses every body from the model's ``position``, ``orientation`` and
``joint_positions``; ``joint_velocities`` give the bodies' velocities through the same
chain, so the stated velocities satisfy the joints. Limits (URDF: absolute) become physval's
(relative to t = 0) by subtracting the joint's initial position.

Shapes: the model's collision geometry is not read (``collisions: true`` is refused); each
body gets a ``PLACEHOLDER_RADIUS`` sphere with the link's inertia stated explicitly. The
placeholder is a real sphere to every engine: keep the ground and other bodies clear of the
model.
"""

from __future__ import annotations

import importlib.util
import xml.etree.ElementTree as ElementTree
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
from pydantic import ValidationError

from validation.scenario.schema import ModelSpec

PLACEHOLDER_RADIUS = 0.01
"""m: the sphere each model body is given (its inertia is the link's, stated explicitly); a
link's size, not its contact shape."""

PACKAGE_PREFIX = "pkg:"
"""A ``file`` that starts with this names a path inside an installed Python package."""

URDF_SUFFIX = ".urdf"

FIXED_BASE_JOINT = "fixed_base"
"""The name (after the model's prefix) of the fixed joint that holds a fixed base's root link
to the world."""

JOINT_KINDS = {"revolute": "hinge", "continuous": "hinge", "prismatic": "slider", "fixed": "fixed"}
"""URDF joint type -> physval joint type (others are refused)."""

LIMITED_KINDS = ("revolute", "prismatic")
"""URDF joint types whose ``<limit lower upper>`` bound the motion."""


class ModelError(ValueError):
    """A model that cannot be read; ``field`` is the ``models[i]`` field it belongs to."""

    def __init__(self, field: str, message: str):
        super().__init__(message)
        self.field = field


@dataclass(frozen=True)
class Frame:
    """A rigid transform: rotation (3, 3) and translation (3,)."""

    rotation: np.ndarray
    translation: np.ndarray

    def __mul__(self, other: Frame) -> Frame:
        return Frame(
            self.rotation @ other.rotation, self.rotation @ other.translation + self.translation
        )


IDENTITY = Frame(np.eye(3), np.zeros(3))


@dataclass(frozen=True)
class Link:
    """A URDF link's inertial frame (in the link frame), mass and inertia (inertial axes)."""

    name: str
    inertial: Frame
    mass: float
    inertia: np.ndarray


@dataclass(frozen=True)
class Joint:
    """A URDF joint: its origin (in the parent link's frame), axis (joint frame), limits."""

    name: str
    kind: str
    parent: str
    child: str
    origin: Frame
    axis: np.ndarray
    limits: tuple[float, float] | None
    damping: float


@dataclass
class Robot:
    """A URDF's links and joints, and its root link."""

    links: dict[str, Link]
    joints: list[Joint]
    root: str = ""
    children: dict[str, list[Joint]] = field(default_factory=dict)


def _rotation():
    """SciPy's ``Rotation``, imported when a model is read (``physval check`` of a scene
    without models loads no SciPy: ``tests/test_architecture.py``)."""
    from scipy.spatial.transform import Rotation

    return Rotation


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
            (the run's ``--package-path``), beside the file's own folder.
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

    def initial_position(self, file_joint: str) -> float:
        """The file joint's coordinate at t = 0 (rad or m, the file's convention): the scene's
        ``joint_positions`` entry, else 0. A tree coordinate (``CompiledScene.joint_tree``,
        relative to t = 0) is the file's coordinate minus this."""
        return float(self.spec.joint_positions.get(f"{self.name}/{file_joint}", 0.0))

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
    return Frame(_rotation().from_euler("xyz", rpy).as_matrix(), _numbers(origin.get("xyz"), 3))


def _link(element: ElementTree.Element) -> Link:
    inertial = element.find("inertial")
    if inertial is None:
        return Link(element.get("name", ""), IDENTITY, 0.0, np.zeros((3, 3)))
    mass = float(inertial.find("mass").get("value", "0"))
    if mass < 0:
        raise ValueError(f"link {element.get('name')!r} has a negative mass {mass}")
    values = inertial.find("inertia")
    get = (lambda key: float(values.get(key, "0"))) if values is not None else (lambda key: 0.0)
    xx, yy, zz, xy, xz, yz = (get(k) for k in ("ixx", "iyy", "izz", "ixy", "ixz", "iyz"))
    inertia = np.array([[xx, xy, xz], [xy, yy, yz], [xz, yz, zz]])
    return Link(element.get("name", ""), _origin(inertial), mass, inertia)


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
    return Joint(
        name,
        kind,
        element.find("parent").get("link", ""),
        element.find("child").get("link", ""),
        _origin(element),
        axis / np.linalg.norm(axis),
        limits,
        float(dynamics.get("damping", "0")) if dynamics is not None else 0.0,
    )


def read_urdf(path: Path) -> Robot:
    """The links and joints of the URDF at ``path``; ValueError saying what is wrong."""
    try:
        root = ElementTree.parse(path).getroot()
    except (OSError, ElementTree.ParseError) as error:
        raise ValueError(f"cannot read {path}: {error}") from None
    try:
        links = {e.get("name", ""): _link(e) for e in root.findall("link")}
        joints = [_joint(e) for e in root.findall("joint")]
    except (AttributeError, TypeError, ValueError) as error:
        raise ValueError(f"{path.name}: {error}") from None
    robot = Robot(links, joints)
    for joint in joints:
        unknown = {joint.parent, joint.child} - set(links)
        if unknown:
            raise ValueError(f"{path.name}: joint {joint.name!r} names no link {unknown.pop()!r}")
    children = [j.child for j in joints]
    if len(children) != len(set(children)):
        raise ValueError(f"{path.name}: a link is the child of two joints (not a tree)")
    roots = [name for name in links if name not in children]
    if len(roots) != 1:
        raise ValueError(f"{path.name}: expected one root link; found {roots}")
    robot.root = roots[0]
    for joint in joints:
        robot.children.setdefault(joint.parent, []).append(joint)
    return robot


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
    if JOINT_KINDS[joint.kind] == "hinge":
        return Frame(_rotation().from_rotvec(joint.axis * q).as_matrix(), np.zeros(3))
    if JOINT_KINDS[joint.kind] == "slider":
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
    x, y, z, w = _rotation().from_matrix(rotation).as_quat()
    return [float(w), float(x), float(y), float(z)]


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

    def name(self, text: str) -> str:
        return f"{self.model.name}/{text}"

    def run(self) -> None:
        base = Frame(
            _rotation()
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
                self.joints.append(
                    {
                        "name": self.name(FIXED_BASE_JOINT),
                        "type": "fixed",
                        "parent": "world",
                        "child": placed.body,
                        "anchor": base.translation.tolist(),
                    }
                )
        elif not self.model.fixed_base:
            raise ModelError(
                "fixed_base",
                f"the root link {root.name!r} has no mass: "
                "a free root needs one (set fixed_base: true)",
            )
        self.descend(root.name, placed)

    def add_body(self, link: Link, placed: _Placed) -> None:
        frame = placed.frame * link.inertial
        centre_velocity = placed.velocity + np.cross(
            placed.angular_velocity, frame.translation - placed.frame.translation
        )
        self.bodies.append(
            {
                "name": self.name(link.name),
                "shape": {"type": "sphere", "radius": PLACEHOLDER_RADIUS},
                "mass": link.mass,
                "inertia": link.inertia.tolist(),
                "position": frame.translation.tolist(),
                "orientation": _quaternion(frame.rotation),
                "velocity": centre_velocity.tolist(),
                "angular_velocity": placed.angular_velocity.tolist(),
            }
        )
        placed.body = self.name(link.name)
        self.links.append(link.name)
        self.body_in_link.append(link.inertial)

    def descend(self, parent: str, above: _Placed) -> None:
        for joint in self.robot.children.get(parent, []):
            self.place(joint, above)

    def place(self, joint: Joint, above: _Placed) -> None:
        name = self.name(joint.name)
        q = self.model.joint_positions.get(name, 0.0)
        rate = self.model.joint_velocities.get(name, 0.0)
        kind = JOINT_KINDS[joint.kind]
        at_joint = above.frame * joint.origin
        frame = at_joint * _motion(joint, q)
        axis = at_joint.rotation @ joint.axis
        anchor_velocity = above.velocity + np.cross(
            above.angular_velocity, frame.translation - above.frame.translation
        )
        placed = _Placed(
            frame,
            anchor_velocity + (axis * rate if kind == "slider" else 0.0),
            above.angular_velocity + (axis * rate if kind == "hinge" else 0.0),
            above.body,
        )
        link = self.robot.links[joint.child]
        if link.mass <= 0:
            if kind != "fixed":
                raise ModelError(
                    "file", f"link {link.name!r} has no mass but moves on joint {joint.name!r}"
                )
            self.descend(link.name, placed)  # a massless fixed link carries nothing
            return
        limits = None
        if joint.limits is not None:
            limits = (joint.limits[0] - q, joint.limits[1] - q)
            if not limits[0] <= 0.0 <= limits[1]:
                raise ModelError(
                    "joint_positions",
                    f"{name}: {q} is outside the URDF's limits {list(joint.limits)}",
                )
        self.add_body(link, placed)
        record = {
            "name": name,
            "type": kind,
            "parent": above.body or "world",
            "child": placed.body,
            "anchor": frame.translation.tolist(),
            "damping": joint.damping,
        }
        if kind != "fixed":
            record["axis"] = axis.tolist()
        if limits is not None:
            record["limits"] = list(limits)
        self.joints.append(record)
        self.file_joints.append(joint.name)
        self.descend(link.name, placed)


def _movable_joints(model: ModelSpec, robot: Robot) -> list[str]:
    return [model.name + "/" + j.name for j in robot.joints if j.kind != "fixed"]


def expand_model(model: ModelSpec, scene: Path) -> tuple[list[dict], list[dict]]:
    """The bodies and joints of ``model`` (a scene's ``models`` entry, read relative to the
    scene file ``scene``), as scene entries; ``ModelError`` at the field that is wrong."""
    expansion = _expanded(model, scene)
    return expansion.bodies, expansion.joints


def _expanded(model: ModelSpec, scene: Path) -> _Expansion:
    if model.collisions:
        raise ModelError(
            "collisions",
            "true is not supported yet: a model's collision shapes are not read "
            "(collisions: false gives its bodies placeholder spheres)",
        )
    try:
        path = model_path(model.file, scene)
    except ValueError as error:
        raise ModelError("file", str(error)) from None
    if path.suffix.lower() != URDF_SUFFIX:
        raise ModelError(
            "file", f"expected a URDF file (.urdf); got {path.name!r} (MJCF .xml is a later step)"
        )
    if not path.is_file():
        raise ModelError("file", f"no such file: {path}")
    try:
        robot = read_urdf(path)
    except ValueError as error:
        raise ModelError("file", str(error)) from None
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


def expand_models(data: dict, scene: Path) -> tuple[dict, list[tuple[tuple, str]]]:
    """``data`` (a scene document) with its ``models`` expanded into ``bodies`` and
    ``joints``, and the problems found (location, message). Entries the schema refuses are
    left for the schema to report."""
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
            more_bodies, more_joints = expand_model(model, scene)
        except ModelError as error:
            problems.append((("models", i, error.field), f"{error}"))
            continue
        bodies += more_bodies
        joints += more_joints
    if problems:
        return data, problems  # the scene as written: its own problems are reported with these
    return {**data, "bodies": bodies, "joints": joints}, problems


PACKAGE_PATHS: dict[str, str] = {}
"""``package://NAME`` -> DIR, the run's ``--package-path`` flags (set by the command before any
scene is loaded; carried to the workers in each ``ModelLayout``)."""


def model_layouts(scenario) -> tuple[ModelLayout, ...]:
    """Each of the scenario's ``models`` as a ``ModelLayout`` (the file read again, as the
    scene's load read it: a scene that loaded reads the same)."""
    scene = Path(scenario.source or ".")
    layouts = []
    for model in scenario.models:
        expansion = _expanded(model, scene)
        layouts.append(
            ModelLayout(
                name=model.name,
                path=expansion.path,
                format=expansion.path.suffix.lower().lstrip(".").replace("xml", "mjcf"),
                spec=model,
                bodies=tuple(b["name"] for b in expansion.bodies),
                links=tuple(expansion.links),
                body_in_link=tuple(expansion.body_in_link),
                joints=tuple(j["name"] for j in expansion.joints),
                file_joints=tuple(expansion.file_joints),
                root_link=expansion.robot.root,
                package_paths=tuple(sorted(PACKAGE_PATHS.items())),
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
    expanded, problems = expand_models(data, Path(scenario.source or "."))
    if problems:
        location, message = problems[0]
        raise ModelError(str(location[-1]), message)
    return Scenario.model_validate({**expanded, "source": scenario.source})
