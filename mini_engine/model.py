"""The static ``Model`` (what the scene is) and the dynamic ``State`` (where it is now).

Both are structures of arrays, one row per body, named ``<object>_<property>``
(``body_mass``, ``spring_stiffness``) as in MuJoCo/MJX. The model never changes
during a run; ``step`` maps one ``State`` to the next.

Worlds: every body carries a *world index*. Bodies of different worlds never
touch and never share a spring, so independent copies of one scene (an
ensemble, a dt sweep) live in one model and advance in one vectorized step.
World ``SHARED_WORLD`` (-1) is for static bodies seen by every world, such as
one ground plane under all copies.
"""

from __future__ import annotations

import dataclasses
import functools
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from functools import cached_property
from typing import TypeVar

import numpy as np

from mini_engine.joints import Joint, JointModel, build_joints
from mini_engine.shapes import Plane, Shape, solid_inertia

SHARED_WORLD = -1
"""World index of a static body that every world sees (for example one ground plane)."""

WORLD_ANCHOR = -1
"""``spring_body_b`` value of a spring whose second end is fixed in the world frame."""

ISOTROPY_TOLERANCE = 1e-12
"""Relative spread of the principal moments below which a body counts as isotropic
(ω × Iω = 0 exactly, so the gyroscopic phase skips it); round-off level."""

SYMMETRY_TOLERANCE = 1e-9
"""Relative asymmetry of an explicit inertia accepted as round-off (then symmetrised); the
scenario format uses the same value."""

UNIT_QUATERNION_TOLERANCE = 1e-6
"""An orientation whose norm is within this of 1 is normalised; further away it is an
error (a typo, not round-off). The scenario format uses the same rule."""

PER_MODEL_PREFIX = "_per_model_"
"""Prefix of the ``Model.__dict__`` keys where ``per_model`` keeps what it derived."""


@dataclass(frozen=True)
class Body:
    """One rigid body as a user describes it (the input of ``build_model``).

    Attributes:
        shape: a ``Sphere``, ``Box``, ``Capsule`` or ``Plane`` (planes must be fixed).
        mass: kg, > 0.
        inertia: optional body-frame inertia about the centre of mass, kg·m²: three
            principal moments (diagonal) or a full symmetric 3x3; default: the solid shape.
        position: (3,) m, world frame, centre of mass.
        orientation: (4,) unit quaternion w x y z, body to world.
        velocity: (3,) m/s, world frame, centre of mass.
        angular_velocity: (3,) rad/s, world frame.
        force: (3,) N, world frame, a constant applied force at the centre of mass.
        torque: (3,) N·m, world frame, a constant applied torque.
        restitution: coefficient of restitution e in [0, 1].
        friction: Coulomb coefficient μ >= 0; 0 is frictionless, as documented.
        fixed: a static body (infinite mass, never moves; its loads are ignored).
        world: world index (``SHARED_WORLD`` for a static body seen by every world).
        collides: False removes the body from collision detection entirely.
        name: label for reports.
    """

    shape: Shape
    mass: float = 1.0
    inertia: Sequence[float] | Sequence[Sequence[float]] | np.ndarray | None = None
    position: Sequence[float] = (0.0, 0.0, 0.0)
    orientation: Sequence[float] = (1.0, 0.0, 0.0, 0.0)
    velocity: Sequence[float] = (0.0, 0.0, 0.0)
    angular_velocity: Sequence[float] = (0.0, 0.0, 0.0)
    force: Sequence[float] = (0.0, 0.0, 0.0)
    torque: Sequence[float] = (0.0, 0.0, 0.0)
    restitution: float = 0.0
    friction: float = 0.0
    fixed: bool = False
    world: int = 0
    collides: bool = True
    name: str = ""


@dataclass(frozen=True)
class Spring:
    """A linear spring-damper between body anchors (the input of ``build_model``).

    Force on B along the unit axis u from anchor A to anchor B (length L):
    ``F_B = -(k (L - rest_length) + c (v_anchorB - v_anchorA)·u) u``, and ``F_A = -F_B``.

    Attributes:
        body_a: body index.
        body_b: body index, or ``None`` for a point fixed in the world.
        anchor_a: (3,) m, in body A's frame, relative to its centre of mass.
        anchor_b: (3,) m, in body B's frame, or a world point when ``body_b`` is None.
        stiffness: k, N/m, >= 0.
        damping: c, N·s/m, >= 0.
        rest_length: m, >= 0.
    """

    body_a: int
    body_b: int | None
    anchor_a: Sequence[float] = (0.0, 0.0, 0.0)
    anchor_b: Sequence[float] = (0.0, 0.0, 0.0)
    stiffness: float = 0.0
    damping: float = 0.0
    rest_length: float = 0.0


@dataclass(frozen=True)
class PairProperties:
    """Contact values for one pair of bodies that replace the mixing rules.

    ``None`` keeps the rule (``Settings.restitution_mix`` / ``friction_mix``) for that value.
    """

    body_a: int
    body_b: int
    restitution: float | None = None
    friction: float | None = None


@dataclass(frozen=True, eq=False)
class Model:
    """Static description of a scene: bodies, springs, gravity. Arrays are read-only.

    Body arrays (n bodies):
        body_name: (n,) str labels.
        body_mass: (n,) kg. body_inv_mass: (n,) 1/kg, 0 for fixed bodies.
        body_inertia: (n, 3, 3) kg·m², body frame, about the centre of mass.
        body_inv_inertia: (n, 3, 3) 1/(kg·m²), body frame; 0 for fixed bodies.
        body_isotropic: (n,) bool, inertia proportional to identity (no gyroscopic term).
        body_shape: (n,) int ``ShapeType``. body_size: (n, 3) m, see ``shapes``.
        body_bound_radius: (n,) m, radius of a sphere around the centre enclosing
            the shape (inf for planes).
        body_restitution: (n,) e in [0, 1]. body_friction: (n,) μ >= 0.
        body_force: (n, 3) N, world frame, constant applied force at the centre of mass
            (0 for fixed bodies). body_torque: (n, 3) N·m, world frame, constant applied torque.
        body_fixed: (n,) bool. body_collides: (n,) bool.
        body_world: (n,) int world index (``SHARED_WORLD`` = every world).

    Spring arrays (s springs):
        spring_body_a, spring_body_b: (s,) int (``WORLD_ANCHOR`` for a world point).
        spring_anchor_a, spring_anchor_b: (s, 3) m, body frames (world for world points).
        spring_stiffness: (s,) N/m. spring_damping: (s,) N·s/m. spring_rest_length: (s,) m.

    Pair overrides (p pairs):
        pair_body_a, pair_body_b: (p,) int. pair_restitution, pair_friction: (p,), NaN = use the rule.

    gravity: (3,) m/s², world frame.
    joints: the ``JointModel`` of the scene's joints (``mini_engine.joints``), or None.
    """

    body_name: tuple[str, ...]
    body_mass: np.ndarray
    body_inv_mass: np.ndarray
    body_inertia: np.ndarray
    body_inv_inertia: np.ndarray
    body_isotropic: np.ndarray
    body_shape: np.ndarray
    body_size: np.ndarray
    body_bound_radius: np.ndarray
    body_restitution: np.ndarray
    body_friction: np.ndarray
    body_force: np.ndarray
    body_torque: np.ndarray
    body_fixed: np.ndarray
    body_collides: np.ndarray
    body_world: np.ndarray
    spring_body_a: np.ndarray
    spring_body_b: np.ndarray
    spring_anchor_a: np.ndarray
    spring_anchor_b: np.ndarray
    spring_stiffness: np.ndarray
    spring_damping: np.ndarray
    spring_rest_length: np.ndarray
    pair_body_a: np.ndarray
    pair_body_b: np.ndarray
    pair_restitution: np.ndarray
    pair_friction: np.ndarray
    gravity: np.ndarray = field(default_factory=lambda: np.array([0.0, 0.0, -9.81]))
    joints: JointModel | None = None

    def __post_init__(self) -> None:
        for value in self.__dict__.values():
            if isinstance(value, np.ndarray):
                value.flags.writeable = False

    def __getstate__(self) -> dict:
        """Pickle the model's fields only: what ``per_model`` derived is rebuilt on first use."""
        return {k: v for k, v in self.__dict__.items() if not k.startswith(PER_MODEL_PREFIX)}

    def forget_derived(self) -> None:
        """Drop everything ``per_model`` derived (the workspace, the broad-phase plan and
        every cache they hold): the next step rebuilds it from the fields, as for a new model."""
        for key in [k for k in self.__dict__ if k.startswith(PER_MODEL_PREFIX)]:
            del self.__dict__[key]

    @property
    def n_bodies(self) -> int:
        return len(self.body_name)

    @property
    def n_springs(self) -> int:
        return int(self.spring_body_a.shape[0])

    @cached_property
    def n_worlds(self) -> int:
        own = self.body_world[self.body_world != SHARED_WORLD]
        return int(own.max()) + 1 if own.size else 1

    @cached_property
    def body_dynamic(self) -> np.ndarray:
        """(n,) bool, bodies that move (not fixed)."""
        return ~self.body_fixed

    @cached_property
    def gyroscopic_bodies(self) -> np.ndarray:
        """(g,) int, dynamic bodies with anisotropic inertia: the only ones with ω × Iω ≠ 0."""
        return np.flatnonzero(self.body_dynamic & ~self.body_isotropic)

    @cached_property
    def can_touch(self) -> bool:
        """Whether any two collidable bodies, not both fixed, share a world.

        When False the step skips collision detection and the contact solver entirely.
        """
        collidable = self.body_collides
        dynamic_worlds = self.body_world[collidable & self.body_dynamic]
        if dynamic_worlds.size == 0:
            return False
        shared_static = np.any(collidable & self.body_fixed & (self.body_world == SHARED_WORLD))
        if shared_static:
            return True
        all_worlds = self.body_world[collidable]
        counts = np.bincount(all_worlds[all_worlds >= 0], minlength=self.n_worlds)
        return bool(np.any(counts[np.unique(dynamic_worlds)] >= 2))

    def body_index(self, name: str) -> int:
        return self.body_name.index(name)


@dataclass(frozen=True, eq=False)
class State:
    """Dynamic state of every body at one instant.

    Attributes:
        pos: (n, 3) m, world frame, centre of mass.
        quat: (n, 4) unit quaternion w x y z, body to world.
        vel: (n, 3) m/s, world frame, velocity of the centre of mass.
        ang_vel: (n, 3) rad/s, world frame.
        time: s since the start of the run.
        contact_memory: the last step's ``ContactReport`` (solver warm start), or None.
    """

    pos: np.ndarray
    quat: np.ndarray
    vel: np.ndarray
    ang_vel: np.ndarray
    time: float = 0.0
    contact_memory: object | None = None

    def copy(self) -> State:
        return State(
            self.pos.copy(),
            self.quat.copy(),
            self.vel.copy(),
            self.ang_vel.copy(),
            self.time,
            self.contact_memory,
        )

    def is_finite(self) -> bool:
        return bool(
            np.isfinite(self.pos).all()
            and np.isfinite(self.quat).all()
            and np.isfinite(self.vel).all()
            and np.isfinite(self.ang_vel).all()
        )


Derived = TypeVar("Derived")


def per_model(build: Callable[[Model], Derived]) -> Callable[[Model], Derived]:
    """Decorator: ``build(model)`` runs once per ``Model`` object and its result is kept
    while the model lives (a model never changes, so nothing derived from it goes stale).

    The result is kept in the model's own ``__dict__`` (as ``functools.cached_property``
    does): a dict look-up, several times cheaper per step than a ``WeakKeyDictionary``."""
    slot = f"{PER_MODEL_PREFIX}{build.__module__}.{build.__qualname__}"

    @functools.wraps(build)
    def cached(model: Model) -> Derived:
        found = model.__dict__.get(slot)
        if found is None:
            found = model.__dict__[slot] = build(model)
        return found

    return cached


def _vector(values: Sequence[float] | np.ndarray, length: int, what: str) -> np.ndarray:
    array = np.asarray(values, dtype=float)
    if array.shape != (length,) or not np.isfinite(array).all():
        raise ValueError(f"{what}: expected {length} finite numbers; got {values!r}")
    return array


def _rows_of(bodies: Sequence[Body], labels: list[str], name: str, length: int) -> np.ndarray:
    """(n, length) array of the vector field ``name`` of every body, validated."""
    rows = [
        _vector(getattr(b, name), length, f"{lab}.{name}")
        for b, lab in zip(bodies, labels, strict=True)
    ]
    return np.array(rows, dtype=float).reshape(len(bodies), length)


def _body_inertia(body: Body, label: str) -> np.ndarray:
    """Body-frame inertia (3, 3) of ``body``: the explicit one if given, else the solid shape's."""
    if body.inertia is None:
        return solid_inertia(body.shape, body.mass)
    inertia = np.asarray(body.inertia, dtype=float)
    if inertia.shape == (3,):
        inertia = np.diag(inertia)
    if inertia.shape != (3, 3) or not np.isfinite(inertia).all():
        raise ValueError(
            f"{label}.inertia: expected 3 moments or a 3x3 matrix; got {body.inertia!r}"
        )
    if not np.allclose(
        inertia, inertia.T, rtol=0.0, atol=SYMMETRY_TOLERANCE * np.abs(inertia).max()
    ):
        raise ValueError(f"{label}.inertia: expected a symmetric matrix; got {inertia.tolist()}")
    inertia = 0.5 * (inertia + inertia.T)
    if np.linalg.eigvalsh(inertia).min() <= 0.0:
        raise ValueError(f"{label}.inertia: expected positive definite; got {inertia.tolist()}")
    return inertia


def _unit_quaternion(values: Sequence[float], label: str) -> np.ndarray:
    quat = _vector(values, 4, f"{label}.orientation")
    norm = np.linalg.norm(quat)
    if abs(norm - 1.0) > UNIT_QUATERNION_TOLERANCE:
        raise ValueError(f"{label}.orientation: expected a unit quaternion; got norm {norm:.9g}")
    return quat / norm


def build_model(
    bodies: Sequence[Body],
    springs: Sequence[Spring] = (),
    gravity: Sequence[float] = (0.0, 0.0, -9.81),
    pairs: Sequence[PairProperties] = (),
    joints: Sequence[Joint] = (),
) -> tuple[Model, State]:
    """The ``Model`` and initial ``State`` of a scene made of ``bodies`` and ``springs``.

    Raises ``ValueError`` naming the body and field for impossible input (non-positive
    mass, a moving plane, a non-unit quaternion, a non-SPD inertia, a bad spring index).
    """
    n = len(bodies)
    labels = [b.name or f"bodies[{i}]" for i, b in enumerate(bodies)]
    for body, label in zip(bodies, labels, strict=True):
        if not (np.isfinite(body.mass) and body.mass > 0.0):
            raise ValueError(f"{label}.mass: expected a finite number > 0; got {body.mass!r}")
        if isinstance(body.shape, Plane) and not body.fixed:
            raise ValueError(
                f"{label}.fixed: expected true for a plane (planes are infinite and static)"
            )
        if body.world == SHARED_WORLD and not body.fixed:
            raise ValueError(f"{label}.world: only fixed bodies may be shared by every world")

    fixed = np.array([b.fixed for b in bodies], dtype=bool)
    mass = np.array([b.mass for b in bodies], dtype=float)
    inertia = np.array([_body_inertia(b, lab) for b, lab in zip(bodies, labels, strict=True)])
    inertia = inertia.reshape(n, 3, 3)
    inv_inertia = np.zeros_like(inertia)
    inv_inertia[~fixed] = np.linalg.inv(inertia[~fixed])
    moments = np.linalg.eigvalsh(inertia) if n else np.zeros((0, 3))
    spread = moments.max(axis=1) - moments.min(axis=1) if n else np.zeros(0)
    isotropic = spread <= ISOTROPY_TOLERANCE * np.maximum(moments.max(axis=1, initial=0.0), 1e-300)

    spring_b = np.array(
        [WORLD_ANCHOR if s.body_b is None else s.body_b for s in springs], dtype=np.int64
    )
    spring_a = np.array([s.body_a for s in springs], dtype=np.int64)
    for k, (a, b) in enumerate(zip(spring_a, spring_b, strict=True)):
        if not 0 <= a < n or not (b == WORLD_ANCHOR or 0 <= b < n) or a == b:
            raise ValueError(f"springs[{k}]: expected two different body indices; got {a}, {b}")
    world = np.array([b.world for b in bodies], dtype=np.int64)
    for k, (a, b) in enumerate(zip(spring_a, spring_b, strict=True)):
        if b != WORLD_ANCHOR and SHARED_WORLD not in (world[a], world[b]) and world[a] != world[b]:
            raise ValueError(f"springs[{k}]: the two bodies are in different worlds")

    model = Model(
        body_name=tuple(labels),
        body_mass=mass,
        body_inv_mass=np.where(fixed, 0.0, 1.0 / mass),
        body_inertia=inertia,
        body_inv_inertia=inv_inertia,
        body_isotropic=isotropic,
        body_shape=np.array([int(b.shape.type) for b in bodies], dtype=np.int64),
        body_size=np.array([b.shape.size() for b in bodies], dtype=float).reshape(n, 3),
        body_bound_radius=np.array([b.shape.bounding_radius() for b in bodies], dtype=float),
        body_restitution=np.array([b.restitution for b in bodies], dtype=float),
        body_friction=np.array([b.friction for b in bodies], dtype=float),
        body_force=np.where(fixed[:, None], 0.0, _rows_of(bodies, labels, "force", 3)),
        body_torque=np.where(fixed[:, None], 0.0, _rows_of(bodies, labels, "torque", 3)),
        body_fixed=fixed,
        body_collides=np.array([b.collides for b in bodies], dtype=bool),
        body_world=world,
        spring_body_a=spring_a,
        spring_body_b=spring_b,
        spring_anchor_a=np.array([s.anchor_a for s in springs], dtype=float).reshape(-1, 3),
        spring_anchor_b=np.array([s.anchor_b for s in springs], dtype=float).reshape(-1, 3),
        spring_stiffness=np.array([s.stiffness for s in springs], dtype=float),
        spring_damping=np.array([s.damping for s in springs], dtype=float),
        spring_rest_length=np.array([s.rest_length for s in springs], dtype=float),
        pair_body_a=np.array([p.body_a for p in pairs], dtype=np.int64),
        pair_body_b=np.array([p.body_b for p in pairs], dtype=np.int64),
        pair_restitution=np.array(
            [np.nan if p.restitution is None else p.restitution for p in pairs], dtype=float
        ),
        pair_friction=np.array(
            [np.nan if p.friction is None else p.friction for p in pairs], dtype=float
        ),
        gravity=_vector(gravity, 3, "gravity"),
    )
    state = State(
        pos=_rows_of(bodies, labels, "position", 3),
        quat=np.array(
            [_unit_quaternion(b.orientation, lab) for b, lab in zip(bodies, labels, strict=True)]
        ).reshape(n, 4),
        vel=_rows_of(bodies, labels, "velocity", 3),
        ang_vel=_rows_of(bodies, labels, "angular_velocity", 3),
    )
    state.vel[fixed] = 0.0
    state.ang_vel[fixed] = 0.0
    if joints:
        joint_model = build_joints(list(joints), state.pos, state.quat, fixed)
        model = dataclasses.replace(model, joints=joint_model)
    return model, state


def replicate(model: Model, state: State, copies: int) -> tuple[Model, State]:
    """``copies`` independent copies of a one-world scene in one model (worlds 0..copies-1).

    Bodies in ``SHARED_WORLD`` are kept once, after all the copies, and seen by every world;
    springs, pair overrides and the state are copied with their body indices remapped.
    """
    if copies < 1:
        raise ValueError(f"copies: expected an integer >= 1; got {copies!r}")
    if model.joints is not None:
        raise ValueError("replicate: a model with joints is not replicated (not built yet)")
    local = np.flatnonzero(model.body_world != SHARED_WORLD)
    shared = np.flatnonzero(model.body_world == SHARED_WORLD)
    n_local = local.size
    old_to_local = np.full(model.n_bodies, -1, dtype=np.int64)
    old_to_local[local] = np.arange(n_local)
    shared_new = copies * n_local + np.arange(shared.size)
    order = np.concatenate([np.tile(local, copies), shared])

    def remap(body: np.ndarray) -> np.ndarray:
        """(s,) old indices -> (copies*s,) new indices, copy-major; shared bodies keep one index."""
        new = np.empty((copies, body.size), dtype=np.int64)
        for_shared = np.zeros(model.n_bodies, dtype=np.int64)
        for_shared[shared] = shared_new
        is_world = body == WORLD_ANCHOR
        safe = np.where(is_world, 0, body)
        is_shared = ~is_world & (model.body_world[safe] == SHARED_WORLD)
        offsets = (np.arange(copies) * n_local)[:, None]
        new[:] = np.where(is_shared, for_shared[safe], old_to_local[safe] + offsets)
        new[:, is_world] = WORLD_ANCHOR
        return new.reshape(-1)

    def tile(array: np.ndarray) -> np.ndarray:
        return np.concatenate(
            [np.tile(array[local], (copies,) + (1,) * (array.ndim - 1)), array[shared]]
        )

    def tile_rows(array: np.ndarray) -> np.ndarray:
        return np.tile(array, (copies,) + (1,) * (array.ndim - 1))

    world = np.concatenate([np.repeat(np.arange(copies), n_local), model.body_world[shared]])
    new_model = Model(
        body_name=tuple(
            [f"{model.body_name[i]}@{c}" for c in range(copies) for i in local]
            + [model.body_name[i] for i in shared]
        ),
        body_mass=tile(model.body_mass),
        body_inv_mass=tile(model.body_inv_mass),
        body_inertia=tile(model.body_inertia),
        body_inv_inertia=tile(model.body_inv_inertia),
        body_isotropic=tile(model.body_isotropic),
        body_shape=tile(model.body_shape),
        body_size=tile(model.body_size),
        body_bound_radius=tile(model.body_bound_radius),
        body_restitution=tile(model.body_restitution),
        body_friction=tile(model.body_friction),
        body_force=tile(model.body_force),
        body_torque=tile(model.body_torque),
        body_fixed=tile(model.body_fixed),
        body_collides=tile(model.body_collides),
        body_world=world,
        spring_body_a=remap(model.spring_body_a),
        spring_body_b=remap(model.spring_body_b),
        spring_anchor_a=tile_rows(model.spring_anchor_a),
        spring_anchor_b=tile_rows(model.spring_anchor_b),
        spring_stiffness=tile_rows(model.spring_stiffness),
        spring_damping=tile_rows(model.spring_damping),
        spring_rest_length=tile_rows(model.spring_rest_length),
        pair_body_a=remap(model.pair_body_a),
        pair_body_b=remap(model.pair_body_b),
        pair_restitution=tile_rows(model.pair_restitution),
        pair_friction=tile_rows(model.pair_friction),
        gravity=model.gravity.copy(),
    )
    new_state = State(
        pos=state.pos[order].copy(),
        quat=state.quat[order].copy(),
        vel=state.vel[order].copy(),
        ang_vel=state.ang_vel[order].copy(),
        time=state.time,
    )
    return new_model, new_state
