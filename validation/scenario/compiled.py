"""The scene compiled once: what every engine, measurement and check derives from a scenario.

``compile_scene(scenario)`` is called once per scenario (in planning) and the result is passed
down: the parity reference, every adapter, the recording, the stability checks and the
metrics read the shapes, the invariants and the scales from here instead of deriving them
again. Physics formulas of the invariants are defined once, below, as functions of
arrays (so an adapter can apply them to what its engine reads back). The invariants take
their inertias, rotations and spring energy from the reference side (``validation.reference``),
so a mistake in mini_engine's formulas cannot move what the engines are judged against; the
contacts of observed states come from the reference side's own finder
(``validation.reference.contacts``), never from an engine's narrow phase. Nothing here imports
mini_engine: its adapter builds its own model (``validation.engines.mini.model``).

It lives in ``scenario/`` rather than ``measure/`` because the engine adapters (one layer
below the measurements) consume it too.

Array conventions: ``s`` states (observations), ``n`` scene bodies in scenario order (the
ground is never one of them); positions are centres of mass, world frame; quaternions
w x y z; velocities world frame.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from functools import cached_property

import numpy as np

from validation.reference import contacts, rotation
from validation.reference.articulated import JointTree
from validation.reference.loads import Springs, spring_energy
from validation.reference.motion import Motion
from validation.scenario.joints import joint_tree
from validation.scenario.physics import (
    GROUND,
    body_inertia,
    pair_value,
    scene_poses,
    scene_shapes,
    scene_springs,
)
from validation.scenario.schema import Scenario
from validation.scenario.urdf import ModelLayout, model_layouts

# --- the invariants, one definition each -------------------------------------------------


def rotations(quat: np.ndarray) -> np.ndarray:
    """(..., 3, 3) body-to-world rotations of unit quaternions ``quat (..., 4)`` w x y z (the
    reference's ``rotation.quat_to_matrix``)."""
    return rotation.quat_to_matrix(np.asarray(quat, dtype=float))


def kinetic_energy(
    mass: np.ndarray, inertia_world: np.ndarray, vel: np.ndarray, ang_vel: np.ndarray
) -> np.ndarray:
    """(s,) J, ``Σ ½ m |v|² + ½ ωᵀ I_world ω`` for ``mass (n,)`` kg (0 for a fixed body),
    ``inertia_world (s, n, 3, 3)`` kg·m², ``vel``, ``ang_vel (s, n, 3)``; fixed bodies must
    have zero velocities or zero mass (their rotation term is weighted by ``mass > 0``)."""
    moving = (mass > 0).astype(float)
    spin = np.einsum("snij,snj->sni", inertia_world, ang_vel)
    translation = 0.5 * np.einsum("n,sni,sni->s", mass, vel, vel)
    return translation + 0.5 * np.einsum("sni,sni,n->s", ang_vel, spin, moving)


def gravitational_energy(mass: np.ndarray, pos: np.ndarray, gravity: np.ndarray) -> np.ndarray:
    """(s,) J, ``Σ -m g·x`` (zero at the origin) for ``mass (n,)``, ``pos (s, n, 3)``."""
    return -np.einsum("n,sni,i->s", mass, pos, gravity)


def applied_force_energy(force: np.ndarray, pos: np.ndarray) -> np.ndarray:
    """(s,) J, ``Σ -F·x`` (zero at the origin), the potential of constant applied forces
    ``force (n, 3)`` N at the centres of mass ``pos (s, n, 3)``: like gravity, a constant force
    is conservative."""
    return -np.einsum("ni,sni->s", force, pos)


def linear_momentum(mass: np.ndarray, vel: np.ndarray) -> np.ndarray:
    """(s, 3) kg·m/s, ``Σ m v``."""
    return np.einsum("n,sni->si", mass, vel)


def centre_of_mass(mass: np.ndarray, pos: np.ndarray) -> np.ndarray:
    """(s, 3) m, of the bodies with mass (the origin when none has)."""
    total = float(mass.sum())
    if total <= 0.0:
        return np.zeros((pos.shape[0], 3))
    return np.einsum("n,sni->si", mass, pos) / total


def angular_momentum(
    mass: np.ndarray,
    inertia_world: np.ndarray,
    pos: np.ndarray,
    vel: np.ndarray,
    ang_vel: np.ndarray,
) -> np.ndarray:
    """(s, 3) kg·m²/s about the system's centre of mass: ``Σ (x - c) × m v + I_world ω``."""
    moving = (mass > 0).astype(float)
    arm = pos - centre_of_mass(mass, pos)[:, None, :]
    orbital = np.einsum("n,sni->si", mass, rotation.cross(arm, vel))
    spin = np.einsum("snij,snj,n->si", inertia_world, ang_vel, moving)
    return orbital + spin


def world_inertia(inertia: np.ndarray, rot: np.ndarray) -> np.ndarray:
    """(s, n, 3, 3) ``R I Rᵀ`` from body-frame ``inertia (n, 3, 3)`` and ``rot (s, n, 3, 3)``."""
    return rot @ inertia[None] @ rot.swapaxes(-1, -2)


# --- the compiled scene ------------------------------------------------------------------


@dataclass(eq=False)
class CompiledScene:
    """A scenario and everything derived from it once.

    Attributes:
        scenario: the validated scene.
        shapes: the collision shapes (``physics.scene_shapes``: scene bodies first, in
            scenario order, then the ground plane). shape_count: N, n plus the ground.
        body_name: (N,) names, the ground's ``GROUND``. rest_pos, rest_quat: (N, 3) m, (N, 4)
            the shapes at t = 0 (the ground's pose is its pose throughout).
        count: n, the scene's bodies. moving: (n,) bool, not fixed.
        mass: (n,) kg, 0 for fixed bodies. inertia: (n, 3, 3) kg·m², body frame: the
            scene's, or the reference's solid shape (``physics.body_inertia``).
        gravity: (3,) m/s². can_touch: whether any two bodies can meet.
        force: (n, 3) N, torque: (n, 3) N·m, world frame: each body's constant applied load
            (0 for fixed bodies). acceleration: (n, 3) m/s², what acts on each centre of mass
            besides contacts and springs: g + F/m (0 for fixed bodies).
        external_loads: a ground, fixed body, world spring or world joint can push the moving bodies (then
            momentum is not conserved).
        springs: the scene's springs as the reference evaluates them (``physics.scene_springs``).
        start: the scene's bodies at t = 0 as the scene states them (one state; fixed bodies
            at rest), what the reference starts from.
        bound_radius: (N,) m, each shape's bounding radius (``contacts.Shapes``).
        energy_floor: J, the smallest scale energy changes are judged against (the stability
            checks): total moving mass times (1 + |g|).
        speed_scale: m/s, initial speeds, spin times size, free fall over the run and what
            the springs can release, plus 1.
    """

    scenario: Scenario
    shapes: contacts.Shapes
    body_name: list[str]
    rest_pos: np.ndarray
    rest_quat: np.ndarray
    count: int
    moving: np.ndarray
    mass: np.ndarray
    inertia: np.ndarray
    gravity: np.ndarray
    force: np.ndarray
    torque: np.ndarray
    acceleration: np.ndarray
    can_touch: bool
    external_loads: bool
    springs: Springs
    start: Motion
    bound_radius: np.ndarray
    energy_floor: float = 0.0
    speed_scale: float = 0.0
    _last_inertia: dict = field(default_factory=dict, repr=False)

    @cached_property
    def joint_tree(self) -> JointTree | None:
        """The scene's joints as one tree (``validation.scenario.joints.joint_tree``), or None
        without joints: built once, the structure every engine adapter and the reference side
        read (each joint placed in its parent's frame)."""
        return joint_tree(self.scenario)

    @cached_property
    def models(self) -> tuple[ModelLayout, ...]:
        """Each of the scene's ``models`` as its file maps onto the scene's bodies and joints
        (``validation.scenario.urdf.ModelLayout``): empty without models. What a native loader
        reads; the bodies and joints themselves are already in the scenario."""
        return model_layouts(self.scenario) if self.scenario.models else ()

    @cached_property
    def model_names(self) -> dict[str, ModelLayout]:
        """Every body and joint name a model's expansion gave -> its model (what a native
        loader builds itself, and leaves out of the scene it writes)."""
        return {name: layout for layout in self.models for name in (*layout.bodies, *layout.joints)}

    def model_of(self, body: str) -> ModelLayout | None:
        """The model whose expansion gave the body (or joint) named ``body``, or None."""
        return self.model_names.get(body)

    def __getstate__(self) -> dict:
        """Pickled for worker processes without the inertia cache (rebuilt on demand), with
        the model layouts read here (they carry the command's ``--package-path`` flags, which
        a worker of another process, Dask's, never saw)."""
        _ = self.models
        return {**self.__dict__, "_last_inertia": {}}

    @property
    def name(self) -> str:
        return self.scenario.name or ""

    # -- invariants of observed states (s, n, ...) --

    def inertia_world(self, quat) -> np.ndarray:
        """(s, n, 3, 3) kg·m², world frame: ``R I Rᵀ`` at the orientations ``quat (s, n, 4)``,
        read-only. The last call's while ``quat`` has its bytes: a recorded block's energy,
        kinetic energy, angular momentum and stability check read the same states, and on a
        1,000-body pile the 3x3 products are a tenth of a job (the same numbers)."""
        quat = np.asarray(quat, dtype=float)
        key = (quat.shape, quat.tobytes())
        if self._last_inertia.get("key") != key:
            inertia = world_inertia(self.inertia, rotations(quat))
            inertia.flags.writeable = False
            self._last_inertia.update(key=key, inertia=inertia)
        return self._last_inertia["inertia"]

    def kinetic_energy(self, quat, vel, ang_vel) -> np.ndarray:
        """(s,) J."""
        return kinetic_energy(self.mass, self.inertia_world(quat), vel, ang_vel)

    def gravitational_energy(self, pos) -> np.ndarray:
        """(s,) J."""
        return gravitational_energy(self.mass, pos, self.gravity)

    def applied_force_energy(self, pos) -> np.ndarray:
        """(s,) J, the potential of the constant applied forces, ``Σ -F·x``."""
        return applied_force_energy(self.force, pos)

    @property
    def applies_torque(self) -> bool:
        """Whether a constant torque acts: it does work with no potential (a world-fixed torque
        on a rotating body is not conservative), so energy is not an invariant then."""
        return bool(np.any(self.torque != 0.0))

    @property
    def uniform_acceleration(self) -> bool:
        """Whether every moving body's free acceleration g + F/m is the same vector (always
        without applied forces): then those forces exert no torque about the system's centre
        of mass, and dL/dt is the sum of the applied torques."""
        moving = self.acceleration[self.moving]
        return bool(moving.size == 0 or np.allclose(moving, moving[0], rtol=1e-12, atol=0.0))

    def spring_energy(self, pos, quat) -> np.ndarray:
        """(s,) J stored in the springs, ``Σ ½ k (L - rest)²`` (the reference's
        ``loads.spring_energy``) at ``pos (s, n, 3)``, ``quat (s, n, 4)``."""
        if self.springs.count == 0:
            return np.zeros(pos.shape[0])
        return spring_energy(self.springs, np.asarray(pos), rotations(quat))

    def energy(self, pos, quat, vel, ang_vel) -> np.ndarray:
        """(s,) J, kinetic + gravitational + spring + applied-force potential."""
        energy = self.kinetic_energy(quat, vel, ang_vel) + self.gravitational_energy(pos)
        energy += self.spring_energy(pos, quat)
        if np.any(self.force):
            energy += self.applied_force_energy(pos)
        return energy

    def linear_momentum(self, vel) -> np.ndarray:
        """(s, 3) kg·m/s."""
        return linear_momentum(self.mass, vel)

    def angular_momentum(self, pos, quat, vel, ang_vel) -> np.ndarray:
        """(s, 3) kg·m²/s about the system's centre of mass."""
        return angular_momentum(self.mass, self.inertia_world(quat), pos, vel, ang_vel)

    def centre_of_mass(self, pos) -> np.ndarray:
        """(s, 3) m, of the moving bodies."""
        return centre_of_mass(self.mass, pos)

    def pair_value(self, a: str, b: str, quantity: str) -> float:
        """The scene's restitution or friction of bodies ``a`` and ``b`` (or "ground")."""
        return pair_value(self.scenario, a, b, quantity)

    # -- contacts of observed states, batched --

    @property
    def shape_count(self) -> int:
        """N: the scene's bodies and the ground."""
        return int(self.shapes.kind.size)

    def contacts(self, pos: np.ndarray, quat: np.ndarray, margin: float) -> contacts.Found:
        """The deepest contact (depth >= -margin) of every touching pair of the ``s`` observed
        states ``pos (s, n, 3)``, ``quat (s, n, 4)``, the ground at its own pose: the
        reference side's finder (``contacts.find_contacts``), all states in one call; shape
        indices are the scene's bodies 0..n-1, then the ground n."""
        samples = pos.shape[0]
        ground = self.shape_count - self.count
        full_pos = np.concatenate(
            [pos, np.broadcast_to(self.rest_pos[self.count :], (samples, ground, 3))], axis=1
        )
        full_rot = np.concatenate(
            [
                rotations(quat),
                rotations(np.broadcast_to(self.rest_quat[self.count :], (samples, ground, 4))),
            ],
            axis=1,
        )
        return contacts.find_contacts(self.shapes, full_pos, full_rot, margin)


def _spin_up(scene: CompiledScene) -> np.ndarray:
    """(n,) rad/s, the spin each applied torque can add over the run: |τ|·T / I_min."""
    smallest = np.linalg.eigvalsh(scene.inertia)[:, 0] if scene.count else np.zeros(0)
    return np.linalg.norm(scene.torque, axis=1) * scene.scenario.duration / smallest


def _speed_scale(scene: CompiledScene, stored_energy: float) -> float:
    """m/s: 1 + the fastest initial speed + the fastest spin (initial plus what applied torques
    add) times its body's size + the speed the free acceleration g + F/m gives over the run +
    the speed the springs' stored energy could give the lightest moving body."""
    scenario, mass = scene.scenario, scene.mass
    bodies = scenario.bodies
    radius = scene.bound_radius[: scene.count]
    speed = max(float(np.linalg.norm(b.velocity)) for b in bodies)
    initial_spin = np.array([np.linalg.norm(b.angular_velocity) for b in bodies])
    spin = float(np.max((initial_spin + _spin_up(scene)) * radius))
    fall = float(np.linalg.norm(scene.acceleration, axis=1).max()) * scenario.duration
    lightest = float(mass[mass > 0].min(initial=math.inf))
    release = math.sqrt(2.0 * max(stored_energy, 0.0) / max(lightest, 1e-300))
    return 1.0 + speed + spin + fall + release


def _energy_floor(scene: CompiledScene) -> float:
    """J: total moving mass times (1 + |g|), plus the work the applied loads can do over the
    run (|F| times the distance the speed scale allows, |τ| times the angle its spin allows)."""
    duration = scene.scenario.duration
    spin = np.array([np.linalg.norm(b.angular_velocity) for b in scene.scenario.bodies])
    force_work = np.linalg.norm(scene.force, axis=1).sum() * scene.speed_scale * duration
    torque_work = np.sum(np.linalg.norm(scene.torque, axis=1) * (spin + _spin_up(scene)))
    weight = float(scene.mass.sum()) * (1.0 + float(np.linalg.norm(scene.gravity)))
    return weight + float(force_work + torque_work * duration)


def scene_start(scenario: Scenario) -> Motion:
    """The scene's bodies at t = 0 as the scene states them: one state (t = 0) of every body's
    position, orientation, velocity and angular velocity, fixed bodies at rest."""
    bodies = scenario.bodies
    moving = np.array([not b.fixed for b in bodies])[:, None]

    def column(field: str, size: int) -> np.ndarray:
        return np.array([getattr(b, field) for b in bodies], dtype=float).reshape(1, -1, size)

    return Motion(
        t=np.zeros(1),
        pos=column("position", 3),
        quat=column("orientation", 4),
        vel=np.where(moving, column("velocity", 3), 0.0),
        ang_vel=np.where(moving, column("angular_velocity", 3), 0.0),
    )


def compile_scene(scenario: Scenario) -> CompiledScene:
    """The scene's shapes, invariants and scales, built once."""
    shapes = scene_shapes(scenario)
    rest_pos, rest_quat = scene_poses(scenario)
    moving = np.array([not b.fixed for b in scenario.bodies])
    mass = np.where(moving, [b.mass for b in scenario.bodies], 0.0)
    world_springs = any(s.b == "world" for s in scenario.springs)
    world_joints = any(j.parent == "world" for j in scenario.joints)
    force = np.where(moving[:, None], [b.force for b in scenario.bodies], 0.0).reshape(-1, 3)
    torque = np.where(moving[:, None], [b.torque for b in scenario.bodies], 0.0).reshape(-1, 3)
    gravity = np.asarray(scenario.gravity, dtype=float)
    safe_mass = np.where(moving, mass, 1.0)
    scene = CompiledScene(
        scenario=scenario,
        shapes=shapes,
        body_name=[b.name for b in scenario.bodies] + [GROUND] * (scenario.ground is not None),
        rest_pos=rest_pos,
        rest_quat=rest_quat,
        count=len(scenario.bodies),
        moving=moving,
        mass=mass,
        inertia=np.array([body_inertia(b) for b in scenario.bodies]).reshape(-1, 3, 3),
        gravity=gravity,
        force=force,
        torque=torque,
        acceleration=np.where(moving[:, None], gravity + force / safe_mass[:, None], 0.0),
        can_touch=shapes.can_touch,
        external_loads=scenario.ground is not None
        or not moving.all()
        or world_springs
        or world_joints,
        springs=scene_springs(scenario),
        start=scene_start(scenario),
        bound_radius=shapes.bound_radius,
    )
    start = scene.start
    scene.speed_scale = _speed_scale(scene, float(scene.spring_energy(start.pos, start.quat)[0]))
    scene.energy_floor = _energy_floor(scene)
    return scene
