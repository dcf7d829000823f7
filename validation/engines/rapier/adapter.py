"""The Rapier adapter: a ``Scenario`` as rapier3d rigid bodies and colliders, stepped by
``PhysicsWorld.step`` and read back in the scene's conventions.

Every fact it relies on is measured in ``docs/engines-rapier.md`` (section numbers below).

Boundary conventions (engines-rapier.md 2). A Rapier body's pose is its own frame; the adapter
puts the centre of mass at the body's origin, the collider at the scene shape's offset and
orientation from it, and the principal axes of the scene's inertia into the collider's
``MassProperties`` (``principal_inertia_local_frame``, in the collider's frame), so the body
frame *is* the scene's body frame and nothing is converted but the quaternion order:
Rapier's ``Rotation3.quaternion`` is x y z w, its constructor ``Rotation3(w, x, y, z)``.
Velocities are the centre of mass's, angular velocities in the world frame. Everything Rapier
holds is float32 (``declaration.PRECISION``): the parity gate takes the float32 tolerance and
the provenance says so in its notes.

Profiles (``declaration.PROFILES``, each choice documented there):

- ``matched`` (default): gyroscopic term on, CCD on, Rapier's per-manifold friction, the
  scene's combine rules (restitution by max, friction by geometric mean) and its ``pairs:``
  overrides set on each contact by a ``modify_solver_contacts`` hook, contacts only between
  touching shapes (no speculative band), no sleeping, no damping.
- ``defaults``: Rapier's own settings (Rapier's AVERAGE combine rule, sleeping, no CCD,
  speculative contacts) with the scene's masses, inertias, shapes, gravity, dt and per-body
  contact values.

In both, the world has one worker thread (``WORKER_THREADS``) and dt is the scene's.
"""

from __future__ import annotations

import importlib.metadata
from dataclasses import dataclass

import numpy as np
import rapier3d

from validation.engines.base import JointReport, ModelReport, Provenance, Snapshot, Trajectory
from validation.engines.frames import principal_axes
from validation.engines.rapier.declaration import DEFAULT_JOINTS, PRECISION, PROFILES, Profile
from validation.engines.rapier.joints import JointBuilder
from validation.engines.rapier.readback import from_xyzw, world_inertia
from validation.engines.reference import dynamic_bodies
from validation.reference.loads import applied_loads
from validation.reference.rotation import quat_multiply, quat_to_matrix
from validation.scenario import BodySpec, Scenario
from validation.scenario.compiled import (
    CompiledScene,
    angular_momentum,
    gravitational_energy,
    kinetic_energy,
    linear_momentum,
)
from validation.scenario.engine_spec import EngineSpec
from validation.scenario.physics import ground_pose, pair_value

# --- numbers and where they come from ---------------------------------------------------------

WORKER_THREADS = 1
"""Rapier's own worker pool per world (``set_num_threads``). physval runs one job per core
(``--jobs``); a second pool per job would oversubscribe the cores, and one thread keeps a run
bit-identical on rerun whatever the machine's core count (engines-rapier.md 3)."""

SCENE_COMBINE_RULES = {
    "restitution": rapier3d.CoefficientCombineRule.MAX,
    "friction": rapier3d.CoefficientCombineRule.GEOMETRIC_MEAN,
}
"""Rapier's combine rule per contact quantity for the scene's ``physics.PAIR_RULES``
(restitution: max of the two bodies', friction: geometric mean). Rapier uses the larger of
the two colliders' rules; every collider gets the same, so the pair gets exactly this one."""

RAPIER_COMBINE_RULE = "AVERAGE"
"""Rapier's default rule for both quantities (the defaults profile keeps it)."""

FRICTION_MODELS = {
    "coulomb": rapier3d.FrictionModel.COULOMB,
    "simplified": rapier3d.FrictionModel.SIMPLIFIED,
}

SWITCH = {"on": True, "off": False}

GROUND = "ground"
"""The name scene pairs use for the ground plane."""

SHAPE_BUILDERS = {
    "sphere": lambda s: rapier3d.Collider.ball(s.radius),
    "box": lambda s: rapier3d.Collider.cuboid(*s.half_extents),
    # Rapier's capsule half-height is the cylinder's half-length, along body z for capsule_z.
    "capsule": lambda s: rapier3d.Collider.capsule_z(s.half_length, s.radius),
    # Rapier's cylinder runs along the collider's y: ``SHAPE_TURNS`` lays it along the shape's z.
    "cylinder": lambda s: rapier3d.Collider.cylinder(s.half_length, s.radius),
}
"""Scene shape type -> ``ColliderBuilder`` (same size conventions)."""

Y_TO_Z = (np.sqrt(0.5), np.sqrt(0.5), 0.0, 0.0)
"""w x y z: a quarter turn about x, taking the collider's y axis onto the shape's z."""

SHAPE_TURNS = {"cylinder": Y_TO_Z}
"""The collider's axes in the shape's, for a builder whose axis is not the shape's z (the
identity for the others)."""


def collider_place(shape) -> tuple[np.ndarray, np.ndarray]:
    """The collider's translation (3,) and quaternion w x y z (4,) relative to its rigid body
    (the scene body's frame, at the centre of mass): the shape's ``offset``, and its
    ``orientation`` turned by the builder's own axes (``SHAPE_TURNS``)."""
    turn = np.asarray(SHAPE_TURNS.get(shape.type, (1.0, 0.0, 0.0, 0.0)), dtype=float)
    orientation = quat_multiply(np.asarray(shape.orientation, dtype=float), turn)
    return np.asarray(shape.offset, dtype=float), orientation


def rotation(quat) -> rapier3d.Rotation3:
    """A unit quaternion w x y z as Rapier's ``Rotation3`` (its constructor takes w first)."""
    w, x, y, z = (float(c) for c in quat)
    return rapier3d.Rotation3(w, x, y, z)


PLAIN_DEPTH = 3
ADDRESS = " at 0x"
"""What an object's default repr carries and a plain value never does: its memory address."""
"""How deep ``plain_fields`` follows nested settings objects (IntegrationParameters nests two)."""


def plain_fields(settings: object, depth: int = PLAIN_DEPTH) -> dict[str, object]:
    """A bindings object's public, non-callable attributes as plain values: numbers, text,
    booleans, values with their own text (an enum), other objects as dicts of theirs
    (``depth`` levels), anything deeper by its type's name. Deterministic: the same settings give the same dict in every process."""
    found: dict[str, object] = {}
    for name in dir(settings):
        if name.startswith("_"):
            continue
        value = getattr(settings, name)
        if callable(value):
            continue
        if value is None or isinstance(value, bool | int | float | str):
            found[name] = value
        elif ADDRESS not in str(value):  # an enum or a value with its own text
            found[name] = str(value)
        elif depth > 1:
            found[name] = plain_fields(value, depth - 1) or type(value).__name__
        else:
            found[name] = type(value).__name__
    return found


@dataclass(frozen=True)
class Settings:
    """The effective settings of one adapter: the profile's defaults, the spec's options on top."""

    profile: str
    gyroscopic: str
    ccd: str
    friction_model: str
    combine: str
    sleeping: bool
    prediction_distance: float | None
    solver_iterations: int | None
    joints: str

    @staticmethod
    def of(spec: EngineSpec) -> Settings:
        options = spec.as_dict()
        name = str(options.get("profile", "matched"))
        profile: Profile = PROFILES[name]
        iterations = options.get("solver_iterations")
        return Settings(
            profile=name,
            gyroscopic=str(options.get("gyroscopic", profile.gyroscopic)),
            ccd=str(options.get("ccd", profile.ccd)),
            friction_model=str(options.get("friction_model", profile.friction_model)),
            combine=profile.combine,
            sleeping=profile.sleeping,
            prediction_distance=profile.prediction_distance,
            solver_iterations=None if iterations is None else int(iterations),
            joints=str(options.get("joints", DEFAULT_JOINTS)),
        )


class PairHooks:
    """Rapier ``PhysicsHooks``: the scene's value for each ``pairs:`` override, set on the
    contact every step (``modify_solver_contacts``). ``values`` maps the two objects' indices
    (collider ``user_data``, scenario order, the ground last), smaller first, to (restitution,
    friction); any other pair keeps its combined values."""

    def __init__(self, values: dict[tuple[int, int], tuple[float, float]]):
        self.values = values

    def modify_solver_contacts(self, ctx) -> None:
        a = ctx.colliders[ctx.collider1].user_data
        b = ctx.colliders[ctx.collider2].user_data
        found = self.values.get((min(a, b), max(a, b)))
        if found is not None:
            ctx.restitution, ctx.friction = found


# --- the adapter ----------------------------------------------------------------------------


class RapierAdapter:
    """rapier3d as an ``EngineAdapter``: one ``PhysicsWorld`` per load.

    Attributes (after ``load``):
        world: the ``PhysicsWorld``.
        handles: (n,) ``RigidBodyHandle`` of the scene's bodies, scenario order.
        ground: the ground's body handle, or None.
    """

    precision = PRECISION
    """The engine's floating-point type (the parity gate's tolerance)."""

    def __init__(self, spec: EngineSpec):
        self.spec = spec
        self.settings = Settings.of(spec)
        self.world = None

    # -- loading ---------------------------------------------------------------------------

    def load(self, scene: CompiledScene) -> None:
        """Build the scene in a fresh world at its dt and gravity."""
        self.scene = scene
        self.scenario = scenario = scene.scenario
        self.steps_taken = 0
        self.notes: list[str] = []
        self.joint_builder: JointBuilder | None = None
        self.world = rapier3d.PhysicsWorld(gravity=tuple(float(g) for g in scenario.gravity))
        self.world.set_num_threads(WORKER_THREADS)
        self._set_integration(scenario)
        self.hook_pairs = self._pair_overrides(scenario)
        self.handles = [self._create_body(k, b) for k, b in enumerate(scenario.bodies)]
        self.ground = self._create_ground() if scenario.ground else None
        if self.hook_pairs:
            self.world.physics_hooks = PairHooks(self.hook_pairs)
        self._set_up_loads(scenario)
        if scene.joint_tree is not None:
            self._create_joints(scene)
        self._fixed_pose = (
            np.array([b.position for b in scenario.bodies], dtype=float),
            np.array([b.orientation for b in scenario.bodies], dtype=float),
        )

    def _set_integration(self, scenario: Scenario) -> None:
        parameters = self.world.integration_parameters
        parameters.dt = float(scenario.dt)
        parameters.friction_model = FRICTION_MODELS[self.settings.friction_model]
        if self.settings.prediction_distance is not None:
            parameters.normalized_prediction_distance = self.settings.prediction_distance
        if self.settings.solver_iterations is not None:
            parameters.num_solver_iterations = self.settings.solver_iterations

    def _pair_overrides(self, scenario: Scenario) -> dict[tuple[int, int], tuple[float, float]]:
        """(i, j) -> (restitution, friction) of each ``pairs:`` entry, matched profile only
        (the defaults profile keeps Rapier's combined per-body values, said in the notes)."""
        if not scenario.pairs:
            return {}
        if self.settings.combine != "scene":
            self.notes.append(
                f"profile=defaults: the scene's {len(scenario.pairs)} pairs: override(s) and "
                "its pair rules are not used; Rapier averages the two colliders' values"
            )
            return {}
        index = {b.name: k for k, b in enumerate(scenario.bodies)} | {GROUND: len(scenario.bodies)}
        values = {}
        for pair in scenario.pairs:
            i, j = sorted((index[pair.a], index[pair.b]))
            values[(i, j)] = (
                pair_value(scenario, pair.a, pair.b, "restitution"),
                pair_value(scenario, pair.a, pair.b, "friction"),
            )
        return values

    def _collider(self, builder, index: int, restitution: float, friction: float):
        """The shape's builder with the contact values, combine rules, index and hook flag; a
        body with ``collides: false`` in no interaction group (it meets nothing)."""
        builder = builder.restitution(float(restitution)).friction(float(friction))
        bodies = self.scenario.bodies
        if index < len(bodies) and not bodies[index].collides:
            builder = builder.collision_groups(rapier3d.InteractionGroups.none())
        if self.settings.combine == "scene":
            builder = builder.restitution_combine_rule(SCENE_COMBINE_RULES["restitution"])
            builder = builder.friction_combine_rule(SCENE_COMBINE_RULES["friction"])
        hooked = any(index in pair for pair in self.hook_pairs)
        if hooked:
            builder = builder.active_hooks(rapier3d.ActiveHooks.MODIFY_SOLVER_CONTACTS)
        return builder.user_data(index)

    def _create_body(self, index: int, spec: BodySpec):
        """One scene body: its pose is the scene's (origin at the centre of mass), its
        collider at the shape's place in it (``collider_place``); the centre of mass and the
        principal axes go into the collider's mass properties, which Rapier reads in the
        collider's frame: the body origin and the principal axes as seen from there (module
        docstring), so a placed shape leaves them where the scene states them."""
        pose = rapier3d.Isometry3(tuple(spec.position), rotation(spec.orientation))
        offset, axes = collider_place(spec.shape)
        builder = SHAPE_BUILDERS[spec.shape.type](spec.shape).position(
            rapier3d.Isometry3(tuple(offset), rotation(axes))
        )
        collider = self._collider(builder, index, spec.restitution, spec.friction)
        if spec.fixed:
            return self.world.add_body(rapier3d.RigidBody.fixed().position(pose), [collider])
        moments, q_principal = principal_axes(self._inertia(index))
        to_collider = quat_to_matrix(axes[None])[0].T
        mass_properties = rapier3d.MassProperties(
            local_com=tuple(float(c) for c in -(to_collider @ offset)),
            mass=float(spec.mass),
            principal_inertia=tuple(float(m) for m in moments),
            principal_inertia_local_frame=rotation(
                quat_multiply(axes * np.array([1.0, -1.0, -1.0, -1.0]), q_principal)
            ),
        )
        body = (
            rapier3d.RigidBody.dynamic()
            .position(pose)
            .linvel(tuple(spec.velocity))
            .angvel(tuple(spec.angular_velocity))
            .linear_damping(0.0)
            .angular_damping(0.0)
            .can_sleep(self.settings.sleeping)
            .ccd_enabled(SWITCH[self.settings.ccd])
            .gyroscopic_forces(SWITCH[self.settings.gyroscopic])
        )
        return self.world.add_body(body, [collider.mass_properties(mass_properties)])

    def _inertia(self, index: int) -> np.ndarray:
        """(3, 3) kg·m², body frame: the compiled scene's (the scene's own or the solid's)."""
        return np.asarray(self.scene.inertia[index], dtype=float)

    def _create_ground(self):
        """A fixed body at the one ground pose of ``physics.ground_pose`` carrying a halfspace
        whose outward normal is its +z."""
        point, quat = ground_pose(self.scenario.ground)
        ground = self.scenario.ground
        collider = self._collider(
            rapier3d.Collider.halfspace((0.0, 0.0, 1.0)),
            len(self.scenario.bodies),
            ground.restitution,
            ground.friction,
        )
        pose = rapier3d.Isometry3(tuple(float(p) for p in point), rotation(quat))
        return self.world.add_body(rapier3d.RigidBody.fixed().position(pose), [collider])

    def _create_joints(self, scene: CompiledScene) -> None:
        """The scene's joint tree as Rapier joints of the ``joints`` kind (multibody or
        impulse, ``validation.engines.rapier.joints``); the bodies keep their stated states."""
        scenario = scene.scenario
        self.joint_builder = JointBuilder(self.world, self.settings.joints)
        self.joint_builder.build(
            scene.joint_tree,
            self.handles,
            {j.name: j.limits for j in scenario.joints},
            (
                np.array([b.velocity for b in scenario.bodies], dtype=float),
                np.array([b.angular_velocity for b in scenario.bodies], dtype=float),
            ),
        )
        self.notes.append(
            f"joints: {len(scenario.joints)} Rapier {self.settings.joints} joint(s) "
            "(GenericJoint, frames placing each child at its stated pose, no contact between "
            "a joint's two bodies)"
        )

    def _set_up_loads(self, scenario: Scenario) -> None:
        """Constant loads are Rapier's persistent user force and torque (set once, kept over
        every step, engines-rapier.md 2); with springs, every loaded body's force and torque
        are set again before each step from the state at its start (explicit in time), by
        the reference's load law."""
        self.fixed = np.array([b.fixed for b in scenario.bodies])
        scene = self.scene
        ends = np.concatenate([scene.springs.body_a, scene.springs.body_b])
        constant = np.any(scene.force != 0.0, axis=1) | np.any(scene.torque != 0.0, axis=1)
        self.sprung = bool(scene.springs.body_a.size)
        self.loaded = ~self.fixed & (np.isin(np.arange(len(scenario.bodies)), ends) | constant)
        if self.sprung:
            self.notes.append(
                "springs: forces and torques set with add_force/add_torque (world frame, at the "
                "centre of mass) before every step from the state at its start (explicit in "
                "time, held over the step's substeps), by the reference's load law "
                "(validation.reference.loads.applied_loads)"
            )
        else:
            for k in np.flatnonzero(self.loaded):
                body = self.world.rigid_bodies[self.handles[k]]
                body.add_force(tuple(float(f) for f in scene.force[k]))
                body.add_torque(tuple(float(t) for t in scene.torque[k]))

    # -- stepping --------------------------------------------------------------------------

    def _apply_spring_loads(self) -> None:
        pos, quat, vel, ang_vel = self._split(self._raw_state()[None])
        scene = self.scene
        rot = quat_to_matrix(quat[0])
        force, torque = applied_loads(
            scene.springs, scene.moving, scene.force, scene.torque, pos[0], rot, vel[0], ang_vel[0]
        )
        for k in np.flatnonzero(self.loaded):
            body = self.world.rigid_bodies[self.handles[k]]
            body.reset_forces()
            body.reset_torques()
            body.add_force(tuple(float(f) for f in force[k]))
            body.add_torque(tuple(float(t) for t in torque[k]))

    def _step(self) -> None:
        if self.sprung:
            self._apply_spring_loads()
        self.world.step()
        self.steps_taken += 1

    def advance(self, steps: int) -> None:
        """``steps`` world steps of the scene's dt (springs set before each)."""
        for _ in range(steps):
            self._step()

    def advance_observed(self, steps: int) -> Trajectory:
        """``steps`` steps, the raw states read after each, converted in one pass at the end."""
        raw = np.empty((steps, len(self.handles), 13))
        for k in range(steps):
            self._step()
            raw[k] = self._raw_state()
        times = (self.steps_taken - steps + 1 + np.arange(steps)) * self.scenario.dt
        return self._states(times, raw)

    # -- reading back ----------------------------------------------------------------------

    def _raw_state(self) -> np.ndarray:
        """(n, 13): position, quaternion x y z w, velocity, world ω of every scene body; after
        a step, a multibody link's velocities from its multibody (``JointBuilder.
        link_velocities``: its rigid body's are one substep late). Before the first, every body
        carries its stated velocities, which the multibody's reproduce to float32 only."""
        bodies = self.world.rigid_bodies
        rows = []
        for handle in self.handles:
            body = bodies[handle]
            rows.append(
                (
                    *body.translation.to_tuple(),
                    *body.rotation.quaternion,
                    *body.linvel.to_tuple(),
                    *body.angvel.to_tuple(),
                )
            )
        raw = np.array(rows, dtype=float)
        if self.joint_builder is not None and self.steps_taken:
            for k, velocity in self.joint_builder.link_velocities(self.handles).items():
                raw[k, 7:13] = velocity
        return raw

    @staticmethod
    def _split(raw: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """Raw states (s, n, 13) -> pos, quat w x y z (normalised), vel, ang_vel (s, n, ...)."""
        quat = from_xyzw(raw[..., 3:7])
        quat = quat / np.linalg.norm(quat, axis=-1, keepdims=True)
        return raw[..., 0:3].copy(), quat, raw[..., 7:10].copy(), raw[..., 10:13].copy()

    def _states(self, times: np.ndarray, raw: np.ndarray) -> Trajectory:
        """The scene's conventions for ``raw (s, n, 13)``; fixed bodies keep the scene's pose
        exactly (Rapier holds it in float32), at rest."""
        pos, quat, vel, ang_vel = self._split(raw)
        pos[:, self.fixed] = self._fixed_pose[0][self.fixed]
        quat[:, self.fixed] = self._fixed_pose[1][self.fixed]
        vel[:, self.fixed] = 0.0
        ang_vel[:, self.fixed] = 0.0
        return Trajectory(np.asarray(times, dtype=float), pos, quat, vel, ang_vel)

    def observe(self) -> Snapshot:
        states = self._states(
            np.array([self.steps_taken * self.scenario.dt]), self._raw_state()[None]
        )
        return Snapshot(
            float(states.t[0]),
            *(a[0] for a in (states.pos, states.quat, states.vel, states.ang_vel)),
        )

    def joint_report(self) -> JointReport:
        """The joints Rapier holds, read back at t = 0 (``JointBuilder.report``): types from
        their locked axes, anchors and axes from their frames on the parent's pose, and for
        multibody joints M(q0) from Rapier's own Jacobians and masses."""
        return self.joint_builder.report(self.scene.joint_tree, self.scenario.joints, self.handles)

    def model_report(self) -> ModelReport:
        """The dynamic bodies as Rapier holds them: ``RigidBody.mass``, ``center_of_mass``
        (world), the principal inertia and its local frame rotated to world with the body's
        rotation, and the state; energy and momenta from those readbacks and the world's
        gravity, by the invariants of ``validation.scenario.compiled`` (springs and applied
        forces: the scene's laws)."""
        moving = dynamic_bodies(self.scene)
        bodies = self.world.rigid_bodies
        mass, com, inertia = [], [], []
        for k in moving:
            body = bodies[self.handles[k]]
            mass.append(float(body.mass))
            com.append(body.center_of_mass.to_tuple())
            inertia.append(world_inertia(body))
        mass_array = np.array(mass, dtype=float)
        inertia_array = np.array(inertia, dtype=float).reshape(-1, 3, 3)
        pos, quat, vel, ang_vel = self._split(self._raw_state()[None])
        gravity = np.array(self.world.gravity.to_tuple(), dtype=float)
        states = [a[:, moving] for a in (pos, vel, ang_vel)]
        energy = kinetic_energy(mass_array, inertia_array[None], states[1], states[2])
        energy += gravitational_energy(mass_array, states[0], gravity)
        energy += self.scene.spring_energy(pos, quat)
        energy += self.scene.applied_force_energy(pos)
        return ModelReport(
            mass=mass_array,
            com=np.array(com, dtype=float).reshape(-1, 3),
            inertia_world=inertia_array,
            energy=float(energy[0]),
            linear_momentum=linear_momentum(mass_array, states[1])[0],
            angular_momentum=angular_momentum(mass_array, inertia_array[None], *states)[0],
        )

    # -- provenance ------------------------------------------------------------------------

    def _integration_settings(self) -> dict[str, object]:
        """Every plain field of the world's ``IntegrationParameters``, nested settings objects
        (``soft_bodies``, ``contact_softness``) as their own plain fields: never an object's
        repr, whose memory address would differ between two runs of one scene."""
        return plain_fields(self.world.integration_parameters)

    def provenance(self) -> Provenance:
        """rapier3d's version, every integration parameter, the profile and what it set."""
        s = self.settings
        settings: dict[str, object] = {
            **{f"spec.{k}": v for k, v in self.spec.as_dict().items()},
            "profile": s.profile,
            "precision": PRECISION,
            "integration_parameters": self._integration_settings(),
            "gyroscopic_forces": SWITCH[s.gyroscopic],
            "ccd_enabled": SWITCH[s.ccd],
            "friction_model": s.friction_model,
            "can_sleep": s.sleeping,
            "prediction_distance": (
                s.prediction_distance if s.prediction_distance is not None else "Rapier default"
            ),
            "combine_rules": (
                {"restitution": "MAX", "friction": "GEOMETRIC_MEAN"}
                if s.combine == "scene"
                else {"restitution": RAPIER_COMBINE_RULE, "friction": RAPIER_COMBINE_RULE}
            ),
            "pair_overrides_by_hook": [list(pair) for pair in sorted(self.hook_pairs)],
            "damping": {"linear": 0.0, "angular": 0.0},
            "worker_threads": WORKER_THREADS,
            "build_features": str(rapier3d.build_features()),
        }
        if self.scene.joint_tree is not None:
            settings["joints"] = s.joints
        dt = self.world.integration_parameters.dt
        notes = [
            f"float32 engine: Rapier stores every state, mass and dt in 32-bit floats "
            f"(epsilon 1.19e-7; dt {self.scenario.dt:g} s is held as {dt:.10g} s): rows whose "
            "error is near float32 resolution of their quantity measure the precision, not the "
            "physics",
            *self.notes,
        ]
        return Provenance(
            engine="rapier",
            version=importlib.metadata.version("rapier3d"),
            settings=settings,
            notes=notes,
        )

    def close(self) -> None:
        """Drop the world (Rapier frees it with the Python object); idempotent."""
        self.world = None
