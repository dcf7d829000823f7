"""A scene's ``models`` loaded by MuJoCo's own compiler (``model_loader=native``, issue 36).

The scene's other bodies and joints are written as MJCF by ``mjcf.build_mjcf`` (as for any
scene); each model file is then read by ``mujoco.MjSpec.from_file`` (MuJoCo's URDF importer or
its MJCF parser) and attached into a frame of the world body at the model's ``position`` and
``orientation``, its names prefixed ``<model>/`` so that MuJoCo's body and joint names are the
scene's (``<model>/<link>``, ``<model>/<joint>``). What is MuJoCo's and what is physval's:

- MuJoCo's: everything the file's own reading decides: masses, inertias (URDF ``<inertial>``,
  MJCF ``<inertial>`` or the geoms' under the file's ``<compiler inertiafromgeom>``), joint
  frames, axes, ranges (MJCF ``angle`` units), damping and armature (MJCF ``<default>``
  classes), every other ``<compiler>`` setting of the file;
- physval's (``NATIVE_COMPILER``): ``fusestatic`` off, so every link stays a MuJoCo body that
  the scene's name addresses (MuJoCo's URDF default fuses a fixed joint's child into its
  parent; welded, its dynamics is the same);
- the scene's: the timestep, gravity, integrator and every other ``<option>`` (the spec's):
  ``attach`` keeps the parent's options, so a model file's own ``<option>`` (an MJCF's
  timestep, gravity, integrator) is not used; MuJoCo's attach-conflict warnings say which
  values were dropped, and the provenance lists them;
- the base: fixed (the root body welded to the frame; an MJCF root's free joint removed) or
  free (a free joint ``<root>/free`` added to the root link's body); joint states at t = 0
  from the scene (``ModelLayout.initial_position``/``initial_velocity``, the file's own
  coordinate: MuJoCo's qpos);
- actuators: removed (a scene applies no controls; a position servo at ctrl 0 would hold its
  joint, a motor at ctrl 0 does nothing): the model is passive, as physval's reading of it;
- contacts: ``collisions: false`` removes the geoms that neither collide nor weigh
  (``drop_idle_geoms``) and gives the remaining ones ``contype = conaffinity = 0`` (on the
  compiled model, so the compiler's inertia-from-geom logic sees the file's own values).
  ``collisions: true`` keeps every geom of the file (MuJoCo's reading of its shapes, meshes
  included) and gives them the scene's contacts, not the file's: every model geom gets
  ``contype = conaffinity = 0`` too (the file's bitmasks, ``friction``, ``solref`` and
  ``<contact>`` pairs do not act), and each geom on a model body gets an explicit ``<pair>``
  with every geom of the scene that collides (its bodies' and the ground's,
  ``pair_with_scene``) carrying the matched profile's values for that pair: a model link's
  scene values are ``urdf.LINK_CONTACT`` (restitution 0, friction 0), so the scene's pair
  (restitution the larger, friction the geometric mean) is the other end's restitution
  without friction: that geom's own ``solref``/``solimp`` (``mjcf.geom_surface``: its
  values as if it met itself) and condim 1. A model's geoms on its world body (an MJCF's
  floor and rails, which physval's reading leaves out) and on links welded to the world get
  no pair; the links of one model, and two models, do not meet each other (physval's
  reading lets a model's links that share no joint touch: a difference of this loader).
  The ``defaults`` profile gets the same pairs (MuJoCo's own values are not restored).

MuJoCo is imported inside the functions: the adapter imports it first, headless
(``adapter.NO_RENDERING``).
"""

from __future__ import annotations

import warnings

import numpy as np

from validation.engines.frames import matrix_to_quat
from validation.engines.mujoco.mjcf import FRICTIONLESS_CONDIM
from validation.scenario.packages import PACKAGE_URI, resolve

FREE_JOINT = "free"
"""The name (after the root link's name) of the free joint a free-base model's root gets."""

NATIVE_COMPILER = {"fusestatic": False}
"""``<compiler>`` settings physval sets on every model file (module docstring): links on fixed
joints stay bodies, addressable by the scene's names."""

WORLD_BODY = "world"
"""MuJoCo's world body: its geoms weigh nothing; an MJCF model's root when no top-level body
is free (``validation/scenario/mjcf.py``)."""

AXIS_JOINTS = (2, 3)
"""MuJoCo's ``mjtJoint`` codes of the joints with one coordinate: mjJNT_SLIDE 2, mjJNT_HINGE 3."""


def mujoco_name(layout, name: str) -> str:
    """The MuJoCo name of a file's link or joint once attached: the scene's name."""
    return f"{layout.name}/{name}"


def _resolve_meshes(child, layout) -> None:
    """``package://NAME/path`` mesh files resolved as physval's load resolves them
    (``validation.scenario.packages.resolve``: the file's folder tree, then ``--package-path``):
    MuJoCo's importer would take the URL as a relative path. Other paths are MuJoCo's own."""
    for mesh in child.meshes:
        if mesh.file.startswith(PACKAGE_URI):
            found = resolve(mesh.file, layout.path, layout.package_paths)
            mesh.file = mesh.file if found is None else str(found)


def _weighs(child, body) -> bool:
    """Whether MuJoCo's compiler takes ``body``'s inertia from its geoms (``inertiafromgeom``
    true, or auto on a body without an explicit ``<inertial>``)."""
    import mujoco

    if body.name == WORLD_BODY:
        return False
    rule = child.compiler.inertiafromgeom
    if rule == mujoco.mjtInertiaFromGeom.mjINERTIAFROMGEOM_TRUE:
        return True
    automatic = rule == mujoco.mjtInertiaFromGeom.mjINERTIAFROMGEOM_AUTO
    return automatic and not body.explicitinertial


def drop_idle_geoms(child) -> None:
    """Under ``collisions: false``: the geoms that take no part in the model (they collide with
    nothing, and their body's inertia is stated, ``_weighs``) removed before compiling, and the
    meshes no geom uses left: a model's meshes are read only where MuJoCo weighs them (a mesh
    file MuJoCo cannot read, or an empty one, then does not matter)."""
    for body in child.bodies:
        if not _weighs(child, body):
            for geom in list(body.geoms):
                child.delete(geom)
    used = {geom.meshname for geom in child.geoms}
    for mesh in list(child.meshes):
        if mesh.name not in used:
            child.delete(mesh)


def _root_body(child, layout):
    """The model's root body in the file's spec (the layout's root link)."""
    body = child.body(layout.root_link)
    if body is None:
        raise ValueError(f"{layout.path.name}: MuJoCo read no body {layout.root_link!r}")
    return body


def _set_base(child, layout) -> None:
    """Weld or free the root (module docstring)."""
    import mujoco

    if layout.root_link == WORLD_BODY:
        return  # an MJCF without a free top-level body: its bodies hang from the world
    root = _root_body(child, layout)
    free = [j for j in root.joints if j.type == mujoco.mjtJoint.mjJNT_FREE]
    if layout.spec.fixed_base:
        for joint in free:
            child.delete(joint)
        return
    if free:
        return
    if list(root.joints):
        raise ValueError(
            f"{layout.path.name}: the root body {layout.root_link!r} has joints of its own: "
            "MuJoCo gives a free joint only to a body without other joints (fixed_base: true)"
        )
    root.add_freejoint(name=f"{layout.root_link}/{FREE_JOINT}")


def _name_geoms(child) -> None:
    """Every unnamed geom named ``<body>/collision<k>`` (an explicit pair names its geoms;
    MuJoCo's URDF importer names none)."""
    for body in child.bodies:
        for k, geom in enumerate(body.geoms):
            geom.name = geom.name or f"{body.name}/collision{k}"


def _welded(body) -> bool:
    """Whether ``body`` (a child spec's) is held to the world: no joint on it or above it."""
    while body is not None and body.name != WORLD_BODY:
        if list(body.joints):
            return False
        body = body.parent
    return True


def scene_geoms(parent) -> list:
    """The geoms of the scene (``mjcf``'s, before any model is attached) that collide."""
    return [g for g in parent.geoms if g.name and (g.contype or g.conaffinity)]


def pair_with_scene(parent, child, others) -> None:
    """Under ``collisions: true``: a ``<pair>`` on ``parent`` between each geom of a moving
    model body of ``child`` (attached, names prefixed) and each geom of ``others`` (the
    scene's, ``scene_geoms``), with that scene geom's ``solref``/``solimp`` and condim 1
    (module docstring: the matched profile's pair of a link of restitution and friction 0)."""
    for body in child.bodies:
        if body.name == WORLD_BODY or _welded(body):
            continue
        for geom in body.geoms:
            for other in others:
                parent.add_pair(
                    geomname1=geom.name,
                    geomname2=other.name,
                    condim=FRICTIONLESS_CONDIM,
                    solref=list(other.solref),
                    solimp=list(other.solimp),
                )


def attach_model(parent, layout) -> None:
    """Read ``layout``'s file with MuJoCo's own importer and attach it to ``parent`` (an
    ``MjSpec``) at the model's pose, names prefixed, and under ``collisions: true`` paired
    with the scene's colliding geoms (module docstring)."""
    import mujoco

    others = scene_geoms(parent)
    child = mujoco.MjSpec.from_file(str(layout.path))
    for name, value in NATIVE_COMPILER.items():
        setattr(child.compiler, name, value)
    for actuator in list(child.actuators):
        child.delete(actuator)  # a scene applies no controls: a passive model
    if not layout.spec.collisions:
        drop_idle_geoms(child)
    else:
        _name_geoms(child)
    _resolve_meshes(child, layout)
    _set_base(child, layout)
    spec = layout.spec
    frame = parent.worldbody.add_frame(
        pos=[float(v) for v in spec.position], quat=[float(v) for v in spec.orientation]
    )
    parent.attach(child, prefix=f"{layout.name}/", frame=frame)
    if layout.spec.collisions:
        pair_with_scene(parent, child, others)


def compile_with_models(xml: str, layouts) -> tuple[object, list[str]]:
    """(MjModel, MuJoCo's attach-conflict warnings) of the scene's MJCF ``xml`` with every
    model of ``layouts`` (``ModelLayout``) attached, and MuJoCo's contacts on when a model's
    pairs need them (the scene without its models may have had nothing to touch)."""
    import mujoco

    parent = mujoco.MjSpec.from_string(xml)
    for layout in layouts:
        attach_model(parent, layout)
    if parent.pairs:  # the scene without its models may have nothing that touches
        parent.option.disableflags &= ~int(mujoco.mjtDisableBit.mjDSBL_CONTACT)
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        model = parent.compile()
    notes = [" ".join(str(w.message).split()) for w in caught]
    switch_off_collisions(model, layouts)
    return model, notes


def switch_off_collisions(model, layouts) -> None:
    """``contype = conaffinity = 0`` on every geom of every model (its bodies' and the geoms
    it attached to the world body, named with its prefix): with ``collisions: false`` it
    touches nothing; with ``collisions: true`` only its explicit pairs act
    (``pair_with_scene``)."""
    import mujoco

    for layout in layouts:
        prefix = f"{layout.name}/"
        for geom in range(model.ngeom):
            body = mujoco.mj_id2name(model, mujoco.mjtObj.mjOBJ_BODY, model.geom_bodyid[geom])
            name = mujoco.mj_id2name(model, mujoco.mjtObj.mjOBJ_GEOM, geom) or ""
            if (body or "").startswith(prefix) or name.startswith(prefix):
                model.geom_contype[geom] = 0
                model.geom_conaffinity[geom] = 0


def set_joint_state(model, data, layouts) -> None:
    """Each model's hinges and slides at the scene's t = 0 coordinates (qpos, qvel: the file's
    own convention; a ball joint, which ``joint_positions`` cannot state, and a free root stay
    at ``qpos0``, at rest)."""
    import mujoco

    for layout in layouts:
        for file_joint in layout.file_joints:
            jid = mujoco.mj_name2id(
                model, mujoco.mjtObj.mjOBJ_JOINT, mujoco_name(layout, file_joint or "")
            )
            if jid < 0 or model.jnt_type[jid] not in AXIS_JOINTS:
                continue  # welded (a fixed joint, the base's weld), or a ball
            data.qpos[model.jnt_qposadr[jid]] = layout.initial_position(file_joint)
            data.qvel[model.jnt_dofadr[jid]] = layout.initial_velocity(file_joint)


def joint_friction(model, scenario) -> np.ndarray:
    """(j,) N·m or N: each scene joint's dry friction as MuJoCo holds it, ``dof_frictionloss``
    (its URDF importer reads ``<dynamics friction>`` into it, its MJCF parser
    ``frictionloss``; 0 for a joint MuJoCo welded, and for every joint ``mjcf`` writes from
    the scene's, which have none): the ``JointReport.friction`` of the ``model_fields`` tier."""
    import mujoco

    friction = np.zeros(len(scenario.joints))
    for k, joint in enumerate(scenario.joints):
        jid = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_JOINT, joint.name)
        if jid >= 0:
            friction[k] = model.dof_frictionloss[model.jnt_dofadr[jid]]
    return friction


def body_offsets(scene, body_count: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Per scene body, its frame in the MuJoCo body's (``ModelLayout.body_in_link``):
    rotations (n, 3, 3), translations (n, 3), and (n,) whether it is a model's body (the
    others are written by ``mjcf`` with their frame at the centre of mass: identity; every
    body's without a natively loaded ``scene``, None)."""
    rotation = np.repeat(np.eye(3)[None], body_count, axis=0)
    translation = np.zeros((body_count, 3))
    native = np.zeros(body_count, dtype=bool)
    if scene is None:
        return rotation, translation, native
    index = {body.name: k for k, body in enumerate(scene.scenario.bodies)}
    for layout in scene.models:
        for name, frame in zip(layout.bodies, layout.body_in_link, strict=True):
            k = index[name]
            rotation[k], translation[k], native[k] = frame.rotation, frame.translation, True
    return rotation, translation, native


def offset_quaternions(rotation: np.ndarray) -> np.ndarray:
    """(n, 4) w x y z of the offsets' rotations."""
    return np.array([matrix_to_quat(r) for r in rotation])


def without_models(scene):
    """The scene's scenario without the bodies and joints its models own (what ``mjcf``
    writes under native loading), and the joint tree of what remains."""
    from validation.scenario.joints import joint_tree

    owned = scene.model_names.keys()
    scenario = scene.scenario
    bodies = [b for b in scenario.bodies if b.name not in owned]
    joints = [j for j in scenario.joints if j.name not in owned]
    ties = [(j.name, j.parent, j.child) for j in joints]
    ties += [(f"spring {k}", s.a, s.b) for k, s in enumerate(scenario.springs)]
    for name, a, b in ties:
        if a in owned or b in owned:
            raise ValueError(
                f"{name} joins a model's body: the native loader keeps a model whole "
                "(use mujoco(model_loader=physval))"
            )
    pairs = [p for p in scenario.pairs if not {p.a, p.b} & owned]  # models touch nothing
    rest = scenario.model_copy(update={"bodies": bodies, "joints": joints, "pairs": pairs})
    return rest, joint_tree(rest)
