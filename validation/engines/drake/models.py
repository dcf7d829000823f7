"""A scene's ``models`` read by Drake's own ``Parser`` (``model_loader=native``, issue 36):
each file added to the plant as its own model instance, placed, set to its stated joint
state, and mapped onto the scene's bodies and joints (``validation.scenario.urdf.ModelLayout``)
so that the adapter reads Drake's links as the scene's bodies (docs/engines-drake.md 10).

- Parsing: ``Parser(plant, model_name_prefix=<model name>)`` (two models of one file stay two
  instances); ``package://NAME/...`` resolves through the parser's ``PackageMap``, each name
  to the folder the load's own rule finds (``validation.scenario.packages``: the file's folder
  tree, then ``ModelLayout.package_paths``). URDF (``.urdf``) and MJCF (``.xml``, Drake's
  MuJoCo parser).
- A URDF whose root link is named ``world`` is parsed with that link renamed: Drake's parser
  takes a link of that name for its own world body (pybullet_data's ``pendulum5.urdf`` and 22
  other files have one).
- ``collisions: false``: none of the model's geometry may collide. A URDF is parsed with its
  ``<collision>`` and ``<visual>`` elements removed (the geometry is never registered: Drake
  1.51 refuses a ``.stl`` collision mesh outright, and Kuka's are ``.stl``); an MJCF keeps its
  geoms (Drake computes the bodies' inertia from them, ``inertiafromgeom``), and every
  proximity geometry the file added is filtered from everything (``filter_model_geometry``).
- ``collisions: true``: a URDF is parsed with its ``<collision>`` elements and without its
  ``<visual>`` ones; an MJCF with its geoms. Every proximity geometry on a model link gets the
  scene's friction for a model link (``urdf.LINK_CONTACT``: 0, so Drake's 2ab/(a+b) with any
  other is the scene's geometric mean, 0) in place of the file's or Drake's default
  (``_scene_contacts``); an MJCF's worldbody geoms (physval's reading leaves them out) are
  filtered from everything. Drake keeps its own filter of geometry on bodies joined by a
  joint (as physval's reading). A mesh is Drake's to read (a scene with a mesh collision shape
  does not load: physval's reading refuses it).
- Placement: a URDF's root link is welded to the world at the model's position and
  orientation (``fixed_base``: through a ``FixedOffsetFrame`` of the world at that pose, so the
  weld's anchor is the base's point), or floats from that pose. Drake's MJCF parser attaches
  the file's top-level bodies to the world itself (their joints, or a weld): an MJCF rooted at
  its ``<worldbody>`` is parsed as it is at the origin, and elsewhere with its ``<worldbody>``
  moved into one jointless body at the model's pose (``_placed_mjcf``); an MJCF whose root is
  one free top-level body is placed like a URDF's root (welded or floating at the model's
  pose, not the file's).
- Gravity: Drake's MJCF parser sets the plant's gravity from the file's ``<option gravity>``
  (MuJoCo's default when absent); the scene's gravity is set again after every model is
  parsed (``add_models``).
- Joint state: each file joint's default position is ``layout.initial_position`` (so every
  context, the simulator's and a scratch one, starts there); its rate,
  ``layout.initial_velocity``, is set in the simulator's context (``model_velocities``).
"""

from __future__ import annotations

import contextlib
import logging
import xml.etree.ElementTree as ElementTree
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from pydrake.geometry import (
    CollisionFilterDeclaration,
    GeometrySet,
    ProximityProperties,
    Role,
    RoleAssign,
)
from pydrake.math import RigidTransform, RotationMatrix
from pydrake.multibody.parsing import Parser
from pydrake.multibody.plant import CoulombFriction
from pydrake.multibody.tree import FixedOffsetFrame

from validation.engines.drake.joints import pose
from validation.scenario.packages import PACKAGE_URI, resolve
from validation.scenario.robot import xml_root
from validation.scenario.urdf import LINK_CONTACT, ModelLayout

GEOMETRY_ELEMENTS = {False: ("collision", "visual"), True: ("visual",)}
"""``collisions`` -> the URDF link elements removed before Drake parses the model: all its
geometry when it does not collide; its ``<visual>`` elements when it does (illustration only:
a visual's undefined material or unreadable mesh would stop the parse for nothing)."""

HELD_FRICTION = 0.0
"""N·m or N: a parsed joint's dry friction in Drake. ``MultibodyPlant`` has no joint friction:
the parser warns ("MultibodyPlant does not currently support non-zero joint friction", kept in
the provenance by ``parser_log``) and drops a URDF's ``<dynamics friction>`` (and an MJCF's
``frictionloss``); the ``model_fields`` tier reads Drake's as this."""

FRICTION_PROPERTY = ("material", "coulomb_friction")
"""The proximity property (group, name) Drake reads a geometry's friction from."""

FILE_TYPES = {"urdf": "urdf", "mjcf": "xml"}
"""``ModelLayout.format`` -> Drake's ``file_type`` for ``AddModelsFromString``."""

DRAKE_LOGGER = "drake"
"""pydrake forwards Drake's C++ log (the parser's warnings among it) to this Python logger
(its level is synced to spdlog)."""

BASE_FRAME = "physval_base"
"""The name of the world frame at a URDF's fixed base pose (the weld's frame on the parent),
and of the body an MJCF's world is moved into to place it (``_placed_mjcf``)."""

DRAKE_WORLD = "world"
"""A URDF link of this name is Drake's world body to its parser: the file's joints from it
would hang from Drake's world at the origin, not at the model's pose. Physval's MJCF reading
names an MJCF's ``<worldbody>`` so too (``validation.scenario.mjcf.WORLD``)."""

RENAMED_WORLD = "physval_world_link"
"""What a root link named ``DRAKE_WORLD`` is renamed to before Drake parses the file, so that
it is the model's own root, welded at the model's pose like any other."""

MESH_AND_TEXTURE_FOLDERS = ("meshdir", "texturedir")
"""MJCF ``<compiler>`` attributes naming folders relative to the file; unset, ``assetdir``
stands for both, and unset too, the file's own folder."""


@dataclass(frozen=True)
class NativeModel:
    """One model as Drake holds it.

    Attributes:
        layout: the scene's ``ModelLayout``. instance: Drake's ``ModelInstanceIndex``.
        links: the Drake body of each of ``layout.bodies`` (the file's link).
        in_link: each body's frame (centre of mass, the scene body's axes) in its link's
            frame (``layout.body_in_link``) as a ``RigidTransform``.
        joints: scene joint name -> the Drake joint (the fixed-base weld included).
        geometry: the proximity geometry the file added (filtered when it must not collide).
        idle: of it, what must not collide although the model does (``_scene_contacts``).
        warnings: what Drake's parser logged while reading the file (its differences from
            the file: attributes it ignores, inertias it cannot take), for the provenance.
    """

    layout: ModelLayout
    instance: object
    links: tuple
    in_link: tuple
    joints: dict
    geometry: tuple
    warnings: tuple = ()
    idle: tuple = ()


def transform(frame) -> RigidTransform:
    """A ``validation.scenario.urdf.Frame`` as Drake's ``RigidTransform``."""
    return RigidTransform(
        RotationMatrix.ProjectToRotationMatrix(np.asarray(frame.rotation, dtype=float)),
        np.asarray(frame.translation, dtype=float),
    )


def base_pose(layout: ModelLayout) -> RigidTransform:
    """The model's base in the world: its ``position`` and ``orientation`` (w x y z)."""
    return pose(layout.spec.position, layout.spec.orientation)


def _urdf_text(layout: ModelLayout) -> str:
    """The URDF at ``layout.path`` as text, its namespace prefixes kept (Drake reads
    ``drake:rotor_inertia`` by its prefix; ElementTree would write ``ns0:``): without its
    links' geometry elements when the model does not collide, or without its visuals when it
    does (``GEOMETRY_ELEMENTS``), each relative mesh file a ``file://`` URL (Drake refuses a
    bare path in text); a root link named ``world`` renamed ``RENAMED_WORLD``
    (``root_name``)."""
    for _, (prefix, uri) in ElementTree.iterparse(layout.path, events=("start-ns",)):
        ElementTree.register_namespace(prefix, uri)
    root = ElementTree.parse(layout.path).getroot()
    for link in root.iter("link"):
        for tag in GEOMETRY_ELEMENTS[layout.spec.collisions]:
            for element in link.findall(tag):
                link.remove(element)
    for mesh in root.iter("mesh"):
        file = mesh.get("filename", "")
        if "://" not in file:
            mesh.set("filename", (layout.path.parent / file).resolve().as_uri())
    for element in (*root.iter("link"), *root.iter("parent"), *root.iter("child")):
        key = "name" if element.tag == "link" else "link"
        if element.get(key) == DRAKE_WORLD:
            element.set(key, RENAMED_WORLD)
    return ElementTree.tostring(root, encoding="unicode")


def root_name(layout: ModelLayout) -> str:
    """The model's root link as Drake's parser names it (``_urdf_text``)."""
    return RENAMED_WORLD if layout.root_link == DRAKE_WORLD else layout.root_link


def _parser(plant, layout: ModelLayout) -> Parser:
    """A parser scoped by the model's name, each ``package://`` name of the file in its
    ``PackageMap`` (``_package_folders``)."""
    parser = Parser(plant, layout.name)
    for name, folder in _package_folders(layout).items():
        parser.package_map().Add(name, folder)
    return parser


def _package_folders(layout: ModelLayout) -> dict[str, str]:
    """Package name -> its folder, for every ``package://NAME/...`` the file refers to, found
    by the load's own rule (``validation.scenario.packages.resolve``: the file's folder tree,
    then the layout's package paths); a reference found nowhere is left to Drake's message."""
    found: dict[str, str] = {}
    for element in xml_root(layout.path).iter():
        for value in element.attrib.values():
            if not value.startswith(PACKAGE_URI):
                continue
            name, _, inside = value[len(PACKAGE_URI) :].partition("/")
            where = resolve(value, layout.path, layout.package_paths)
            if where is not None:
                found.setdefault(name, str(where.parents[len(Path(inside).parts) - 1]))
    return found


def _placed_mjcf(layout: ModelLayout) -> str:
    """The MJCF at ``layout.path`` as text with everything in its ``<worldbody>`` moved into
    one body (``BASE_FRAME``, no joint: welded to the world) at the model's position and
    orientation, and its asset folders (``<compiler meshdir texturedir assetdir>``, each
    ``<include file>``) made absolute (``MESH_AND_TEXTURE_FOLDERS``), as the text has no
    folder of its own."""
    root = ElementTree.parse(layout.path).getroot()
    folder = layout.path.parent
    world = root.find("worldbody")
    compiler = root.find("compiler")
    if compiler is None:
        compiler = ElementTree.SubElement(root, "compiler")
    assets = compiler.get("assetdir", "")
    for key in MESH_AND_TEXTURE_FOLDERS:
        compiler.set(key, str(folder / compiler.get(key, assets)))
    compiler.set("assetdir", str(folder / assets))
    for include in root.iter("include"):
        include.set("file", str(folder / include.get("file", "")))
    turn = pose(layout.spec.position, layout.spec.orientation).rotation().ToQuaternion()
    base = ElementTree.Element(
        "body",
        {"name": BASE_FRAME, "pos": _written(layout.spec.position), "quat": _written(turn.wxyz())},
    )
    for child in list(world):
        world.remove(child)
        base.append(child)
    world.append(base)
    return ElementTree.tostring(root, encoding="unicode")


def _written(values) -> str:
    """Numbers as an XML attribute, each to its last digit."""
    return " ".join(repr(float(v)) for v in values)


def _parse(plant, layout: ModelLayout) -> list:
    """The model instances Drake's parser makes of the file (one, for URDF and MJCF): a URDF
    as ``_urdf_text``; an MJCF away from the origin inside a base body at the model's pose
    (``_placed_mjcf``), else the file itself."""
    parser = _parser(plant, layout)
    if layout.format == "urdf":
        return parser.AddModelsFromString(_urdf_text(layout), FILE_TYPES["urdf"])
    if _hangs_from_drakes_world(layout) and not _is_origin(layout):
        return parser.AddModelsFromString(_placed_mjcf(layout), FILE_TYPES["mjcf"])
    return parser.AddModels(str(layout.path))


@contextlib.contextmanager
def parser_log():
    """The messages Drake logs in the block, kept (a list) instead of printed."""
    logger = logging.getLogger(DRAKE_LOGGER)
    found: list[str] = []

    class Keep(logging.Handler):
        def emit(self, record: logging.LogRecord) -> None:
            found.append(record.getMessage())

    handler, propagate = Keep(), logger.propagate
    logger.addHandler(handler)
    logger.propagate = False
    try:
        yield found
    finally:
        logger.removeHandler(handler)
        logger.propagate = propagate


def _is_origin(layout: ModelLayout) -> bool:
    return not np.any(layout.spec.position) and tuple(layout.spec.orientation) == (1, 0, 0, 0)


def add_model(plant, scene_graph, layout: ModelLayout, children=None) -> NativeModel:
    """``layout``'s file on ``plant`` (not finalized) by Drake's parser, placed and at its
    stated joint positions (module docstring); ``children`` (scene joint name -> its child
    body's scene name) finds the Drake weld of each scene joint the file does not name (a
    fixed base's, an MJCF jointless body's): its child's inboard joint."""
    inspector = scene_graph.model_inspector()
    before = set(inspector.GetAllGeometryIds(Role.kProximity))
    with parser_log() as warnings:
        (instance,) = _parse(plant, layout)
    geometry = tuple(g for g in inspector.GetAllGeometryIds(Role.kProximity) if g not in before)
    if not _hangs_from_drakes_world(layout):
        _place_root(plant, layout, plant.GetBodyByName(root_name(layout), instance), instance)
    links = tuple(plant.GetBodyByName(link, instance) for link in layout.links)
    joints = {}
    for name, file in _named(layout):
        if file is not None:
            joints[name] = plant.GetJointByName(file, instance)
            if joints[name].num_positions() == 1:
                joints[name].set_default_positions([layout.initial_position(file)])
        elif name in (children or {}):
            joints[name] = _inboard(plant, links[layout.bodies.index(children[name])])
    in_link = tuple(transform(frame) for frame in layout.body_in_link)
    idle = _scene_contacts(plant, scene_graph, layout, geometry, links)
    return NativeModel(layout, instance, links, in_link, joints, geometry, tuple(warnings), idle)


def _scene_contacts(plant, scene_graph, layout: ModelLayout, geometry, links) -> tuple:
    """Under ``collisions: true``: each proximity geometry on one of the model's links gets
    the scene's friction for a model link (``urdf.LINK_CONTACT``) in place of the file's
    (an MJCF geom's ``friction``, a URDF's ``drake:proximity_properties``) or Drake's default;
    the others (an MJCF's worldbody geoms, which physval's reading leaves out) are returned,
    to be filtered from everything (``filter_model_geometry``)."""
    if not layout.spec.collisions:
        return ()
    inspector = scene_graph.model_inspector()
    mine = {body.index() for body in links}
    mu = LINK_CONTACT["friction"]
    idle = []
    for gid in geometry:
        if plant.GetBodyFromFrameId(inspector.GetFrameId(gid)).index() not in mine:
            idle.append(gid)
            continue
        properties = ProximityProperties(inspector.GetProximityProperties(gid))
        if properties.HasProperty(*FRICTION_PROPERTY):
            properties.RemoveProperty(*FRICTION_PROPERTY)
        properties.AddProperty(*FRICTION_PROPERTY, CoulombFriction(mu, mu))
        scene_graph.AssignRole(plant.get_source_id(), gid, properties, RoleAssign.kReplace)
    return tuple(idle)


def _hangs_from_drakes_world(layout: ModelLayout) -> bool:
    """An MJCF whose root is its ``<worldbody>`` (physval's reading names it ``world``): Drake's
    parser hangs its top-level bodies from Drake's world itself (placed by ``_placed_mjcf``)."""
    return layout.format == "mjcf" and layout.root_link == DRAKE_WORLD


def _place_root(plant, layout: ModelLayout, root, instance) -> None:
    """The root link at the model's pose: welded to the world there (``fixed_base``, through a
    ``FixedOffsetFrame``, so the weld's anchor is the base's point) or floating from there (an
    MJCF free body's own pose in the file is not the model's: physval's reading puts the root
    at the model's pose)."""
    if layout.spec.fixed_base:
        on_world = plant.AddFrame(
            FixedOffsetFrame(BASE_FRAME, plant.world_frame(), base_pose(layout), instance)
        )
        plant.WeldFrames(on_world, root.body_frame())
    else:
        plant.SetDefaultFloatingBaseBodyPose(root, base_pose(layout))


def _inboard(plant, body):
    """The joint whose child is ``body``."""
    return next(
        plant.get_joint(index)
        for index in plant.GetJointIndices()
        if plant.get_joint(index).child_body().index() == body.index()
    )


def add_models(plant, scene_graph, layouts, gravity, children=None) -> list[NativeModel]:
    """Every layout's model (``add_model``), then the scene's ``gravity`` (3,) m/s² on the
    plant again (the MJCF parser sets the file's)."""
    models = [add_model(plant, scene_graph, layout, children) for layout in layouts]
    plant.mutable_gravity_field().set_gravity_vector(np.asarray(gravity, dtype=float))
    return models


def model_notes(models: list[NativeModel]) -> list[str]:
    """The provenance notes of the native models: how each was parsed and what Drake's
    parser said of it."""
    found = []
    for model in models:
        layout = model.layout
        stripped = layout.format == "urdf" and not layout.spec.collisions
        found.append(
            f"model {layout.name}: {layout.path.name} read by Drake's Parser"
            + (" without its <collision> and <visual> elements (collisions: false)" if stripped
               else f"; {len(model.geometry)} proximity geometries")
        )  # fmt: skip
        found += [f"model {layout.name}: Drake's parser: {w}" for w in model.warnings]
    return found


def _named(layout: ModelLayout):
    return zip(layout.joints, layout.file_joints, strict=True)


def filter_model_geometry(scene_graph, models: list[NativeModel]) -> int:
    """Every proximity geometry of the models with ``collisions: false``, and the idle ones
    of the others (``NativeModel.idle``), excluded from contact with every geometry (after
    ``Finalize``); the number of geometries filtered."""
    quiet = [
        g
        for model in models
        for g in (model.geometry if not model.layout.spec.collisions else model.idle)
    ]
    if not quiet:
        return 0
    every = scene_graph.model_inspector().GetAllGeometryIds(Role.kProximity)
    declaration = CollisionFilterDeclaration()
    declaration.ExcludeBetween(GeometrySet(quiet), GeometrySet(every))  # themselves among them
    scene_graph.collision_filter_manager().Apply(declaration)
    return len(quiet)


def model_velocities(plant, context, models: list[NativeModel]) -> np.ndarray:
    """(nv,) bool: the velocities the models own (their joints' and floating roots'), after
    each model joint's rate is set to ``layout.initial_velocity`` in ``context``."""
    owned = np.zeros(plant.num_velocities(), dtype=bool)
    v = plant.GetVelocities(context)
    for model in models:
        for index in plant.GetJointIndices(model.instance):
            joint = plant.get_joint(index)
            owned[joint.velocity_start() : joint.velocity_start() + joint.num_velocities()] = True
        for joint in model.joints.values():  # the file's joints, by the file's names
            if joint.num_velocities() == 1:
                v[joint.velocity_start()] = model.layout.initial_velocity(joint.name())
    plant.SetVelocities(context, v)
    return owned
