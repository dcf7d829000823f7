"""physval's own reading of an MJCF file (MuJoCo's XML format) into the links and joints of
``validation/scenario/robot.py``, the same structure a URDF gives, for a documented subset.

Why a plain ``xml.etree`` reader and not MuJoCo's own parser (``MjSpec``/``MjModel``):
MuJoCo's compiler is one of the loaders the ``model_fields`` tier judges, so the reference it
is judged against must not be it (a MuJoCo quirk would then agree with itself); and the scene
side imports no engine (``tests/test_architecture.py``). The subset is small enough to read
by hand, and ``tests/test_mjcf.py`` compares the reading with MuJoCo's compiled model
(measured with MuJoCo 4.0.1 on pybullet_data's inverted double pendulum and a file using
every part of the subset: masses agree to 1.7e-16, inertias to 7.8e-15 of the largest moment,
centres of mass and poses to 1e-15 m: its solid formulas, the capsule's included, are exact).

The subset:

- ``<compiler>``: ``angle`` (``degree``, the default, or ``radian``: euler, axisangle and a
  hinge's range), ``coordinate="local"``, ``inertiafromgeom`` (``auto`` default, ``true``,
  ``false``), ``eulerseq`` (default ``xyz``; lower case turns about the moving axes, upper
  case about the fixed ones), ``autolimits``, ``meshdir``/``assetdir`` (where mesh files are);
- ``<default>`` classes, nested, for ``joint`` and ``geom``; an element takes its ``class``,
  else its body's nearest ``childclass``, else the top-level class ``main``;
- ``<worldbody>``'s tree of ``<body>`` (``pos``, and ``quat``, ``axisangle``, ``euler``,
  ``xyaxes`` or ``zaxis``): each body is a link; the worldbody is a massless link ``world``
  (a fixed base); geoms on it are not bodies (ignored, with ``collisions: true`` too: the
  scene has its own ground);
- at most one ``<joint>`` per body, ``hinge`` (a physval hinge) or ``slide`` (a slider), with
  ``pos`` (the pivot, in the body's frame), ``axis``, ``range`` and ``limited``, ``damping``,
  ``frictionloss`` (the joint's dry friction: physval's scene joints have none, so it is
  carried to the ``model_fields`` tier only, ``robot.Joint.friction``);
  a body without a joint is welded to its parent (a fixed joint ``<body>.weld``, not in the
  file); a ``<freejoint/>`` (or ``type="free"``) only on the one top-level body, which is then
  the model's root (``fixed_base`` chooses whether it is held);
- mass: an explicit ``<inertial pos quat mass diaginertia|fullinertia>``, or, by
  ``inertiafromgeom``, the body's geoms (sphere, capsule and cylinder, also by ``fromto``, box,
  ellipsoid) each of ``mass`` or ``density`` (default 1000 kg/m³) times its volume, with the
  reference side's solid formulas (``validation/reference/mass_properties.py``) summed about
  the body's centre of mass by the parallel-axis theorem;
- collision geometry (``collisions: true``): every geom of a body, its type, ``size`` and
  ``pos``/orientation or ``fromto`` (``robot.Geometry``); ``contype``, ``conaffinity``,
  ``group`` and the geom's contact values are not read (physval has no collision groups: a
  body's geom collides as the scene's bodies do; its friction and restitution are the
  scene's), so a body with a visual geom beside its collision geom has two.

Refused, each with one line naming the element: anything else that changes the model's
mechanics (``include``, ``frame``, ``equality``, ``tendon``, ``composite``, ball joints, a free
joint inside the tree, two joints on one body, mesh or other geoms that would give mass, and
a nonzero ``armature``, ``stiffness`` or ``ref``: physval's joints have no rotor inertia,
spring or reference offset). Elements that do not change the
mechanics of a passive model without contacts (``option``, ``size``, ``visual``, ``actuator``,
``sensor``, ``contact``, ``keyframe``, ``custom``, ``statistic``, sites, cameras, lights) are
ignored: the scene's own ``dt`` and ``gravity`` apply.
"""

from __future__ import annotations

import math
import xml.etree.ElementTree as ElementTree
from dataclasses import dataclass, field, replace
from pathlib import Path

import numpy as np

from validation.reference.mass_properties import (
    BALL_MOMENT,
    CYLINDER_AXIAL,
    CYLINDER_TRANSVERSE_LENGTH,
    CYLINDER_TRANSVERSE_RADIAL,
    box_inertia,
    capsule_inertia,
    sphere_inertia,
)
from validation.scenario.robot import (
    IDENTITY,
    MASSLESS,
    Frame,
    Geometry,
    Joint,
    Link,
    Robot,
    rotation_class,
    translation,
    xml_root,
)

ANGLE_UNITS = {"degree": math.pi / 180.0, "radian": 1.0}
"""``<compiler angle>`` -> rad per unit of the file's angles (MJCF's default: degree)."""

WORLD = "world"
"""The link the worldbody becomes (MuJoCo's name for it too)."""

WELD_SUFFIX = ".weld"
"""A body without joints is held to its parent by the scene joint ``<body>.weld``."""

WELD_AXIS = np.array([0.0, 0.0, 1.0])
"""A weld's axis (unused: a fixed joint has none)."""

DEFAULT_CLASS = "main"
"""The top-level ``<default>``'s class."""

DEFAULT_DENSITY = 1000.0
"""kg/m³: a geom's density when it states neither ``density`` nor ``mass`` (MuJoCo's, water)."""

DEFAULT_AXIS = "0 0 1"
"""A joint's axis when it states none (MuJoCo's default)."""

JOINT_KINDS = {"hinge": "hinge", "slide": "slider"}
"""MJCF joint type -> physval joint type; ``free`` is the root's (below), others refused."""

FREE = "free"
DEFAULT_JOINT = "hinge"
"""A joint's type when it states none."""

READ_TOP = ("compiler", "default", "worldbody", "asset")
IGNORED_TOP = (
    "option",
    "size",
    "visual",
    "statistic",
    "custom",
    "actuator",
    "sensor",
    "contact",
    "keyframe",
)
"""``<mujoco>`` children read, and ignored (no effect on a passive model without contacts);
any other (``include``, ``equality``, ``tendon``, ``deformable``, ``extension``...) is refused."""

IGNORED_IN_BODY = ("site", "camera", "light")
"""``<body>`` children that carry no mass and no joint; ``inertial``, ``joint``,
``freejoint``, ``geom`` and ``body`` are read, anything else (``frame``, ``composite``,
``attach``, ``replicate``, ``plugin``...) is refused."""

REFUSED_COMPILER = (
    "boundmass",
    "boundinertia",
    "settotalmass",
    "balanceinertia",
    "inertiagrouprange",
    "fusestatic",
    "alignfree",
)
"""``<compiler>`` attributes that would change the masses or the tree this reader builds."""

UNSUPPORTED_JOINT_VALUES = {
    "armature": "physval's joints have no rotor inertia",
    "stiffness": "physval's joints have no spring",
    "ref": "physval's joints are at 0 in the file's pose",
}
"""Joint attributes refused when nonzero, and why."""

MASS_TYPES = ("sphere", "capsule", "cylinder", "box", "ellipsoid")
"""Geom types whose mass and inertia this reader computes; a body's mass from any other
(mesh, plane, hfield, sdf) is refused."""

SIZE_COUNTS = {"sphere": 1, "capsule": 2, "cylinder": 2, "box": 3, "ellipsoid": 3}
"""Numbers of ``size`` a geom type reads (a capsule's or cylinder's second from ``fromto``)."""


@dataclass
class _Compiler:
    """The ``<compiler>`` settings this reader uses."""

    angle_unit: float = ANGLE_UNITS["degree"]  # rad per unit of the file's angles
    inertia_from_geom: str = "auto"
    euler_sequence: str = "xyz"
    auto_limits: bool = True
    mesh_folder: str = ""


@dataclass
class _Reading:
    """The state of one file's reading: settings, default classes, links and joints so far."""

    compiler: _Compiler = field(default_factory=_Compiler)
    defaults: dict[str, dict[str, dict[str, str]]] = field(default_factory=dict)
    links: dict[str, Link] = field(default_factory=dict)
    joints: list[Joint] = field(default_factory=list)
    meshes: list[str] = field(default_factory=list)


def read_mjcf(path: Path) -> Robot:
    """The links and joints of the MJCF file at ``path``; ValueError naming what is wrong."""
    root = xml_root(path)
    try:
        robot = _read(root)
    except (TypeError, ValueError) as error:
        raise ValueError(f"{path.name}: {error}") from None
    return robot


def _read(root: ElementTree.Element) -> Robot:
    if root.tag != "mujoco":
        raise ValueError(f"expected a <mujoco> root element (MJCF); got <{root.tag}>")
    reading = _Reading()
    for element in root:
        if element.tag not in READ_TOP + IGNORED_TOP:
            raise ValueError(f"<{element.tag}> is outside the MJCF subset physval reads")
    for element in root.findall("compiler"):
        _compiler(element, reading.compiler)
    reading.defaults[DEFAULT_CLASS] = {}
    for element in root.findall("default"):
        _defaults(element, {}, reading.defaults, top=True)
    for element in root.findall("asset"):
        reading.meshes += [
            _joined(reading.compiler.mesh_folder, mesh.get("file", ""))
            for mesh in element.findall("mesh")
            if mesh.get("file")
        ]
    worldbody = root.find("worldbody")
    if worldbody is None:
        raise ValueError("no <worldbody>")
    _tree(worldbody, reading)
    robot = Robot(reading.links, reading.joints, "mjcf", meshes=reading.meshes)
    return robot.assemble()


def _joined(folder: str, file: str) -> str:
    return file if not folder or file.startswith(("/", "package://")) else f"{folder}/{file}"


# --- settings -----------------------------------------------------------------------------


def _compiler(element: ElementTree.Element, compiler: _Compiler) -> None:
    for name in REFUSED_COMPILER:
        if name in element.attrib:
            raise ValueError(f"<compiler {name}> is outside the MJCF subset physval reads")
    angle = element.get("angle")
    if angle is not None:
        if angle not in ANGLE_UNITS:
            raise ValueError(f"<compiler angle={angle!r}>: expected degree or radian")
        compiler.angle_unit = ANGLE_UNITS[angle]
    if element.get("coordinate", "local") != "local":
        raise ValueError("<compiler coordinate='global'> is outside the subset (local only)")
    compiler.inertia_from_geom = element.get("inertiafromgeom", compiler.inertia_from_geom)
    if compiler.inertia_from_geom not in ("auto", "true", "false"):
        raise ValueError(f"<compiler inertiafromgeom={compiler.inertia_from_geom!r}>")
    compiler.euler_sequence = element.get("eulerseq", compiler.euler_sequence)
    if len(compiler.euler_sequence) != 3 or set(compiler.euler_sequence) - set("xyzXYZ"):
        raise ValueError(f"<compiler eulerseq={compiler.euler_sequence!r}>: expected 3 of xyzXYZ")
    compiler.auto_limits = element.get("autolimits", str(compiler.auto_limits).lower()) == "true"
    compiler.mesh_folder = element.get("meshdir", element.get("assetdir", compiler.mesh_folder))


def _defaults(element: ElementTree.Element, inherited: dict, classes: dict, top: bool) -> None:
    """Each ``<default>`` class's attributes per element tag, its parent's merged under its
    own."""
    name = element.get("class", DEFAULT_CLASS if top else None)
    if name is None:
        raise ValueError("a nested <default> without a class")
    own = {tag: dict(values) for tag, values in inherited.items()}
    for child in element:
        if child.tag != "default":
            own[child.tag] = {**own.get(child.tag, {}), **child.attrib}
    classes[name] = own
    for child in element.findall("default"):
        _defaults(child, own, classes, top=False)


def _attributes(element: ElementTree.Element, reading: _Reading, childclass: str) -> dict:
    """The element's attributes over its class's defaults."""
    name = element.get("class", childclass)
    if name not in reading.defaults:
        raise ValueError(f"<{element.tag} class={name!r}>: no such <default> class")
    return {**reading.defaults[name].get(element.tag, {}), **element.attrib}


def _floats(values: dict, key: str, count: int, default: str | None = None) -> np.ndarray:
    text = values.get(key, default)
    if text is None:
        raise ValueError(f"expected {key}")
    numbers = [float(v) for v in text.split()]
    if len(numbers) < count:
        raise ValueError(f"{key}={text!r}: expected {count} numbers")
    return np.array(numbers[:count])


# --- frames -------------------------------------------------------------------------------


def _turn(axis: np.ndarray, angle: float) -> np.ndarray:
    return rotation_class().from_rotvec(axis / np.linalg.norm(axis) * angle).as_matrix()


def _z_to(direction: np.ndarray) -> np.ndarray:
    """The smallest rotation taking +z to ``direction`` (MuJoCo's ``zaxis`` and ``fromto``)."""
    direction = direction / np.linalg.norm(direction)
    z = np.array([0.0, 0.0, 1.0])
    cross = np.cross(z, direction)
    if np.linalg.norm(cross) < 1e-12:
        return np.eye(3) if direction[2] > 0 else np.diag([1.0, -1.0, -1.0])
    return _turn(cross, math.atan2(np.linalg.norm(cross), direction @ z))


def _euler(angles: np.ndarray, sequence: str) -> np.ndarray:
    rotation = np.eye(3)
    for letter, angle in zip(sequence, angles, strict=True):
        step = _turn(np.eye(3)["xyz".index(letter.lower())], angle)
        rotation = rotation @ step if letter.islower() else step @ rotation
    return rotation


def _from_quat(numbers: np.ndarray, compiler: _Compiler) -> np.ndarray:
    w, x, y, z = numbers
    return rotation_class().from_quat([x, y, z, w]).as_matrix()  # normalized, as MuJoCo does


def _from_xyaxes(numbers: np.ndarray, compiler: _Compiler) -> np.ndarray:
    x = numbers[:3] / np.linalg.norm(numbers[:3])
    y = numbers[3:] - (numbers[3:] @ x) * x
    y /= np.linalg.norm(y)
    return np.column_stack([x, y, np.cross(x, y)])


ORIENTATIONS = {
    "quat": (4, _from_quat),
    "axisangle": (4, lambda n, compiler: _turn(n[:3], n[3] * compiler.angle_unit)),
    "euler": (3, lambda n, compiler: _euler(n * compiler.angle_unit, compiler.euler_sequence)),
    "xyaxes": (6, _from_xyaxes),
    "zaxis": (3, lambda n, compiler: _z_to(n)),
}
"""MJCF's ways to state an element's orientation: attribute -> (numbers, their rotation)."""


def _orientation(values: dict, compiler: _Compiler) -> np.ndarray:
    """The rotation an element's orientation attribute states (identity when none)."""
    given = [key for key in ORIENTATIONS if key in values]
    if len(given) > 1:
        raise ValueError(f"both {given[0]} and {given[1]} given")
    if not given:
        return np.eye(3)
    count, rotation = ORIENTATIONS[given[0]]
    return rotation(_floats(values, given[0], count), compiler)


def _frame(values: dict, compiler: _Compiler) -> Frame:
    return Frame(_orientation(values, compiler), _floats(values, "pos", 3, "0 0 0"))


# --- the tree -----------------------------------------------------------------------------


def _tree(worldbody: ElementTree.Element, reading: _Reading) -> None:
    """The worldbody's bodies as links and joints; the one top-level body with a free joint
    is the root, else the worldbody is (a massless ``world`` link)."""
    for child in worldbody:
        if child.tag not in ("body", "geom", *IGNORED_IN_BODY):
            raise ValueError(f"<{child.tag}> in <worldbody> is outside the subset")
    tops = worldbody.findall("body")
    free = [body for body in tops if _is_free(body, reading)]
    if free and len(tops) > 1:
        raise ValueError(
            f"body {free[0].get('name')!r} has a free joint beside other top-level bodies: "
            "physval reads a free joint only on the one top-level body"
        )
    if not free:
        reading.links[WORLD] = Link(WORLD, *MASSLESS)
    for body in tops:
        _body(body, WORLD if not free else None, reading, DEFAULT_CLASS)


def _joint_elements(body: ElementTree.Element) -> list[ElementTree.Element]:
    return [child for child in body if child.tag in ("joint", "freejoint")]


def _is_free(body: ElementTree.Element, reading: _Reading) -> bool:
    childclass = body.get("childclass", DEFAULT_CLASS)
    return any(
        j.tag == "freejoint" or _attributes(j, reading, childclass).get("type") == FREE
        for j in _joint_elements(body)
    )


def _body(
    element: ElementTree.Element, parent: str | None, reading: _Reading, childclass: str
) -> None:
    """The body as a link, its joint to ``parent`` (None: it is the free root) and its
    subtree."""
    name = element.get("name")
    if not name:
        where = "the <worldbody>" if parent in (None, WORLD) else f"body {parent!r}"
        raise ValueError(f"a <body> without a name in {where}: physval names bodies by it")
    if name in reading.links:
        raise ValueError(f"two bodies named {name!r}")
    childclass = element.get("childclass", childclass)
    for child in element:
        if child.tag not in ("inertial", "joint", "freejoint", "geom", "body", *IGNORED_IN_BODY):
            raise ValueError(f"<{child.tag}> in body {name!r} is outside the subset")
    if element.get("mocap", "false") == "true":
        raise ValueError(f"body {name!r} is a mocap body: outside the subset")
    reading.links[name] = _link(element, reading, childclass)
    placed = _frame(element.attrib, reading.compiler)
    joints = _joint_elements(element)
    if len(joints) > 1:
        raise ValueError(f"body {name!r} has {len(joints)} joints: physval reads one per body")
    if parent is not None:
        reading.joints.append(_joint(joints, element, parent, placed, reading, childclass))
    for child in element.findall("body"):
        _body(child, name, reading, childclass)


def _joint(
    elements: list[ElementTree.Element],
    body: ElementTree.Element,
    parent: str,
    placed: Frame,
    reading: _Reading,
    childclass: str,
) -> Joint:
    """The joint that carries ``body`` on ``parent``: its one joint element, or a weld."""
    name = body.get("name")
    if not elements:
        return Joint(
            name + WELD_SUFFIX, "fixed", parent, name, placed, WELD_AXIS, None, 0.0, in_file=False
        )
    element = elements[0]
    values = _attributes(element, reading, childclass)
    kind = FREE if element.tag == "freejoint" else values.get("type", DEFAULT_JOINT)
    if kind not in JOINT_KINDS:
        where = "inside the tree" if kind == FREE else "outside the subset"
        raise ValueError(f"joint of body {name!r} is {kind!r}: {where} (hinge and slide only)")
    joint_name = values.get("name")
    if not joint_name:
        raise ValueError(f"the joint of body {name!r} has no name")
    for key, why in UNSUPPORTED_JOINT_VALUES.items():
        if float(values.get(key, "0").split()[0]) != 0.0:
            raise ValueError(f"joint {joint_name!r} has {key}={values[key]}: {why}")
    pivot = _floats(values, "pos", 3, "0 0 0")
    axis = _floats(values, "axis", 3, DEFAULT_AXIS)
    if not axis.any():
        raise ValueError(f"joint {joint_name!r} has a zero axis")
    return Joint(
        joint_name,
        JOINT_KINDS[kind],
        parent,
        name,
        placed * translation(pivot),
        axis / np.linalg.norm(axis),
        _limits(values, kind, joint_name, reading.compiler),
        float(values.get("damping", "0")),
        child_in_joint=translation(-pivot),
        friction=float(values.get("frictionloss", "0")),
    )


def _limits(values: dict, kind: str, name: str, compiler: _Compiler):
    """The joint's range in rad or m when it is limited, else None."""
    limited = values.get("limited", "auto")
    if limited == "auto":
        limited = "true" if compiler.auto_limits and "range" in values else "false"
    if limited != "true":
        return None
    lower, upper = _floats(values, "range", 2, "0 0")
    if kind == "hinge":
        lower, upper = lower * compiler.angle_unit, upper * compiler.angle_unit
    if not lower < upper:
        raise ValueError(f"joint {name!r} has range {[lower, upper]}: expected lower < upper")
    return (float(lower), float(upper))


# --- mass ---------------------------------------------------------------------------------


def _link(element: ElementTree.Element, reading: _Reading, childclass: str) -> Link:
    """The body's inertial frame, mass and inertia: its ``<inertial>``, or its geoms'."""
    name = element.get("name")
    inertial = element.find("inertial")
    geoms = [_attributes(g, reading, childclass) for g in element.findall("geom")]
    geometry = tuple(Geometry(*_placement(name, g, reading.compiler)) for g in geoms)
    source = reading.compiler.inertia_from_geom
    if source == "true" or (source == "auto" and inertial is None):
        return replace(_from_geoms(name, geoms, reading.compiler), geometry=geometry)
    if inertial is None:
        return Link(name, *MASSLESS, geometry)
    values = inertial.attrib
    mass = float(values.get("mass", "0"))
    if mass < 0:
        raise ValueError(f"body {name!r} has a negative mass {mass}")
    if "fullinertia" in values:
        xx, yy, zz, xy, xz, yz = _floats(values, "fullinertia", 6)
        inertia = np.array([[xx, xy, xz], [xy, yy, yz], [xz, yz, zz]])
    else:
        inertia = np.diag(_floats(values, "diaginertia", 3))
    return Link(name, _frame(values, reading.compiler), mass, inertia, geometry)


def _from_geoms(name: str, geoms: list[dict], compiler: _Compiler) -> Link:
    """The body's mass properties from its geoms: each solid's inertia turned into the
    body's axes and moved to the common centre of mass (parallel axes)."""
    solids = [_solid(name, values, compiler) for values in geoms]
    solids = [solid for solid in solids if solid[0] > 0]
    mass = sum(solid[0] for solid in solids)
    if mass <= 0:
        return Link(name, *MASSLESS)
    centre = sum(m * frame.translation for m, frame, _ in solids) / mass
    inertia = np.zeros((3, 3))
    for m, frame, own in solids:
        offset = frame.translation - centre
        inertia += frame.rotation @ own @ frame.rotation.T
        inertia += m * (offset @ offset * np.eye(3) - np.outer(offset, offset))
    return Link(name, translation(centre), float(mass), inertia)


def _solid(body: str, values: dict, compiler: _Compiler) -> tuple[float, Frame, np.ndarray]:
    """A geom's mass, frame in the body and inertia about its centre (its own axes)."""
    kind = values.get("type", "sphere")
    if kind not in MASS_TYPES:
        if float(values.get("mass", "1")) == 0 or float(values.get("density", "1")) == 0:
            return 0.0, IDENTITY, np.zeros((3, 3))
        raise ValueError(
            f"a {kind} geom in body {body!r} would give it mass: physval computes a body's "
            f"mass from {', '.join(MASS_TYPES)} geoms only (state an <inertial>)"
        )
    if values.get("shellinertia", "false") == "true":
        raise ValueError(f"a shellinertia geom in body {body!r} is outside the subset")
    _, sizes, frame = _placement(body, values, compiler)
    volume, unit_inertia = SOLIDS[kind](*sizes)
    density = float(values.get("density", DEFAULT_DENSITY))
    mass = float(values["mass"]) if "mass" in values else density * volume
    return mass, frame, unit_inertia * mass


def _placement(body: str, values: dict, compiler: _Compiler) -> tuple[str, tuple, Frame]:
    """A geom's type, sizes (``SIZE_COUNTS`` of them; none for a type without, a mesh's) and
    frame in the body: ``pos`` and its orientation, or a capsule's or cylinder's ``fromto``
    (its centre, +z along it, half its length)."""
    kind = values.get("type", "sphere")
    if kind not in SIZE_COUNTS:
        return kind, (), _frame(values, compiler)
    sizes = list(_floats(values, "size", 1 if "fromto" in values else SIZE_COUNTS[kind]))
    frame = _frame(values, compiler)
    if "fromto" in values:
        if kind not in ("capsule", "cylinder"):
            raise ValueError(f"a {kind} geom with fromto in body {body!r}: capsules, cylinders")
        ends = _floats(values, "fromto", 6)
        axis = ends[3:] - ends[:3]
        frame = Frame(_z_to(axis), (ends[:3] + ends[3:]) / 2)
        sizes = [sizes[0], np.linalg.norm(axis) / 2]
    return kind, tuple(float(v) for v in sizes[: SIZE_COUNTS[kind]]), frame


def _cylinder(radius: float, half_length: float) -> tuple[float, np.ndarray]:
    length = 2.0 * half_length
    transverse = CYLINDER_TRANSVERSE_RADIAL * radius**2 + CYLINDER_TRANSVERSE_LENGTH * length**2
    return math.pi * radius**2 * length, np.diag(
        [transverse, transverse, CYLINDER_AXIAL * radius**2]
    )


def _ellipsoid(a: float, b: float, c: float) -> tuple[float, np.ndarray]:
    # the ball's 2/5 r² per axis pair, halved: I_x = m (b² + c²) / 5
    half = BALL_MOMENT / 2.0
    return 4.0 / 3.0 * math.pi * a * b * c, np.diag(
        [b * b + c * c, a * a + c * c, a * a + b * b]
    ) * half


SOLIDS = {
    "sphere": lambda r: (4.0 / 3.0 * math.pi * r**3, sphere_inertia(1.0, r)),
    "capsule": lambda r, h: (
        math.pi * r**2 * 2 * h + 4.0 / 3.0 * math.pi * r**3,
        capsule_inertia(1.0, r, h),
    ),
    "cylinder": _cylinder,
    "box": lambda x, y, z: (8.0 * x * y * z, box_inertia(1.0, (x, y, z))),
    "ellipsoid": _ellipsoid,
}
"""Geom type -> (size numbers) -> (volume m³, inertia per kg about its centre, own axes)."""
