"""The Drake adapter: a ``Scenario`` as a pydrake ``MultibodyPlant`` and ``SceneGraph`` built
programmatically, advanced by a ``Simulator`` and read back in the scene's conventions.

Every fact it relies on is measured in ``docs/engines-drake.md`` (section numbers below).

Boundary conventions (engines-drake.md 2). Each moving scene body is one free ``RigidBody``
whose frame origin is its centre of mass and whose axes are the scene's body axes: its
``SpatialInertia`` is made from the scene's mass and full (body-frame) inertia about the
centre of mass, so nothing is converted; its collision shape sits at the scene shape's
``offset`` and ``orientation`` in that frame. A free body's generalized positions are
``qw qx qy qz x y z`` (scalar first, body to world) and its velocities ``wx wy wz vx vy vz``,
both in the world frame (``floating_positions_start`` / ``floating_velocities_start_in_v``
locate them in the plant's state). A fixed scene body is collision geometry of the world body
at its pose, the ground a ``HalfSpace`` of the world body at ``physics.ground_pose``.

Profiles (``declaration.PROFILES``):

- ``discrete``: ``MultibodyPlant(time_step=dt)``, Drake's default contact model and discrete
  contact approximation (``lagged`` in 1.51, or the spec's ``contact_approximation``);
  ``advance(n)`` is n plant updates (one ``Simulator.AdvanceTo`` to n·dt).
- ``continuous``: ``MultibodyPlant(time_step=0)`` under ``ResetIntegratorFromFlags(integrator,
  MAX_STEP_SIZE)`` with the target accuracy; dt is the observation interval.

Joints (``joints``, engines-drake.md 9): a scene with joints has Drake's joints between frames
that coincide at t = 0 (every coordinate 0 at the stated poses), its bodies' velocities set
through Drake's Jacobians and its body states read through Drake's kinematics; a scene without
joints takes the free-body path above, unchanged.

Models (``models``, engines-drake.md 10): with ``model_loader=native`` (the default) each model
file is read by Drake's own ``Parser`` (``models``) and its links stand for the scene's bodies
of that model (a link's pose times ``ModelLayout.body_in_link`` is the scene body's); the
scene's other bodies and joints are built as above. ``model_loader=physval`` builds the model
from the bodies and joints physval expanded it into, like any other scene.

Loads: springs are ``LinearSpringDamper`` force elements (a rest length of 0, which that
element refuses, an isotropic ``LinearBushingRollPitchYaw`` when undamped); constant forces
and torques are ``ExternallyAppliedSpatialForce`` values at each centre of mass, fixed on the
plant's ``applied_spatial_force`` input port once.
"""

from __future__ import annotations

import contextlib
import importlib.metadata
import logging
from collections.abc import Set as AbstractSet
from dataclasses import dataclass

import numpy as np
from pydrake.geometry import (
    Box,
    Capsule,
    CollisionFilterDeclaration,
    Cylinder,
    GeometrySet,
    HalfSpace,
    Sphere,
)
from pydrake.math import RigidTransform
from pydrake.multibody.math import SpatialForce, SpatialVelocity
from pydrake.multibody.plant import (
    AddMultibodyPlantSceneGraph,
    CoulombFriction,
    DiscreteContactApproximation,
    ExternallyAppliedSpatialForce,
)
from pydrake.multibody.tree import (
    FixedOffsetFrame,
    LinearBushingRollPitchYaw,
    LinearSpringDamper,
    RotationalInertia,
    SpatialInertia,
)
from pydrake.systems.analysis import ResetIntegratorFromFlags, Simulator
from pydrake.systems.framework import DiagramBuilder

from validation.engine_api import model_loader
from validation.engines.base import (
    JointReport,
    ModelProbe,
    ModelReport,
    Provenance,
    Snapshot,
    Trajectory,
)
from validation.engines.drake.declaration import (
    CONTINUOUS,
    DEFAULT_INTEGRATOR,
    DISCRETE,
    NAME,
    NATIVE,
    accuracy_of,
    profile_of,
)
from validation.engines.drake.joints import (
    Placement,
    add_joints,
    body_states,
    filter_jointed_pairs,
    joint_report,
    joint_velocities,
    kinematic_states,
    pose,
    set_tree_positions,
    tree_velocities,
)
from validation.engines.drake.models import (
    DRAKE_LOGGER,
    add_models,
    filter_model_geometry,
    model_notes,
    model_velocities,
)
from validation.engines.reference import dynamic_bodies
from validation.reference.loads import WORLD
from validation.scenario import BodySpec, Scenario
from validation.scenario.compiled import CompiledScene
from validation.scenario.engine_spec import EngineSpec
from validation.scenario.physics import ground_pose, pair_value

# --- numbers and where they come from ---------------------------------------------------------

MAX_STEP_SIZE = 0.1
"""s. The continuous profile's largest integrator step: Drake's ``SimulatorConfig``
default. The steps are also cut at every observation (``AdvanceTo`` ends at n·dt exactly)."""

APPROXIMATIONS = {
    "lagged": DiscreteContactApproximation.kLagged,
    "sap": DiscreteContactApproximation.kSap,
    "similar": DiscreteContactApproximation.kSimilar,
    "tamsi": DiscreteContactApproximation.kTamsi,
}
"""``contact_approximation`` word -> Drake's enum (the words are Drake's own, lower case)."""

SAME_VALUE = 1e-12
"""Relative. A scene's pair friction and Drake's combination of the two geometries' values
that differ by more than this are named in the provenance notes."""

GROUND = "ground"
"""The name scene pairs use for the ground plane."""

QUIET_LOG_LEVEL = logging.ERROR
"""Drake's log level while the plant is finalized and the diagram built: a ground
``HalfSpace`` logs a warning there that deformable contact does not support it (a scene has
no deformable body); errors still show."""

SHAPE_BUILDERS = {
    "sphere": lambda s: Sphere(s.radius),
    "box": lambda s: Box(*(2.0 * np.asarray(s.half_extents, dtype=float))),
    # Drake's Capsule(radius, length): length is the cylinder's, along the geometry's z.
    "capsule": lambda s: Capsule(s.radius, 2.0 * s.half_length),
    # Drake's Cylinder(radius, length): its full length, along the geometry's z.
    "cylinder": lambda s: Cylinder(s.radius, 2.0 * s.half_length),
}
"""Scene shape type -> Drake ``Shape`` (full widths and lengths, where the scene has halves)."""


def body_name(index: int, spec: BodySpec) -> str:
    """A scene body's name in Drake (its body and its collision shape): unique by its index."""
    return f"body{index}_{spec.name}"


def rotational_inertia(matrix: np.ndarray) -> RotationalInertia:
    """A (3, 3) kg·m² inertia matrix as Drake's ``RotationalInertia`` (moments, products)."""
    m = np.asarray(matrix, dtype=float)
    return RotationalInertia(m[0, 0], m[1, 1], m[2, 2], m[0, 1], m[0, 2], m[1, 2])


@contextlib.contextmanager
def quiet_drake():
    """Drake's log at ``QUIET_LOG_LEVEL`` for the block, then as it was."""
    logger = logging.getLogger(DRAKE_LOGGER)
    level = logger.level
    logger.setLevel(QUIET_LOG_LEVEL)
    try:
        yield
    finally:
        logger.setLevel(level)


def drake_friction(a: float, b: float) -> float:
    """Drake's combination of two geometries' friction coefficients, 2ab/(a+b) (0 if both 0)."""
    return 0.0 if a + b == 0.0 else 2.0 * a * b / (a + b)


@dataclass(frozen=True)
class Settings:
    """The effective settings of one adapter (the spec's options resolved)."""

    profile: str
    contact_approximation: str | None
    accuracy: float | None
    integrator: str | None
    model_loader: str = NATIVE

    @staticmethod
    def of(spec: EngineSpec) -> Settings:
        options = spec.as_dict()
        profile = profile_of(options)
        loader = model_loader(NAME, options)
        if profile == DISCRETE:
            approximation = options.get("contact_approximation")
            return Settings(
                DISCRETE, None if approximation is None else str(approximation), None, None, loader
            )
        return Settings(
            CONTINUOUS,
            None,
            accuracy_of(options),
            str(options.get("integrator", DEFAULT_INTEGRATOR)),
            loader,
        )


# --- the adapter ----------------------------------------------------------------------------


class DrakeAdapter:
    """pydrake as an ``EngineAdapter``: one diagram (plant + scene graph) and simulator per load.

    Attributes (after ``load``):
        plant: the ``MultibodyPlant``. simulator: its ``Simulator``.
        bodies: (n,) the ``RigidBody`` of each scene body, None for a fixed one, scenario order
            (a native model's body: its link's). models: the native models (``NativeModel``).
        placement: bodies, each body's frame in its Drake body's, the Drake joint of each scene
            joint (``joints.Placement``).
        tree: the scene's ``JointTree`` (None without joints). joints: the Drake joints
            physval built (a native model's are its file's).
        free: the free moving bodies (every moving one without joints).
        position_index: (f, 7) int, each free body's q (qw qx qy qz x y z) in the plant state.
        velocity_index: (f, 6) int, its v (wx wy wz vx vy vz), offset by the plant's positions.
    """

    precision = "float64"

    def __init__(self, spec: EngineSpec):
        self.spec = spec
        self.settings = Settings.of(spec)
        self.simulator = None
        self.diagram = None
        self.plant = None

    # -- building --------------------------------------------------------------------------

    def load(self, scene: CompiledScene) -> None:
        scenario = scene.scenario
        self.scene = scene
        self.scenario = scenario
        self.steps_taken = 0
        self.notes: list[str] = []
        self.fixed = np.array([b.fixed for b in scenario.bodies], dtype=bool)
        builder = DiagramBuilder()
        time_step = float(scenario.dt) if self.settings.profile == DISCRETE else 0.0
        plant, scene_graph = AddMultibodyPlantSceneGraph(builder, time_step)
        self.plant = plant
        self.geometry: dict[int, tuple] = {}  # object -> (Drake body, pose in it, shape, id)
        if self.settings.contact_approximation is not None:
            plant.set_discrete_contact_approximation(
                APPROXIMATIONS[self.settings.contact_approximation]
            )
        plant.mutable_gravity_field().set_gravity_vector(np.asarray(scenario.gravity, dtype=float))
        layouts = scene.models if self.settings.model_loader == NATIVE else ()
        owned = scene.model_names.keys() if layouts else frozenset()
        self.bodies = [
            None if b.name in owned else self._create_body(k, b)
            for k, b in enumerate(scenario.bodies)
        ]
        children = {joint.name: joint.child for joint in scenario.joints}
        self.models = add_models(plant, scene_graph, layouts, scenario.gravity, children)
        self.notes += model_notes(self.models)
        placed = self._place_models(scenario)
        self.tree = scene.joint_tree
        self.joints = [] if self.tree is None else self._create_joints(scenario, placed, owned)
        model_joints = {name: j for model in self.models for name, j in model.joints.items()}
        self.placement = Placement(
            self.bodies, placed, {**{j.name(): j for j in self.joints}, **model_joints}
        )
        self.kinematic = self.tree is not None or bool(self.models)
        if scenario.ground is not None:
            self._create_ground()
        self._create_springs()
        pair_geometry = self._pair_geometries(scenario)
        with quiet_drake():
            plant.Finalize()
            self._filter_pairs(scene_graph, pair_geometry)
            self.filtered_geometry = filter_model_geometry(scene_graph, self.models)
            self.filtered_pairs = (
                0
                if self.tree is None
                else filter_jointed_pairs(scene_graph, self.tree, self.geometry)
            )
            self.diagram = builder.Build()
            self.simulator = Simulator(self.diagram)
        self.context = self.plant.GetMyMutableContextFromRoot(self.simulator.get_mutable_context())
        self._index_state()
        self._set_start(scenario)
        self._fix_loads()
        if self.settings.profile == CONTINUOUS:
            integrator = ResetIntegratorFromFlags(
                self.simulator, self.settings.integrator, MAX_STEP_SIZE
            )
            integrator.set_target_accuracy(self.settings.accuracy)
        self.simulator.Initialize()

    def _create_body(self, index: int, spec: BodySpec):
        """One scene body: a free ``RigidBody`` with the scene's mass and inertia about its
        centre of mass (body axes), its collision shape at the shape's place in the body
        (``_register``); a fixed body's shape on the world body at its pose (and no plant
        body). A body with ``collides: false`` registers no collision shape (it touches
        nothing: ``non_colliding``)."""
        plant = self.plant
        if spec.fixed:
            if spec.collides:
                self._register(
                    index, spec, plant.world_body(), pose(spec.position, spec.orientation)
                )
            return None
        inertia = SpatialInertia.MakeFromCentralInertia(
            float(spec.mass), np.zeros(3), rotational_inertia(self._inertia(index))
        )
        body = plant.AddRigidBody(body_name(index, spec), inertia)
        if spec.collides:
            self._register(index, spec, body, RigidTransform())
        return body

    def _register(self, index: int, spec: BodySpec, body, where: RigidTransform) -> None:
        """The body's collision shape on the Drake ``body``, whose frame is the scene body's
        at ``where``: at the shape's ``offset`` and ``orientation`` in the scene body (a
        placed shape; the body's inertia, about its centre of mass, is the scene's whatever
        the shape's place), with its friction."""
        where = where @ pose(spec.shape.offset, spec.shape.orientation)
        shape = SHAPE_BUILDERS[spec.shape.type](spec.shape)
        friction = CoulombFriction(float(spec.friction), float(spec.friction))
        found = self.plant.RegisterCollisionGeometry(
            body, where, shape, body_name(index, spec), friction
        )
        self.geometry[index] = (body, where, shape, found)

    def _place_models(self, scenario: Scenario) -> list[RigidTransform]:
        """Each native model's links as its scene bodies' Drake bodies (``self.bodies``); each
        scene body's frame in its Drake body's (identity but for a model's)."""
        placed = [RigidTransform()] * len(scenario.bodies)
        index = {b.name: k for k, b in enumerate(scenario.bodies)}
        for model in self.models:
            for name, link, in_link in zip(
                model.layout.bodies, model.links, model.in_link, strict=True
            ):
                self.bodies[index[name]] = link
                placed[index[name]] = in_link
        return placed

    def _create_joints(self, scenario: Scenario, placed: list, owned: AbstractSet[str]) -> list:
        """The joint tree's joints (``joints.add_joints``) with the stated limits, but for a
        native model's (``owned``)."""
        limits = {j.name: tuple(j.limits) for j in scenario.joints if j.limits is not None}
        return add_joints(
            self.plant, self.tree, self.bodies, scenario.gravity, limits, placed, owned
        )

    def _inertia(self, index: int) -> np.ndarray:
        """(3, 3) kg·m², body frame, about the centre of mass: the compiled scene's."""
        return np.asarray(self.scene.inertia[index], dtype=float)

    def _create_ground(self) -> None:
        """A ``HalfSpace`` (outward normal its +z) on the world body at the ground's pose."""
        point, quat = ground_pose(self.scenario.ground)
        mu = float(self.scenario.ground.friction)
        where = pose(point, quat)
        found = self.plant.RegisterCollisionGeometry(
            self.plant.world_body(), where, HalfSpace(), GROUND, CoulombFriction(mu, mu)
        )
        self.geometry[len(self.scenario.bodies)] = (
            self.plant.world_body(),
            where,
            HalfSpace(),
            found,
        )

    def _end(self, body: int, anchor: np.ndarray):
        """(Drake body, anchor in its frame) of one spring end: a moving body's own anchor; a
        fixed body's or the world's as a point of the world body."""
        if body == WORLD:
            return self.plant.world_body(), np.asarray(anchor, dtype=float)
        if self.bodies[body] is None:
            spec = self.scenario.bodies[body]
            world = pose(spec.position, spec.orientation).multiply(np.asarray(anchor, dtype=float))
            return self.plant.world_body(), world
        return self.bodies[body], np.asarray(anchor, dtype=float)

    def _create_springs(self) -> None:
        """Each scene spring as Drake's own force element (module docstring)."""
        springs = self.scene.springs
        for k in range(springs.count):
            body_a, p_a = self._end(int(springs.body_a[k]), springs.anchor_a[k])
            body_b, p_b = self._end(int(springs.body_b[k]), springs.anchor_b[k])
            if body_a.index() == body_b.index():
                continue  # both ends on the world: it moves nothing
            rest, stiffness, damping = (
                float(springs.rest_length[k]),
                float(springs.stiffness[k]),
                float(springs.damping[k]),
            )
            if rest > 0.0:
                self.plant.AddForceElement(
                    LinearSpringDamper(body_a, p_a, body_b, p_b, rest, stiffness, damping)
                )
                continue
            if damping > 0.0:
                raise ValueError(
                    f"spring {k}: a damped spring of rest length 0 has no Drake force element "
                    "(LinearSpringDamper needs a rest length > 0; a bushing damps the whole "
                    "relative velocity, the scene only its stretch rate)"
                )
            self._zero_length_spring(k, body_a, p_a, body_b, p_b, stiffness)

    def _zero_length_spring(self, k: int, body_a, p_a, body_b, p_b, stiffness: float) -> None:
        """A spring of rest length 0 pulls with -k·(P - Q): an isotropic linear bushing with
        force stiffness k on every axis and no torque stiffness or damping is exactly that
        (its force is along P - Q, so where on the line it acts changes no torque)."""
        frames = []
        for end, (body, point) in (("a", (body_a, p_a)), ("b", (body_b, p_b))):
            frame = FixedOffsetFrame(f"spring{k}_{end}", body.body_frame(), RigidTransform(point))
            frames.append(self.plant.AddFrame(frame))
        zero = np.zeros(3)
        self.plant.AddForceElement(
            LinearBushingRollPitchYaw(frames[0], frames[1], zero, zero, np.full(3, stiffness), zero)
        )
        self.notes.append(
            f"spring {k}: rest length 0, a LinearBushingRollPitchYaw with force stiffness "
            f"{stiffness:g} N/m on each axis (LinearSpringDamper refuses a rest length of 0)"
        )

    def _index_state(self) -> None:
        """The moving bodies, the free ones among them (all of them without joints; with joints
        the bodies that are no joint's child) and where each free body's q and v sit."""
        moving = dynamic_bodies(self.scene)
        positions = self.plant.num_positions()
        self.moving = moving
        self.free = (
            moving
            if self.tree is None
            else np.array([j.child for j in self.tree.joints if j.type == "free"], dtype=int)
        )
        self.position_index = np.array(
            [np.arange(7) + self.bodies[k].floating_positions_start() for k in self.free],
            dtype=int,
        ).reshape(-1, 7)
        self.velocity_index = np.array(
            [
                np.arange(6) + positions + self.bodies[k].floating_velocities_start_in_v()
                for k in self.free
            ],
            dtype=int,
        ).reshape(-1, 6)

    def _set_start(self, scenario: Scenario) -> None:
        """The free bodies' stated poses and velocities; with joints, every generalized
        velocity from the stated body velocities (``joints.joint_velocities``; each joint's
        coordinates are 0 at the stated poses)."""
        for k in self.free:
            spec, body = scenario.bodies[k], self.bodies[k]
            where = pose(spec.position, spec.orientation).multiply(
                self.placement.placed[k].inverse()
            )
            self.plant.SetFreeBodyPose(self.context, body, where)
            self.plant.SetFreeBodySpatialVelocity(
                self.context,
                body,
                SpatialVelocity(
                    np.asarray(spec.angular_velocity, dtype=float),
                    np.asarray(spec.velocity, dtype=float),
                ).Shift(-where.rotation().multiply(self.placement.point(k))),
            )
        if self.kinematic:
            known = model_velocities(self.plant, self.context, self.models)
            stated = [(b.velocity, b.angular_velocity) for b in scenario.bodies]
            self.plant.SetVelocities(
                self.context,
                joint_velocities(
                    self.plant, self.context, self.placement, self.moving, stated, known
                ),
            )
        self.start_positions = self.plant.GetPositions(self.context).copy()
        self._fixed_pose = (
            np.array([b.position for b in scenario.bodies], dtype=float).reshape(-1, 3),
            np.array([b.orientation for b in scenario.bodies], dtype=float).reshape(-1, 4),
        )

    def _fix_loads(self) -> None:
        """Every moving body's constant force and torque (world frame, at its centre of mass)
        as one ``ExternallyAppliedSpatialForce`` each, fixed on the input port (empty list
        when there are none: the port must have a value)."""
        loads = []
        scene = self.scene
        for k in self.moving:
            if not (np.any(scene.force[k] != 0.0) or np.any(scene.torque[k] != 0.0)):
                continue
            load = ExternallyAppliedSpatialForce()
            load.body_index = self.bodies[k].index()
            load.p_BoBq_B = np.zeros(3)
            load.F_Bq_W = SpatialForce(
                np.asarray(scene.torque[k], dtype=float), np.asarray(scene.force[k], dtype=float)
            )
            loads.append(load)
        self.loads = len(loads)
        self.plant.get_applied_spatial_force_input_port().FixValue(self.context, loads)

    def _differing_pairs(self, scenario: Scenario) -> list[tuple[int, int, float]]:
        """(i, j, μ) of every pair of objects that can touch (scene bodies in order, then the
        ground) whose scene friction (its ``pairs:`` value or ``physics.PAIR_RULES``, the
        geometric mean) Drake's combination 2ab/(a+b) of the two geometries' does not give."""
        names = [b.name for b in scenario.bodies] + ([GROUND] if scenario.ground else [])
        own = [float(b.friction) for b in scenario.bodies]
        own += [float(scenario.ground.friction)] if scenario.ground else []
        if not scenario.pairs and len(set(own)) <= 1:
            return []  # equal coefficients: every rule gives that one
        still = list(self.fixed) + [True] * (len(names) - len(scenario.bodies))
        found = []
        for i in range(len(names)):
            for j in range(i + 1, len(names)):
                if (still[i] and still[j]) or not {i, j} <= self.geometry.keys():
                    continue  # two world geometries never touch; a native model's are its own
                wanted = pair_value(scenario, names[i], names[j], "friction")
                if abs(wanted - drake_friction(own[i], own[j])) > SAME_VALUE * max(1.0, wanted):
                    found.append((i, j, wanted))
        return found

    def _pair_geometries(self, scenario: Scenario) -> list[tuple[object, object, object, object]]:
        """For each pair whose friction Drake's rule would not give (``_differing_pairs``), a
        second copy of both shapes carrying the pair's μ (2μμ/(μ+μ) = μ), to be filtered so
        that only the two copies meet (``_filter_pairs``); (original a, original b, copy a,
        copy b) geometry ids per pair."""
        found = []
        for i, j, mu in self._differing_pairs(scenario):
            copies = []
            for k in (i, j):
                body, where, shape, _ = self.geometry[k]
                copies.append(
                    self.plant.RegisterCollisionGeometry(
                        body, where, shape, f"pair{i}_{j}_copy{k}", CoulombFriction(mu, mu)
                    )
                )
            found.append((self.geometry[i][3], self.geometry[j][3], *copies))
        if found:
            self.notes.append(
                f"friction: {len(found)} pair(s) whose scene value Drake's rule 2ab/(a+b) would "
                "not give get a second copy of both shapes with the pair's value, filtered to "
                "meet only each other (the originals of the pair filtered apart)"
            )
        return found

    def _filter_pairs(
        self, scene_graph, pairs: list[tuple[object, object, object, object]]
    ) -> None:
        """Collision filters of the pair copies: the pair's originals never meet, each copy
        meets only the other copy."""
        if not pairs:
            return
        every = [entry[3] for entry in self.geometry.values()]
        every += [g for pair in pairs for g in pair[2:]]
        manager = scene_graph.collision_filter_manager()
        for original_a, original_b, copy_a, copy_b in pairs:
            declaration = CollisionFilterDeclaration()
            declaration.ExcludeBetween(GeometrySet([original_a]), GeometrySet([original_b]))
            for mine, partner in ((copy_a, copy_b), (copy_b, copy_a)):
                others = [g for g in every if g not in (mine, partner)]
                declaration.ExcludeBetween(GeometrySet([mine]), GeometrySet(others))
            manager.Apply(declaration)

    # -- stepping --------------------------------------------------------------------------

    def _time(self, steps: int) -> float:
        return steps * float(self.scenario.dt)

    def advance(self, steps: int) -> None:
        """To the time (steps taken + ``steps``)·dt: that many plant updates (discrete), or the
        integrator's own steps to that time (continuous)."""
        self.steps_taken += int(steps)
        self.simulator.AdvanceTo(self._time(self.steps_taken))

    def advance_observed(self, steps: int) -> Trajectory:
        """``steps`` advances of one dt, the raw state read after each, converted at the end;
        fewer when Drake refuses to go on from a non-finite state (its SceneGraph raises on a
        NaN pose, with a per-process source id in the message): the states up to that one."""
        raw = np.empty((steps, self.plant.num_multibody_states()))
        for k in range(steps):
            try:
                self.advance(1)
            except RuntimeError:
                raw[k] = self._raw_state()
                if np.isfinite(raw[k]).all():
                    raise  # not an explosion: an engine error
                raw = raw[: k + 1]
                break
            raw[k] = self._raw_state()
        taken = raw.shape[0]
        times = (self.steps_taken - taken + 1 + np.arange(taken)) * float(self.scenario.dt)
        return self._states(times, raw)

    # -- reading back ----------------------------------------------------------------------

    def _raw_state(self) -> np.ndarray:
        """(nq + nv,) the plant's state: positions, then velocities."""
        return self.plant.GetPositionsAndVelocities(self.context)

    def _states(self, times: np.ndarray, raw: np.ndarray) -> Trajectory:
        """The scene's conventions for raw plant states ``raw (s, nq + nv)``: every scene body
        in order, a fixed body at its scene pose and at rest; with joints through Drake's own
        kinematics (``joints.kinematic_states``), else each free body's q (qw qx qy qz x y z)
        and v (world ω, velocity) read as they are."""
        if self.kinematic:
            return kinematic_states(
                self.plant, self.placement, self.moving, times, raw, self._fixed_pose
            )
        s, n = raw.shape[0], len(self.scenario.bodies)
        pos = np.repeat(self._fixed_pose[0][None], s, axis=0)
        quat = np.repeat(self._fixed_pose[1][None], s, axis=0)
        vel, ang_vel = np.zeros((s, n, 3)), np.zeros((s, n, 3))
        q = raw[:, self.position_index]
        v = raw[:, self.velocity_index]
        pos[:, self.moving] = q[..., 4:7]
        quat[:, self.moving] = q[..., 0:4] / np.linalg.norm(q[..., 0:4], axis=-1, keepdims=True)
        vel[:, self.moving] = v[..., 3:6]
        ang_vel[:, self.moving] = v[..., 0:3]
        return Trajectory(np.asarray(times, dtype=float), pos, quat, vel, ang_vel)

    def observe(self) -> Snapshot:
        states = self._states(np.array([self._time(self.steps_taken)]), self._raw_state()[None])
        return Snapshot(
            float(states.t[0]),
            *(a[0] for a in (states.pos, states.quat, states.vel, states.ang_vel)),
        )

    def model_report(self) -> ModelReport:
        """The moving bodies as Drake holds them: each body's ``SpatialInertia`` in its frame
        (mass, centre of mass, inertia about it, rotated to world with the body's pose), the
        plant's kinetic energy, the gravitational energy of those masses in the plant's
        gravity, and its spatial momentum about the bodies' centre of mass; the springs' and
        constant loads' energy by the scene's laws at the poses Drake holds
        (``EvalPotentialEnergy`` raises for a ``LinearBushingRollPitchYaw``, engines-drake.md 3)."""
        plant, context = self.plant, self.context
        mass, com, inertia = [], [], []
        for k in self.moving:
            body = self.bodies[k]
            spatial = body.CalcSpatialInertiaInBodyFrame(context)
            pose_w = plant.EvalBodyPoseInWorld(context, body)
            central = spatial.Shift(spatial.get_com())
            rotation = pose_w.rotation().matrix()
            mass.append(spatial.get_mass())
            com.append(pose_w.multiply(spatial.get_com()))
            inertia.append(
                rotation @ central.CalcRotationalInertia().CopyToFullMatrix3() @ rotation.T
            )
        mass_array = np.array(mass, dtype=float)
        com_array = np.array(com, dtype=float).reshape(-1, 3)
        state = self.observe()
        gravity = plant.gravity_field().gravity_vector()
        energy = plant.EvalKineticEnergy(context) - float(mass_array @ (com_array @ gravity))
        energy += float(self.scene.spring_energy(state.pos[None], state.quat[None])[0])
        energy += float(self.scene.applied_force_energy(state.pos[None])[0])
        if mass_array.size:
            centre = mass_array @ com_array / mass_array.sum()
            momentum = plant.CalcSpatialMomentumInWorldAboutPoint(context, centre)
            linear, angular = momentum.translational(), momentum.rotational()
        else:
            linear, angular = np.zeros(3), np.zeros(3)
        return ModelReport(
            mass=mass_array,
            com=com_array,
            inertia_world=np.array(inertia, dtype=float).reshape(-1, 3, 3),
            energy=float(energy),
            linear_momentum=np.asarray(linear, dtype=float),
            angular_momentum=np.asarray(angular, dtype=float),
        )

    def joint_report(self) -> JointReport:
        """The joints Drake built, at the current state (``joints.joint_report``; the parity
        gate calls it at t = 0)."""
        return joint_report(self.plant, self.context, self.scenario, self.tree, self.placement)

    def model_probe(self, q: np.ndarray, nu: np.ndarray) -> ModelProbe:
        """The bodies, M(q) and bias at the joint tree's state (q, ν) (relative to t = 0),
        on a scratch context (the simulation's is left as it is): Drake's positions from the
        ones at t = 0 (``joints.set_tree_positions``), v = T ν (``joints.tree_velocities``),
        ``CalcMassMatrix`` and ``CalcBiasTerm`` - ``CalcGravityGeneralizedForces`` (C(q, v) v
        - τ_g: the velocity products and gravity; springs and applied loads are not in it)
        carried into the tree's coordinates: Tᵀ M T and Tᵀ (M Ṫ ν + C v - τ_g)."""
        plant = self.plant
        context = plant.CreateDefaultContext()
        q, nu = np.asarray(q, dtype=float), np.asarray(nu, dtype=float)
        set_tree_positions(plant, context, self.tree, self.placement, self.start_positions, q)
        change, drift = tree_velocities(plant, context, self.tree, self.placement)
        plant.SetVelocities(context, change @ nu)
        mass = plant.CalcMassMatrix(context)
        bias = plant.CalcBiasTerm(context) - plant.CalcGravityGeneralizedForces(context)
        pos, quat, _, _ = body_states(plant, context, self.placement, self.moving, self._fixed_pose)
        return ModelProbe(
            pos=pos,
            quat=quat,
            mass_matrix=change.T @ mass @ change,
            bias=change.T @ (mass @ drift(nu) + bias),
        )

    # -- provenance ------------------------------------------------------------------------

    def _integrator_settings(self) -> dict[str, object]:
        integrator = self.simulator.get_integrator()
        return {
            "integrator": self.settings.integrator,
            "target_accuracy": integrator.get_target_accuracy(),
            "maximum_step_size": integrator.get_maximum_step_size(),
            "fixed_step_mode": integrator.get_fixed_step_mode(),
            "steps_taken": integrator.get_num_steps_taken(),
        }

    def provenance(self) -> Provenance:
        """drake's version, the plant's contact settings, the profile and what it set; with
        joints, Drake's joint types by name and the parent/child pairs collision-filtered."""
        plant = self.plant
        s = self.settings
        settings: dict[str, object] = {
            **{f"spec.{k}": v for k, v in self.spec.as_dict().items()},
            "profile": s.profile,
            "precision": self.precision,
            "time_step": plant.time_step(),
            "contact_model": plant.get_contact_model().name,
            "discrete_contact_approximation": (
                plant.get_discrete_contact_approximation().name if s.profile == DISCRETE else "none"
            ),
            "gravity": plant.gravity_field().gravity_vector().tolist(),
            "applied_spatial_forces": self.loads,
            "force_elements": plant.num_force_elements(),
        }
        if self.joints:
            settings["joints"] = {joint.name(): joint.type_name() for joint in self.joints}
            settings["jointed_pairs_filtered"] = self.filtered_pairs
        if self.scene.models:
            settings["model_loader"] = s.model_loader
        if self.models:
            settings["models"] = {
                m.layout.name: plant.GetModelInstanceName(m.instance) for m in self.models
            }
            settings["model_geometry_filtered"] = self.filtered_geometry
        if s.profile == CONTINUOUS:
            settings["integration"] = self._integrator_settings()
        return Provenance(
            engine="drake",
            version=importlib.metadata.version("drake"),
            settings=settings,
            notes=list(self.notes),
        )

    def close(self) -> None:
        """Drop the simulator, diagram and plant (freed with the Python objects); idempotent."""
        self.simulator = None
        self.context = None
        self.diagram = None
        self.plant = None
        self.bodies = []
