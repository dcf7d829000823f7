"""The PyBullet adapter: a ``Scenario`` as PyBullet 3.2.7 bodies, stepped and read back.

Every fact this adapter relies on is measured in ``docs/engines.md`` section 2; the
numbers below name the subsection they come from.

Boundary conventions (engines.md 2.1). PyBullet's base pose is its *inertial* frame (the
centre of mass and the principal axes), quaternions are x y z w, and the base angular
velocity is in the world frame. The scene's body frame has its origin at the centre of
mass too, but its axes are the scene's, and a full 3x3 inertia is not diagonal in them.
The adapter hands PyBullet the principal moments and puts the principal axes ``P`` (a
rotation, body frame) into ``baseInertialFrameOrientation``; so

    q_pybullet = q_body ⊗ q_P        (inertial frame to world)
    q_body     = q_pybullet ⊗ q_P⁻¹   (what ``observe`` returns, w x y z)

and positions and velocities need no conversion (both frames have their origin at the COM).
A body's collision shape (a cylinder ``GEOM_CYLINDER`` along its z) sits in the link frame (the
base's: the body frame) at the scene shape's ``offset`` and ``orientation``
(``collisionFramePosition``/``Orientation``), apart from the inertial frame.

Profiles (``ENGINE_OPTIONS["pybullet"]``):

- ``matched`` (default): PyBullet set up to integrate the scene's model: zero damping, no
  velocity clamp, no restitution threshold, the contact recipe of engines.md 2.4
  that keeps the requested restitution (maximal coordinates by default), the ground as a
  static box whose top face is the scene's plane, as wide as the scene's bodies can reach
  (``ground_box``, ``GROUND_BOX_HALF_THICKNESS``) and a solver that runs all its iterations
  (``MATCHED_SOLVER_RESIDUAL_THRESHOLD``), so that boxes rest and slide on four points.
- ``defaults``: what a new user gets (a btMultiBody with Bullet's damping, clamps and
  contact settings), with the scene's masses, inertias, gravity, dt and contact values,
  on a ``GEOM_PLANE`` ground.

Joints (engines.md 2.5): a scene's joint tree becomes one btMultiBody per tree (``trees``),
whatever the ``bodies`` option; its bodies' states are read from PyBullet's own kinematics
(``getLinkState``) and its joint velocities set from the stated body velocities through them.
A scene without joints takes the path above untouched.

Models (engines.md 2.6): with ``model_loader=native`` (the default) a scene's ``models`` are read
by PyBullet's own ``loadURDF``/``loadMJCF`` (``models``), the scene's other bodies and joints
built as above; each model body is read back as its link's frame times the layout's
``body_in_link``, and ``model_probe`` takes M and the bias from ``calculateMassMatrix`` and
``calculateInverseDynamics``. ``model_loader=physval`` builds them from the expanded bodies and
joints like any others.
"""

from __future__ import annotations

import importlib
import importlib.metadata
import os
import sys
from collections.abc import Set as AbstractSet
from contextlib import contextmanager
from dataclasses import dataclass, field, replace
from types import ModuleType

import numpy as np

from validation.engine_api import model_loader
from validation.engines.base import (
    JointReport,
    ModelProbe,
    ModelReport,
    Provenance,
    Snapshot,
    Trajectory,
)
from validation.engines.frames import matrix_to_quat, principal_axes
from validation.engines.pybullet import models
from validation.engines.pybullet.pair_fit import PAIR_TIERS, pair_system, per_object_values
from validation.engines.pybullet.trees import BASE, Tree, plan_trees
from validation.engines.reference import dynamic_bodies
from validation.reference.articulated import WORLD, JointTree
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
from validation.scenario.physics import PAIR_RULES, body_inertia, ground_pose
from validation.scenario.urdf import ModelLayout


def _import_quietly(name: str) -> ModuleType:
    """``import name`` with file descriptor 2 pointed at /dev/null meanwhile: Bullet's C code
    writes "pybullet build time: ..." to stderr at import, once in every process that loads it,
    which would otherwise interleave with physval's own lines. An import error still raises."""
    sys.stderr.flush()
    saved = os.dup(2)
    try:
        with open(os.devnull, "w") as devnull:
            os.dup2(devnull.fileno(), 2)
            return importlib.import_module(name)
    finally:
        os.dup2(saved, 2)
        os.close(saved)


pybullet = _import_quietly("pybullet")

# --- numbers and where they come from ---------------------------------------------------------

MATCHED_CONTACT_BREAKING_THRESHOLD = 1e-6
"""Bullet's ``gContactBreakingThreshold`` in the matched profile (dimensionless factor of a
shape's bounding radius). engines.md 2.4: at Bullet's 0.02 a contact point appears ≈3.5 mm
before a 0.1 m sphere touches and the speculative solve brakes it; 1e-6 removes the band
(e = 0.4967–0.5001 and 1.0000–1.0003 over 25 drop heights with the recipe below)."""

PYBULLET_CONTACT_BREAKING_THRESHOLD = 0.02
"""Bullet's own default of ``gContactBreakingThreshold`` (engines.md 2.1 [SRC]). It is a
process-wide C global, so the defaults profile must set it back explicitly."""

SPLIT_IMPULSE_PENETRATION_THRESHOLD = 1.0
"""m. Bullet splits the penetration impulse from the velocity solve only for contacts
shallower than this (default −0.04: only deeper than 4 cm). A large positive value always
splits, so penetration recovery never adds bounce velocity (engines.md 2.4 recipe)."""

MULTIBODY_CONTACT_ERP = 0.0
"""Matched profile with ``bodies=multibody`` or a joint tree (engines.md 2.5): btMultiBody
ignores split impulse (engines.md 2.4 [SRC]); its penetration recovery adds ≈0.08·depth/dt of
bounce (up to +8 % in e). 0 removes it (engines.md 2.4: cbt 1e-6 + contactERP 0 gave e =
0.498–0.502 and 1.002–1.005), as the scene's default ``position_correction: none`` does."""

MAX_JOINT_VELOCITY = 1e4
"""rad/s and m/s. btMultiBody clamps every base velocity component to ±100 even in free
flight (engines.md 2.2); this lifts the clamp far above any scene. (Maximal bodies clamp
|ω|·dt ≤ π/2 instead, 1571 rad/s at dt = 1e-3; no API changes that.)"""

MATCHED_CONTACT_SLOP = 0.0
"""m. Bullet's ``contactSlop`` (default 1e-5 m) is a penetration the solver leaves alone; a
contact that starts an impact step exactly touching loses slop/dt of its rebound to it:
measured 0.005 / 0.010 / 0.020 m/s at dt = 2 / 1 / 0.5 ms for e = 0.5 at 0.03 and 1 m/s
(e = 0.17 for 0.5 at 0.03 m/s), whatever the speed. With 0 the rebound is e·v exactly at every
dt and speed (measured); resting stacks still settle through split impulse."""

MATCHED_RESTITUTION_THRESHOLD = 0.0
"""m/s. The scene has no restitution threshold; Bullet's default 0.2 zeroes every impact
slower than 0.2 m/s (engines.md 2.4)."""


GROUND_BOX_HALF_THICKNESS = 1.0
"""m, at least (``ground_box``). The matched profile's ground: a static ``GEOM_BOX`` whose top
face is the scene's ground plane, not a ``GEOM_PLANE``; as wide as the scene's bodies can reach.

Why [SRC bullet3 btConvexPlaneCollisionAlgorithm.cpp, btPersistentManifold.cpp,
btBoxBoxCollisionAlgorithm.cpp]: a box against a plane gets ONE new point per step (the
deepest vertex); its perturbation pass is off in PyBullet's collision configuration (minimum
points 0), so a 4-point manifold exists only by persistence. A point is dropped when it
separates or slides sideways by more than the manifold's breaking threshold, the smaller of
the two shapes' ``MATCHED_CONTACT_BREAKING_THRESHOLD`` x bounding radius (0.29 µm for the
0.4 x 0.4 x 0.1 m box): a sliding box (1 mm per step) keeps only this step's point, and a
resting one loses every point that rises 0.3 µm. The box rocks on 1-2 points and its velocity
solve sinks it while split impulse pushes it back. btBoxBoxDetector instead clips the two
boxes every step and reports up to 4 points, whatever persists.

Measured (PyBullet 3.2.7, dt = 1e-3, matched profile), GEOM_PLANE -> this box ground:
box_slide_stop (1 kg, 0.4 x 0.4 x 0.1 m, 1 m/s, μ = 0.2) penetration 2.26 mm -> 14 µm,
velocity error mid-slide 0.0275 -> 0.0005 m/s, ω_x 0.129 -> 0.0004 rad/s, stop position error
2.77 -> 0.69 mm (discrete stop 0.50 mm; the rest is ``MATCHED_SOLVER_RESIDUAL_THRESHOLD``'s);
box_stack velocity_at.box5 0.0227 -> 0.0021 m/s; box_drop_flat e 0.292 -> 0.499, box_drop_edge
post-impact speed error 0.797 -> 0.0003 m/s (the flat-box spin of engines.md 2.4 is the same
one-point manifold); deep_initial_penetration velocity 0.023 -> 0.0072 m/s. Spheres use
btSphereBoxCollisionAlgorithm, with the same speculative band (breaking threshold x the
sphere's radius): bounce_ladder, millimetre_spheres, slow_bounce_below_threshold,
newtons_cradle, oblique_impact_friction, bounce_impact_times and capsule_drop keep every row's
value to 1e-9 relative (single impacts' e moved by <= 1.6e-9, slow_bounce_below_threshold); the
sphere rolling on the tilted ground (incline_roll_and_slide) moved its velocity error 3.6e-4 ->
2.7e-4 m/s (it fails its 1e-6 before and after).

Size (``ground_box``): the plane is infinite, the box is not, so it is sized from the scene:
its top face reaches, in every direction along the plane, as far as any body can over the run
(the body's distance from the ground point, plus its bounding radius, plus the scene's
``speed_scale`` times the duration: no body is faster than the speed scale), and at least
``GROUND_BOX_MIN_HALF_WIDTH`` (a smaller box changes Bullet's box-box manifold). A fixed 2 km box
let a kilometre-scale bounce land past its edge, fall through and be declared ``unstable``.
1 m of thickness is 25x the deepest initial overlap (deep_initial_penetration, 4 cm); it grows
to what a body at the speed scale moves in one step, so nothing crosses it in a step. The
breaking threshold takes the smaller bounding radius, the body's, so the ground's size does not
change it.

Cost, measured: btBoxBoxDetector reports only overlapping points (depth >= 0; no speculative
band), and a box that starts exactly touching gets no point in its first step (round-off):
it falls g·dt² = 9.8 µm and is caught by 2·m·g·dt in the second (box_slide_stop's
penetration_max, 9.81 µm)."""

GROUND_BOX_MIN_HALF_WIDTH = 1000.0
"""m. The least half width of the matched ground box (``ground_box``), wider when the scene's
reach is. Bullet's box-box manifold depends on the ground box's size: box_slide_stop's sliding
box (tests/test_engine_pybullet.py, velocity exact to 7e-15 m/s on this box) lost its support
for one step at x = 0.215 m (a g·dt = 0.0098 m/s jump) with half widths of 2 to 600 m, and kept
it at 700 m to 100 km (PyBullet 3.2.7, measured). 1 km, the width the library was measured on,
stays the least."""

MATCHED_SOLVER_RESIDUAL_THRESHOLD = 0.0
"""(N·s)², PyBullet's ``solverResidualThreshold`` (default 1e-7): the sequential-impulse
solver stops once the largest squared impulse change of an iteration is below it, i.e. once
no row changes by 3.2e-4 N·s, 3 % of a 1 kg body's weight impulse per step at dt = 1e-3. A
resting box then keeps ~1e-5 m/s at its corners: it rocks, a corner lifts out of the
overlap-only box-box manifold for a step (86 of 500 sliding steps had fewer than 4), and a
friction row whose normal impulse fell to 0 in a later iteration is not clamped again
(btSequentialImpulseConstraintSolver::solveSingleIteration updates friction only while the
normal impulse is > 0): measured friction/normal = 0.2010 on 3-point steps, 0.20015 overall,
box_slide_stop stopping 0.19 mm short of the discrete stop (error 0.694 mm > 0.67 mm). With 0
the solver runs all ``numSolverIterations`` (50): box_slide_stop's velocity equals
v0 - μg·n·dt to 5e-15 m/s, ω to 4e-18 rad/s, the stop error is the discrete 0.498 mm;
box_stack velocity_at.box5 0.0021 -> 0.0019 m/s; deep_initial_penetration 0.0072 m/s -> 5e-15;
incline_roll_and_slide's roller 2.7e-4 -> 8.9e-5 m/s (still failing 1e-6), its energy_drift
5.219e-3 -> 5.2305e-3 (the scene's derivation: 5.23e-3); millimetre_spheres position error
3.5e-7 -> 1.4e-9 m; mass_ratio_1e6's impact e by 1.8e-9. On the plane ground alone it changed no row's pass/fail (box_slide_stop
errors unchanged to 3 digits). The library's PyBullet run took no longer (pile of 666: 21 s
before, 19-23 s after, on a shared machine)."""


FRICTION_CAP = 10.0
"""Bullet caps the combined lateral friction μ_A·μ_B at 10 (engines.md 2.3 [SRC])."""


MAX_PAIR_NOTES = 12
"""Pairs listed one by one in the notes; the rest are counted (all are in the settings)."""


GYROSCOPIC_TERM = {"maximal": "implicit (btRigidBody)", "multibody": "explicit (btMultiBody)"}
"""engines.md 2.2: which gyroscopic integration each body mode uses (not selectable)."""

GROUND = "ground"
"""The name scene pairs use for the ground plane."""


def ground_box(scene: CompiledScene) -> tuple[np.ndarray, np.ndarray]:
    """The matched ground box for ``scene`` (``GROUND_BOX_HALF_THICKNESS``): its centre (3,) m,
    under the ground point along the plane's normal, and its half extents (3,) m in the ground's
    frame (normal = its +z). Half width: the farthest any body can be from the ground point
    along the plane over the run (start offset + bounding radius + speed scale x duration),
    at least ``GROUND_BOX_MIN_HALF_WIDTH``."""
    point, quat = ground_pose(scene.scenario.ground)
    rot = quat_to_matrix(quat[None])[0]
    normal = rot[:, 2]
    offset = scene.start.pos[0] - point
    along_plane = np.linalg.norm(offset - np.outer(offset @ normal, normal), axis=1)
    travel = scene.speed_scale * scene.scenario.duration
    reach = float(np.max(along_plane + scene.bound_radius[: scene.count], initial=0.0)) + travel
    width = max(GROUND_BOX_MIN_HALF_WIDTH, reach)
    thickness = max(GROUND_BOX_HALF_THICKNESS, scene.speed_scale * scene.scenario.dt)
    return point - thickness * normal, np.array([width, width, thickness])


@dataclass(frozen=True)
class Profile:
    """How one profile sets PyBullet up (see the module docstring)."""

    bodies: str
    """Body mode when the spec does not say: ``maximal`` (btRigidBody) or ``multibody``."""
    zero_damping: bool
    """Set linear and angular damping to 0 (btMultiBody defaults to 0.04 + 0.04|v|)."""
    lift_velocity_clamp: bool
    """Raise btMultiBody's ±100 velocity clamp to ``MAX_JOINT_VELOCITY``."""
    contact_breaking_threshold: float
    """Set explicitly on every load and before every ``advance`` (process-wide global)."""
    world: dict[str, float | int] = field(default_factory=dict)
    """Extra ``setPhysicsEngineParameter`` keywords for every body mode."""
    multibody_world: dict[str, float | int] = field(default_factory=dict)
    """Extra ``setPhysicsEngineParameter`` keywords when the bodies are btMultiBody."""
    ground: str = "plane"
    """``plane`` (GEOM_PLANE) or ``box`` (a static GEOM_BOX sized by ``ground_box``)."""


PROFILES = {
    "matched": Profile(
        bodies="maximal",
        zero_damping=True,
        lift_velocity_clamp=True,
        contact_breaking_threshold=MATCHED_CONTACT_BREAKING_THRESHOLD,
        world={
            "restitutionVelocityThreshold": MATCHED_RESTITUTION_THRESHOLD,
            "contactSlop": MATCHED_CONTACT_SLOP,
            "useSplitImpulse": 1,
            "splitImpulsePenetrationThreshold": SPLIT_IMPULSE_PENETRATION_THRESHOLD,
            "solverResidualThreshold": MATCHED_SOLVER_RESIDUAL_THRESHOLD,
        },
        multibody_world={"contactERP": MULTIBODY_CONTACT_ERP},
        ground="box",
    ),
    "defaults": Profile(
        bodies="multibody",
        zero_damping=False,
        lift_velocity_clamp=False,
        contact_breaking_threshold=PYBULLET_CONTACT_BREAKING_THRESHOLD,
    ),
}

SHAPE_KEYWORDS = {
    "sphere": lambda s: {"shapeType": pybullet.GEOM_SPHERE, "radius": s.radius},
    "box": lambda s: {"shapeType": pybullet.GEOM_BOX, "halfExtents": list(s.half_extents)},
    # PyBullet's capsule height is the cylinder's length along body z (engines.md 2.1).
    "capsule": lambda s: {
        "shapeType": pybullet.GEOM_CAPSULE,
        "radius": s.radius,
        "height": 2.0 * s.half_length,
    },
    # GEOM_CYLINDER's height is its full length, along the shape's z (as the capsule's).
    "cylinder": lambda s: {
        "shapeType": pybullet.GEOM_CYLINDER,
        "radius": s.radius,
        "height": 2.0 * s.half_length,
    },
}
"""Scene shape type -> ``createCollisionShape`` keywords (same size conventions)."""

PYBULLET_JOINT_TYPES = {
    "hinge": pybullet.JOINT_REVOLUTE,
    "slider": pybullet.JOINT_PRISMATIC,
    "ball": pybullet.JOINT_SPHERICAL,
    "fixed": pybullet.JOINT_FIXED,
}
"""Scene joint type -> PyBullet's link joint type (engines.md 2.5)."""

JOINT_WORDS = {code: word for word, code in PYBULLET_JOINT_TYPES.items()}
"""PyBullet's joint type -> the scene's word (``joint_report``)."""

JOINT_DOFS = {"hinge": 1, "slider": 1, "ball": 3, "fixed": 0}
"""Velocity coordinates of each joint type (``resetJointStateMultiDof``'s ``targetVelocity``)."""

FLOATING_BASE_DOFS = 6
"""A floating base's velocity coordinates: v and ω, world frame (``resetBaseVelocity``)."""

JOINT_REST = {"hinge": [0.0], "slider": [0.0], "ball": [0.0, 0.0, 0.0, 1.0], "fixed": []}
"""Each joint type's position at the scene's t = 0 (``targetValue``; a quaternion x y z w)."""

JOINT_LIMIT_FORCE = 1e12
"""N or N·m: the joint limit constraint's largest force (``jointLimitForce``). Bullet's default
is too small to stop heavy bodies: a 1000 kg·m² wheel at 10 rad/s ran 0.5 rad past a 0.2 rad
limit with it, and stopped at the limit with this (engines.md 2.5)."""

JOINTS_NOTE = (
    "joints: one btMultiBody per tree (Featherstone, reduced coordinates) whatever the bodies "
    "option says (it sets the free bodies' mode); joint damping is btMultiBody's jointDamping, "
    "an explicit torque -c·q̇ from the step's start velocity; PyBullet's default joint motors "
    "are switched off; a joint's parent and child never collide (URDF_USE_SELF_COLLISION), "
    "every other pair does; the world takes the multibody settings (contactERP 0), so maximal "
    "free bodies do not push out of overlaps (engines.md 2.5)"
)
"""The provenance note of a scene with joints."""

MODELS_NOTE = (
    "models loaded natively (model_loader=native, engines.md 2.6): PyBullet's own loadURDF or "
    "loadMJCF reads the file; its joints' velocity motors are switched off and the profile's "
    "link damping replaces Bullet's 0.04; URDF damping is jointDamping (explicit -c·q̇); a "
    "fixed base is static and holds mass 0 in PyBullet (the scene's values are reported for it)"
)
"""The provenance note of a scene with natively loaded models."""

# --- frames ---------------------------------------------------------------------------------


def to_xyzw(quat: np.ndarray) -> list[float]:
    """w x y z -> PyBullet's x y z w."""
    return [float(quat[1]), float(quat[2]), float(quat[3]), float(quat[0])]


def from_xyzw(quat) -> np.ndarray:
    """PyBullet's x y z w -> w x y z (one quaternion (4,) or many (..., 4))."""
    return np.asarray(quat, dtype=float)[..., [3, 0, 1, 2]]


@dataclass(frozen=True)
class Coordinate:
    """One tree coordinate PyBullet holds as a joint coordinate (``_coordinates``): the
    multibody, joint index, the file's coordinate at t = 0, and its index in q and in ν."""

    body: int
    index: int
    initial: float
    q: int
    v: int


IDENTITY_QUAT = np.array([1.0, 0.0, 0.0, 0.0])
"""w x y z."""


def _without(tree: JointTree, names: AbstractSet[str]) -> JointTree:
    """``tree`` without the joints named in ``names`` (a native model's, loaded by PyBullet
    itself): the scene's other joints, planned into multibodies as before."""
    return replace(tree, joints=tuple(j for j in tree.joints if j.name not in names))


def conjugate(quat: np.ndarray) -> np.ndarray:
    """Inverse of unit quaternions (n, 4) w x y z."""
    return quat * np.array([1.0, -1.0, -1.0, -1.0])


# --- provenance helpers -----------------------------------------------------------------


# --- the adapter ----------------------------------------------------------------------------


class PybulletAdapter:
    """PyBullet as an ``EngineAdapter``: one DIRECT client per adapter, closed in ``close``.

    Attributes (after ``load``):
        client: the PyBullet physics client id (pass it as ``physicsClientId``).
        ids: (n,) PyBullet body ids of the scene's bodies, scenario order (a jointed body's
            is its tree's multibody).
        links: (n,) each body's link index in its multibody (-1: a base, every unjointed body).
        trees: the scene's multibodies (``trees.plan_trees``; empty without joints).
        ground: PyBullet body id of the ground plane, or None.
    """

    def __init__(self, spec: EngineSpec):
        self.spec = spec
        options = spec.as_dict()
        self.profile_name = str(options.get("profile", "matched"))
        self.profile = PROFILES[self.profile_name]
        self.bodies_mode = str(options.get("bodies", self.profile.bodies))
        self.solver_iterations = options.get("solver_iterations")
        self.model_loader = model_loader(spec.name, options)
        self.urdf_inertia = str(options.get("urdf_inertia", "file"))
        self.client: int | None = None

    # -- loading ---------------------------------------------------------------------------

    def load(self, scene: CompiledScene) -> None:
        """Build the scene in a fresh PyBullet world at the scene's dt and gravity."""
        if self.client is None:
            self.client = pybullet.connect(pybullet.DIRECT)
        else:
            pybullet.resetSimulation(physicsClientId=self.client)
        self.scene = scene
        self.scenario = scenario = scene.scenario
        self.steps_taken = 0
        self.notes: list[str] = []
        layouts = scene.models if self.model_loader == "native" else ()
        owned = scene.model_names.keys() if layouts else frozenset()
        self.trees = (
            [] if scene.joint_tree is None else plan_trees(_without(scene.joint_tree, owned))
        )
        self._set_up_world(scenario)
        jointed = {body for tree in self.trees for body in tree.bodies}
        self.ids = [
            -1 if k in jointed or spec.name in owned else self._create_body(spec)
            for k, spec in enumerate(scenario.bodies)
        ]
        self.links = [BASE] * len(self.ids)
        self.parts: list[models.Part | None] = [None] * len(self.ids)
        for tree in self.trees:
            self._create_tree(tree)
        self.native = [self._load_model(layout) for layout in layouts]
        self.ground = self._create_ground() if scenario.ground else None
        self._set_contact_values(scenario)
        self._filter_pairs(scenario)
        self._keep_apart(scenario, owned)
        self._set_up_loads(scenario)
        self.tree_velocities = np.zeros(0)
        if self.trees:
            self._set_joint_velocities(scenario)

    def _load_model(self, layout: ModelLayout) -> models.NativeModel:
        """One of the scene's models through PyBullet's own loader (``models.load_model``:
        placed, at its initial joint state), with the velocity motors PyBullet puts on its
        joints switched off, the profile's damping and velocity clamp (``_multibody_settings``)
        on each of its multibodies, and no collisions for ``collisions: false``. A floating
        base floats as the file's base link (``useFixedBase`` false)."""
        model = models.load_model(layout, self.urdf_inertia, self.client)
        models.release_motors(model, self.client)
        for body in model.ids:
            pybullet.changeDynamics(
                body, BASE, **self._multibody_settings(), physicsClientId=self.client
            )
        if not layout.spec.collisions:
            models.switch_off_collisions(model, self.client)
        names = [body.name for body in self.scenario.bodies]
        for name, part in model.parts.items():
            k = names.index(name)
            self.ids[k], self.links[k], self.parts[k] = part.body, part.link, part
        return model

    def _world_parameters(self, scenario: Scenario) -> dict[str, float | int]:
        parameters: dict[str, float | int] = {
            "fixedTimeStep": scenario.dt,
            "numSubSteps": 0,
            "contactBreakingThreshold": self.profile.contact_breaking_threshold,
            **self.profile.world,
        }
        if self.bodies_mode == "multibody" or self.trees:
            parameters.update(self.profile.multibody_world)
        if self.solver_iterations is not None:
            parameters["numSolverIterations"] = int(self.solver_iterations)
        return parameters

    def _set_up_world(self, scenario: Scenario) -> None:
        self.world_settings = self._world_parameters(scenario)
        pybullet.setGravity(*scenario.gravity, physicsClientId=self.client)
        pybullet.setPhysicsEngineParameter(**self.world_settings, physicsClientId=self.client)

    def _create_body(self, spec: BodySpec) -> int:
        """One scene body; its base pose is the COM with the principal axes (module docstring)."""
        moments, q_principal = principal_axes(body_inertia(spec))
        shape = self._collision_shape(spec)
        body = pybullet.createMultiBody(
            baseMass=0.0 if spec.fixed else spec.mass,
            baseCollisionShapeIndex=shape,
            basePosition=list(spec.position),
            baseOrientation=to_xyzw(np.asarray(spec.orientation)),
            baseInertialFramePosition=[0.0, 0.0, 0.0],
            baseInertialFrameOrientation=to_xyzw(q_principal),
            useMaximalCoordinates=self.bodies_mode == "maximal",
            physicsClientId=self.client,
        )
        if not spec.fixed:
            self._set_mass_properties(body, spec.mass, moments)
            pybullet.resetBaseVelocity(
                body,
                linearVelocity=list(spec.velocity),
                angularVelocity=list(spec.angular_velocity),
                physicsClientId=self.client,
            )
        return body

    def _collision_shape(self, spec: BodySpec, centre: np.ndarray | None = None) -> int:
        """The body's shape at its place in the link frame (a base's: the body frame): the
        body's centre there (a link's ``centre``: PyBullet puts a link's shape at the link
        frame's origin, the joint, engines.md 2.5) plus the shape's ``offset``, turned by its
        ``orientation`` (the link frame has the body's axes; the inertial frame, and so the
        body's stated inertia, is set apart from it)."""
        shape = spec.shape
        frame = np.zeros(3) if centre is None else np.asarray(centre, dtype=float)
        placed = {}
        if shape.placed or centre is not None:
            placed = {
                "collisionFramePosition": (frame + np.asarray(shape.offset)).tolist(),
                "collisionFrameOrientation": to_xyzw(np.asarray(shape.orientation)),
            }
        return pybullet.createCollisionShape(
            **SHAPE_KEYWORDS[shape.type](shape), **placed, physicsClientId=self.client
        )

    def _set_mass_properties(
        self, body: int, mass: float, moments: np.ndarray, link: int = BASE
    ) -> None:
        """Mass and principal moments in one call (engines.md 2.1: mass alone recomputes the
        inertia from the shape; a diagonal alone zeroes a maximal body's mass); with a base's,
        the profile's damping and velocity clamp (``_multibody_settings``: the whole
        multibody's). A link's go alone: with any multibody-wide keyword in the call,
        PyBullet gives the mass and moments to the base instead (engines.md 2.5)."""
        extra = self._multibody_settings() if link == BASE else {}
        pybullet.changeDynamics(
            body,
            link,
            mass=mass,
            localInertiaDiagonal=[float(m) for m in moments],
            **extra,
            physicsClientId=self.client,
        )

    def _multibody_settings(self) -> dict[str, float]:
        """The profile's damping and velocity clamp, ``changeDynamics`` keywords."""
        extra: dict[str, float] = {}
        if self.profile.zero_damping:
            extra.update(linearDamping=0.0, angularDamping=0.0)
        if self.profile.lift_velocity_clamp:
            extra["maxJointVelocity"] = MAX_JOINT_VELOCITY
        return extra

    def _create_tree(self, tree: Tree) -> None:
        """One multibody of ``trees.plan_trees`` (Featherstone, reduced coordinates): the base
        (the world's massless, shapeless fixed base, or the root body: fixed massless, or
        floating), then a link per jointed body at the frames of ``trees``'s docstring, each
        with its mass, principal moments and joint damping and with PyBullet's default joint
        motor switched off (engines.md 2.5). ``URDF_USE_SELF_COLLISION``: the tree's bodies
        collide with each other except a joint's parent and child."""
        bodies = self.scenario.bodies
        root = None if tree.root == WORLD else bodies[tree.root]
        base = {"baseMass": 0.0, "baseCollisionShapeIndex": -1}
        if root is not None:
            base = {
                "baseMass": 0.0 if root.fixed else root.mass,
                "baseCollisionShapeIndex": self._collision_shape(root),
                "basePosition": list(root.position),
                "baseOrientation": to_xyzw(np.asarray(root.orientation)),
                "baseInertialFrameOrientation": to_xyzw(principal_axes(body_inertia(root))[1]),
            }
        specs = [bodies[link.body] for link in tree.links]
        multibody = pybullet.createMultiBody(
            **base,
            linkMasses=[spec.mass for spec in specs],
            linkCollisionShapeIndices=[
                self._collision_shape(spec, link.centre)
                for link, spec in zip(tree.links, specs, strict=True)
            ],
            linkVisualShapeIndices=[-1] * len(specs),
            linkPositions=[link.position.tolist() for link in tree.links],
            linkOrientations=[to_xyzw(matrix_to_quat(link.rotation)) for link in tree.links],
            linkInertialFramePositions=[link.centre.tolist() for link in tree.links],
            linkInertialFrameOrientations=[
                to_xyzw(principal_axes(body_inertia(spec))[1]) for spec in specs
            ],
            linkParentIndices=[link.parent + 1 for link in tree.links],  # 0 is the base
            linkJointTypes=[PYBULLET_JOINT_TYPES[link.type] for link in tree.links],
            linkJointAxis=[link.axis.tolist() for link in tree.links],
            flags=pybullet.URDF_USE_SELF_COLLISION,
            physicsClientId=self.client,
        )
        if root is not None:
            self.ids[tree.root] = multibody
        if root is not None and not root.fixed:
            moments = principal_axes(body_inertia(root))[0]
            self._set_mass_properties(multibody, root.mass, moments)
        else:
            pybullet.changeDynamics(
                multibody, BASE, **self._multibody_settings(), physicsClientId=self.client
            )
        for k, (link, spec) in enumerate(zip(tree.links, specs, strict=True)):
            self.ids[link.body], self.links[link.body] = multibody, k
            self._set_mass_properties(
                multibody, spec.mass, principal_axes(body_inertia(spec))[0], k
            )
            pybullet.changeDynamics(
                multibody, k, jointDamping=link.damping, physicsClientId=self.client
            )
            self._release_motor(multibody, k, link.type)
            self._set_limits(multibody, k, link.joint)

    def _set_joint_velocities(self, scenario: Scenario) -> None:
        """The trees' joint velocities (and floating bases') from the bodies' stated
        velocities, through PyBullet's own kinematics at the initial configuration
        (``_tree_jacobian``): the least-squares solution of ``J ν = (v, ω)``, exact for the
        velocities the scene's checks let through (the joints allow them), is set."""
        moving, jacobian = self._tree_jacobian()
        stated = np.array(
            [[*scenario.bodies[b].velocity, *scenario.bodies[b].angular_velocity] for b in moving]
        ).reshape(-1)
        self.tree_velocities = np.linalg.lstsq(jacobian, stated, rcond=None)[0]
        self._set_tree_velocities(self.tree_velocities)

    def _tree_jacobian(self) -> tuple[list[int], np.ndarray]:
        """(the trees' moving bodies, J (6 per body, velocity coordinates)): column k is every
        such body's (v, ω), world frame, read back (``_link_state``) with velocity coordinate k
        (``_set_tree_velocities``) at 1 and the others at 0 (body velocities are linear in
        them). It leaves the trees' velocities at 0."""
        bodies = self.scenario.bodies
        moving = [b for tree in self.trees for b in tree.bodies if not bodies[b].fixed]
        count = sum(self._velocity_sizes())
        columns = []
        for k in range(count):
            self._set_tree_velocities(np.eye(count)[k])
            columns.append(np.array(self._raw_state())[moving, 7:13].reshape(-1))
        self._set_tree_velocities(np.zeros(count))
        return moving, np.array(columns).reshape(count, 6 * len(moving)).T

    def _velocity_sizes(self) -> list[int]:
        """The trees' velocity blocks in order: a floating base's 6, then each joint's."""
        sizes = []
        for tree in self.trees:
            if tree.root != WORLD and not self.scenario.bodies[tree.root].fixed:
                sizes.append(FLOATING_BASE_DOFS)
            sizes += [JOINT_DOFS[link.type] for link in tree.links]
        return sizes

    def _set_tree_velocities(self, nu: np.ndarray) -> None:
        """Every tree's velocity coordinates ``nu`` (``_velocity_sizes``' order): a floating
        base's (v, ω) world frame by ``resetBaseVelocity``, each joint's by
        ``resetJointStateMultiDof`` at its initial position."""
        at = 0
        for tree in self.trees:
            if tree.root != WORLD and not self.scenario.bodies[tree.root].fixed:
                base = nu[at : at + FLOATING_BASE_DOFS]
                pybullet.resetBaseVelocity(
                    self.ids[tree.root],
                    linearVelocity=base[:3].tolist(),
                    angularVelocity=base[3:].tolist(),
                    physicsClientId=self.client,
                )
                at += FLOATING_BASE_DOFS
            for link in tree.links:
                size = JOINT_DOFS[link.type]
                if size:
                    pybullet.resetJointStateMultiDof(
                        self.ids[link.body],
                        self.links[link.body],
                        targetValue=JOINT_REST[link.type],
                        targetVelocity=nu[at : at + size].tolist(),
                        physicsClientId=self.client,
                    )
                at += size

    def _set_limits(self, multibody: int, link: int, joint: str) -> None:
        """The scene joint's ``limits`` (rad or m from t = 0, PyBullet's joint coordinate 0):
        btMultiBody's joint limit constraint, its impulse unbounded (``JOINT_LIMIT_FORCE``).
        Measured (engines.md 2.5): an inelastic stop one step late, the limit passed by up to
        the step's travel and then kept (``erp``, ``contactERP``, ``frictionERP`` 0.2 leave it)."""
        stated = next(j for j in self.scenario.joints if j.name == joint)
        if stated.limits is None:
            return
        lower, upper = stated.limits
        pybullet.changeDynamics(
            multibody,
            link,
            jointLowerLimit=float(lower),
            jointUpperLimit=float(upper),
            jointLimitForce=JOINT_LIMIT_FORCE,
            physicsClientId=self.client,
        )

    def _release_motor(self, multibody: int, link: int, joint_type: str) -> None:
        """Switch off the velocity motor PyBullet puts on every joint it creates (engines.md
        2.5: it holds a joint at rest, 1 rad/s -> 0 within a second): a zero-force motor."""
        if joint_type == "fixed":
            return
        dofs = JOINT_DOFS[joint_type]
        pybullet.setJointMotorControlMultiDof(
            multibody,
            link,
            pybullet.POSITION_CONTROL,  # the one multi-DOF mode every joint type takes
            targetPosition=JOINT_REST[joint_type],
            targetVelocity=[0.0] * dofs,
            force=[0.0] * dofs,
            physicsClientId=self.client,
        )

    def _create_ground(self) -> int:
        """The static ground at the one ground pose of ``physics.ground_pose`` (normal = its
        +z): a plane, or the profile's box with its top face on that plane."""
        point, quat = ground_pose(self.scenario.ground)
        if self.profile.ground == "box":
            point, half = ground_box(self.scene)
            shape = pybullet.createCollisionShape(
                pybullet.GEOM_BOX, halfExtents=half.tolist(), physicsClientId=self.client
            )
        else:
            shape = pybullet.createCollisionShape(pybullet.GEOM_PLANE, physicsClientId=self.client)
        return pybullet.createMultiBody(
            baseMass=0.0,
            baseCollisionShapeIndex=shape,
            basePosition=point.tolist(),
            baseOrientation=to_xyzw(quat),
            useMaximalCoordinates=self.bodies_mode == "maximal",
            physicsClientId=self.client,
        )

    def _ground_settings(self) -> dict | None:
        """The ground as set up (provenance): the box's half extents, or the plane; None
        without a ground."""
        if self.scenario.ground is None:
            return None
        if self.profile.ground == "box":
            return {"shape": "GEOM_BOX", "halfExtents": ground_box(self.scene)[1].tolist()}
        return {"shape": "GEOM_PLANE"}

    def _objects(self) -> list[tuple[int, int]]:
        """(PyBullet body id, link index) of each scene body, then of the ground."""
        ground = [(self.ground, BASE)] if self.ground is not None else []
        return [*zip(self.ids, self.links, strict=True), *ground]

    def _set_contact_values(self, scenario: Scenario) -> None:
        """Per-body restitution and friction whose products are the scene's pair values
        (PyBullet multiplies the two bodies' values, engines.md 2.3); every pair that
        cannot get its value is recorded (settings and notes)."""
        self.contact_values: dict[str, list[float]] = {}
        self.contact_misses: list[dict[str, object]] = []
        for quantity in PAIR_RULES:
            system = pair_system(scenario, quantity)
            values, missed = per_object_values(
                len(system.members), system.targets, system.tiers, system.anchor, system.counts
            )
            self.contact_values[quantity] = [float(values[c]) for c in system.class_of]
            self.contact_misses += [
                {
                    "quantity": quantity,
                    "pair": (system.label(a), system.label(b)),
                    "object_pairs": system.counts[(a, b)],
                    "scene": system.targets[(a, b)],
                    "pybullet": got,
                    "tier": PAIR_TIERS[system.tiers[(a, b)]],
                }
                for (a, b), got in sorted(missed.items(), key=lambda item: system.tiers[item[0]])
            ]
            self.contact_misses += [
                {
                    "quantity": quantity,
                    "pair": (system.label(a), system.label(b)),
                    "object_pairs": system.counts[(a, b)],
                    "scene": t,
                    "pybullet": FRICTION_CAP,
                    "tier": "Bullet caps the combined friction",
                }
                for (a, b), t in system.targets.items()
                if quantity == "friction" and t > FRICTION_CAP
            ]
        self.notes += self._contact_notes()
        for k, (body, link) in enumerate(self._objects()):
            pybullet.changeDynamics(
                body,
                link,
                restitution=self.contact_values["restitution"][k],
                lateralFriction=self.contact_values["friction"][k],
                rollingFriction=0.0,
                spinningFriction=0.0,
                physicsClientId=self.client,
            )

    def _contact_notes(self) -> list[str]:
        """One note per missed pair (the first ``MAX_PAIR_NOTES``), then a count."""
        if not self.contact_misses:
            return []
        notes = [
            "PyBullet multiplies the two bodies' restitutions and frictions; no per-body "
            "values give every pair the scene's value, so these pairs (if they meet) differ:"
        ]
        notes += [
            f"  {m['quantity']} {m['pair'][0]}–{m['pair'][1]} ({m['tier']}, "
            f"{m['object_pairs']} pair(s)): PyBullet {m['pybullet']:.6g}, scene {m['scene']:.6g}"
            for m in self.contact_misses[:MAX_PAIR_NOTES]
        ]
        if len(self.contact_misses) > MAX_PAIR_NOTES:
            notes.append(
                f"  ... and {len(self.contact_misses) - MAX_PAIR_NOTES} more pairs "
                "(settings['contact_misses'])"
            )
        return notes

    def _keep_apart(self, scenario: Scenario, owned: AbstractSet[str]) -> None:
        """Every body with ``collides: false`` in no collision group and accepting none (a
        native model's links are its loader's: ``models.load_model``)."""
        for k, body in enumerate(scenario.bodies):
            if not body.collides and body.name not in owned:
                pybullet.setCollisionFilterGroupMask(
                    self.ids[k], self.links[k], *models.NO_COLLISIONS, physicsClientId=self.client
                )

    def _filter_pairs(self, scenario: Scenario) -> None:
        """No contact pair for two objects that can never meet: two static ones (fixed
        bodies, the ground). Every pair with a moving body keeps its contacts."""
        static = [b.fixed for b in scenario.bodies] + ([True] if scenario.ground else [])
        objects = self._objects()
        self.filtered_pairs = [
            (i, j)
            for i in range(len(objects))
            for j in range(i + 1, len(objects))
            if static[i] and static[j]
        ]
        for i, j in self.filtered_pairs:
            (body_a, link_a), (body_b, link_b) = objects[i], objects[j]
            pybullet.setCollisionFilterPair(
                body_a, body_b, link_a, link_b, 0, physicsClientId=self.client
            )

    def _set_up_loads(self, scenario: Scenario) -> None:
        """Springs and constant applied loads are the compiled scene's (``scene.springs``, the
        same rest lengths as every engine's: the anchors' distance at t = 0 unless given);
        Bullet clears external forces after every step, so they are applied explicitly before
        every step."""
        self.fixed = np.array([b.fixed for b in scenario.bodies])
        ends = np.concatenate([self.scene.springs.body_a, self.scene.springs.body_b])
        constant = np.any(self.scene.force != 0.0, axis=1) | np.any(
            self.scene.torque != 0.0, axis=1
        )
        self.loaded = ~self.fixed & (np.isin(np.arange(len(scenario.bodies)), ends) | constant)
        self.any_loads = bool(self.loaded.any())
        self.scene_quat = np.array([b.orientation for b in scenario.bodies])
        self.principal = np.array(
            [principal_axes(body_inertia(b))[1] for b in scenario.bodies]
        ).reshape(-1, 4)
        native = [k for k, part in enumerate(self.parts) if part is not None]
        self.principal[native] = IDENTITY_QUAT  # a model body's row is in its own axes
        if self.loaded.any():
            self.notes.append(
                "springs and applied loads: forces applied with applyExternalForce (at the centre "
                "of mass) and applyExternalTorque (world frame) before every step, from the state "
                "at the start of the step (explicit in time), by the reference's load law "
                "(validation.reference.loads.applied_loads)"
            )

    # -- reading back ----------------------------------------------------------------------

    def _read_state(self) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """COM pos (n, 3), PyBullet inertial-frame quat (n, 4) w x y z, vel, world ω."""
        raw = np.array(self._raw_state()).reshape(-1, 13)
        vel, ang_vel = raw[:, 7:10].copy(), raw[:, 10:13].copy()
        vel[self.fixed] = 0.0
        ang_vel[self.fixed] = 0.0
        return raw[:, 0:3].copy(), from_xyzw(raw[:, 3:7]), vel, ang_vel

    def _apply_loads(self) -> None:
        """The reference's load law (``validation.reference.loads.applied_loads``: springs and
        constant loads) on the state PyBullet holds: each loaded body gets the force at its
        centre of mass and the torque about it (world frame)."""
        pos, quat, vel, ang_vel = self._read_state()
        scene = self.scene
        scene_loads = (scene.springs, scene.moving, scene.force, scene.torque)
        rot = quat_to_matrix(self._body_quat(quat))
        force, torque = applied_loads(*scene_loads, pos, rot, vel, ang_vel)
        for body in np.flatnonzero(self.loaded):
            pybullet.applyExternalForce(
                self.ids[body],
                self.links[body],
                force[body].tolist(),
                pos[body].tolist(),
                pybullet.WORLD_FRAME,
                physicsClientId=self.client,
            )
            pybullet.applyExternalTorque(
                self.ids[body],
                self.links[body],
                torque[body].tolist(),
                pybullet.WORLD_FRAME,
                physicsClientId=self.client,
            )

    def _body_quat(self, inertial_quat: np.ndarray, copies: int = 1) -> np.ndarray:
        """Scene body-frame orientations w x y z of ``copies`` states of the n bodies
        (``inertial_quat (copies * n, 4)``): q_body = q_pybullet ⊗ q_P⁻¹."""
        principal = np.tile(self.principal, (copies, 1))
        quat = quat_multiply(inertial_quat, conjugate(principal))
        fixed = np.tile(self.fixed, copies)
        return np.where(fixed[:, None], np.tile(self.scene_quat, (copies, 1)), quat)

    # -- the protocol ----------------------------------------------------------------------

    def model_report(self) -> ModelReport:
        """The dynamic bodies as PyBullet holds them: ``getDynamicsInfo`` mass and principal
        moments, rotated to world with the base (inertial-frame) orientation, and the base
        pose and velocities; energy and momenta from those readbacks and PyBullet's gravity,
        by the invariants of ``validation.scenario.compiled`` (springs and applied forces: the
        scene's laws). A natively loaded model's bodies: their links' values and inertial
        frames as PyBullet's loader made them (``_held_by_models``)."""
        moving = dynamic_bodies(self.scene)
        pos, quat, vel, ang_vel = self._read_state()
        info = [
            pybullet.getDynamicsInfo(self.ids[i], self.links[i], physicsClientId=self.client)
            for i in moving
        ]
        mass = np.array([item[0] for item in info])
        moments = np.array([item[2] for item in info]).reshape(-1, 3)
        inertial_rot = quat_to_matrix(quat[moving])
        inertia = inertial_rot @ (moments[:, :, None] * inertial_rot.transpose(0, 2, 1))
        self._held_by_models(moving, mass, inertia, pos, quat, vel)
        gravity = np.array(
            [self._engine_parameters()[f"gravityAcceleration{axis}"] for axis in ("X", "Y", "Z")]
        )
        states = [a[moving][None] for a in (pos, vel, ang_vel)]
        body_quat = self._body_quat(quat)[None]
        energy = kinetic_energy(mass, inertia[None], states[1], states[2])
        energy += gravitational_energy(mass, states[0], gravity)
        energy += self.scene.spring_energy(pos[None], body_quat)
        energy += self.scene.applied_force_energy(pos[None])
        return ModelReport(
            mass=mass,
            com=pos[moving],
            inertia_world=inertia,
            energy=float(energy[0]),
            linear_momentum=linear_momentum(mass, states[1])[0],
            angular_momentum=angular_momentum(mass, inertia[None], *states)[0],
        )

    def _held_by_models(self, moving, mass, inertia, pos, quat, vel) -> None:
        """Each natively loaded body's mass, world inertia, centre and its velocity as
        PyBullet holds them (``models.held_inertia``: its link's, in Bullet's inertial frame),
        written into the rows of ``moving`` (``pos``, ``quat``, ``vel``: every body's; a model
        body's ``quat`` is its scene axes). A fixed base is static in PyBullet and holds mass 0
        (measured): its scene mass and inertia stand, at its pose (it never moves)."""
        for row, k in enumerate(moving):
            part = self.parts[k]
            if part is None:
                continue
            if part.welded:
                rot = quat_to_matrix(quat[k])
                mass[row], inertia[row] = self.scene.mass[k], rot @ self.scene.inertia[k] @ rot.T
                continue
            mass[row], pos[k], inertia[row] = models.held_inertia(part, self.client)
            vel[k] = models.inertial_state(part, self.client)[2]

    def advance(self, steps: int) -> None:
        """``steps`` fixed steps: spring forces (if any), then ``stepSimulation``, per step.

        The process-wide contact breaking threshold is set again first: another adapter
        may have changed it since this one loaded, and Bullet reads it whenever a new
        contact manifold is created.
        """
        self._reset_threshold()
        for _ in range(steps):
            self._step()

    def advance_observed(self, steps: int) -> Trajectory:
        """``steps`` steps, PyBullet's raw base states read after each, converted to the
        scene's conventions in one vectorized pass at the end."""
        self._reset_threshold()
        raw = np.empty((steps, len(self.ids), 13))
        for k in range(steps):
            self._step()
            raw[k] = self._raw_state()
        times = (self.steps_taken - steps + 1 + np.arange(steps)) * self.scenario.dt
        return self._states(times, raw)

    def _reset_threshold(self) -> None:
        pybullet.setPhysicsEngineParameter(
            contactBreakingThreshold=self.profile.contact_breaking_threshold,
            physicsClientId=self.client,
        )

    def _step(self) -> None:
        if self.any_loads:
            self._apply_loads()
        pybullet.stepSimulation(physicsClientId=self.client)
        self.steps_taken += 1

    def _raw_state(self) -> list[list[float]]:
        """(n, 13) per body: COM position, inertial-frame quaternion x y z w, velocity, ω
        (world frame); a link's from PyBullet's own kinematics (``_link_state``)."""
        rows = []
        for body, link, part in zip(self.ids, self.links, self.parts, strict=True):
            if part is not None:
                rows.append(models.scene_body_state(part, self.client))
                continue
            if link != BASE:
                rows.append(self._link_state(body, link))
                continue
            position, orientation = pybullet.getBasePositionAndOrientation(
                body, physicsClientId=self.client
            )
            linear, angular = pybullet.getBaseVelocity(body, physicsClientId=self.client)
            rows.append([*position, *orientation, *linear, *angular])
        return rows

    def _link_state(self, body: int, link: int) -> list[float]:
        """A link's 13 numbers from ``getLinkState`` with forward kinematics and velocities
        computed from the multibody's current joint state: ``linkWorldPosition`` and
        ``linkWorldOrientation`` are its inertial frame (the centre of mass with the principal
        axes, as a base's), ``worldLinkLinearVelocity`` the centre's velocity (engines.md 2.5)."""
        state = pybullet.getLinkState(
            body,
            link,
            computeLinkVelocity=1,
            computeForwardKinematics=1,
            physicsClientId=self.client,
        )
        return [*state[0], *state[1], *state[6], *state[7]]

    def _states(self, times: np.ndarray, raw: np.ndarray) -> Trajectory:
        """World COM positions, body-frame quaternions w x y z, COM velocities, world ω of
        ``s`` raw states ``raw (s, n, 13)``; fixed bodies keep the scene's pose, at rest."""
        samples, n = raw.shape[:2]
        pos = raw[..., 0:3].copy()
        inertial = from_xyzw(raw[..., 3:7].reshape(-1, 4))
        quat = self._body_quat(inertial.reshape(samples * n, 4), samples).reshape(samples, n, 4)
        vel, ang_vel = raw[..., 7:10].copy(), raw[..., 10:13].copy()
        pos[:, self.fixed] = np.array([b.position for b in self.scenario.bodies])[self.fixed]
        vel[:, self.fixed] = 0.0
        ang_vel[:, self.fixed] = 0.0
        return Trajectory(times, pos, quat, vel, ang_vel)

    def observe(self) -> Snapshot:
        """World COM positions, body-frame quaternions w x y z, COM velocities, world ω."""
        states = self._states(
            np.array([self.steps_taken * self.scenario.dt]), np.array([self._raw_state()])
        )
        return Snapshot(
            float(states.t[0]),
            *(a[0] for a in (states.pos, states.quat, states.vel, states.ang_vel)),
        )

    def _engine_parameters(self) -> dict[str, object]:
        return dict(pybullet.getPhysicsEngineParameters(physicsClientId=self.client))

    def provenance(self) -> Provenance:
        """PyBullet's version, API and build, its reported parameters and everything set."""
        settings: dict[str, object] = {
            "api_version": pybullet.getAPIVersion(physicsClientId=self.client),
            "engine_parameters": self._engine_parameters(),
            "profile": self.profile_name,
            "bodies": self.bodies_mode,
            "solver_iterations": self.solver_iterations,
            "ground": self._ground_settings(),
            "gyroscopic": GYROSCOPIC_TERM[self.bodies_mode],
            "set_world_parameters": dict(self.world_settings),
            "damping": (
                {"linearDamping": 0.0, "angularDamping": 0.0}
                if self.profile.zero_damping
                else "PyBullet default (multibody 0.04 + 0.04|v|, maximal 0)"
            ),
            "maxJointVelocity": (
                MAX_JOINT_VELOCITY
                if self.profile.lift_velocity_clamp
                else "PyBullet default (multibody ±100 per DOF)"
            ),
            "contact_values": self.contact_values,
            "contact_misses": self.contact_misses,
            "filtered_pairs": self.filtered_pairs,
        }
        settings["model_loader"] = self.model_loader
        settings["urdf_inertia"] = self.urdf_inertia
        if self.trees:
            settings["joint_trees"] = self._tree_settings()
        if self.native:
            settings["models"] = [self._model_settings(model) for model in self.native]
        notes = list(self.notes)
        if self.bodies_mode == "maximal":
            notes.append(
                "maximal bodies: getDynamicsInfo reports no inertial frame (measured: zeros "
                "or stale memory); the principal axes passed at load convert orientations"
            )
        if self.trees:
            notes.append(JOINTS_NOTE)
        if self.native:
            notes.append(MODELS_NOTE)
        return Provenance(
            engine="pybullet",
            version=importlib.metadata.version("pybullet"),
            settings=settings,
            notes=notes,
        )

    def joint_report(self) -> JointReport:
        """The joints PyBullet built, read back at the current state (the parity gate's, at
        t = 0), in the scene's joint order: ``getJointInfo``'s type, its joint point in the
        parent's inertial frame (``parentFramePos``) and its axis in the child's, turned to the
        world by the two frames' poses (``getLinkState``, the base's, or the world's for a tree
        rooted at the world); and M(q0) of the trees (``_mass_matrix``). (A fixed link's
        ``worldLinkFramePosition`` is float32-rounded, 7e-8 of the scene, engines.md 2.5.)
        A natively loaded model's joints: ``models.held_joint``, limits (from t = 0; NaN where
        PyBullet holds none) and damping as ``getJointInfo`` reads what the loader set. This
        adapter's own multibodies: the limits and damping it passed to ``changeDynamics``
        (``_set_limits``, ``_create_tree``), which ``getJointInfo`` does not read back (it
        keeps the values at creation: no limits, damping 0). Armature 0 (Bullet has none)."""
        types, anchors, axes, limits, damping = [], [], [], [], []
        names = [body.name for body in self.scenario.bodies]
        pos, quat, _, _ = self._read_state()
        inertial = quat_to_matrix(quat)
        native = self._native_joints()
        for joint in self.scenario.joints:
            if joint.name in native:
                held = models.held_joint(native[joint.name], self.client)
                types.append(JOINT_WORDS[held.type])
                anchors.append(held.anchor)
                axes.append(held.axis)
                limits.append(held.limits)
                damping.append(held.damping)
                continue
            child, parent = names.index(joint.child), self._parent_body(joint.parent)
            info = pybullet.getJointInfo(
                self.ids[child], self.links[child], physicsClientId=self.client
            )
            origin, frame = (
                (np.zeros(3), np.eye(3)) if parent is None else (pos[parent], inertial[parent])
            )
            types.append(JOINT_WORDS[info[2]])
            anchors.append(origin + frame @ np.asarray(info[14]))
            has_axis = joint.type in ("hinge", "slider")
            axes.append(inertial[child] @ np.asarray(info[13]) if has_axis else np.zeros(3))
            limits.append(np.array(joint.limits if joint.limits else (np.nan, np.nan)))
            damping.append(joint.damping)
        return JointReport(
            tuple(types),
            np.array(anchors),
            np.array(axes),
            self._mass_matrix(),
            limits=np.array(limits).reshape(-1, 2),
            damping=np.array(damping),
            armature=np.zeros(len(types)),
        )

    def _native_joints(self) -> dict[str, models.FileJoint]:
        """Every natively loaded model's scene joints."""
        return {name: joint for model in self.native for name, joint in model.joints.items()}

    def _coordinates(self) -> list[Coordinate]:
        """The tree's coordinates as PyBullet's joint coordinates: every natively loaded
        model joint with coordinates, and every hinge and slider of this adapter's own
        multibodies (their coordinate 0 is the scene's t = 0). ValueError for a coordinate of
        any other kind (a ball, a floating body or base)."""
        tree = self.scene.joint_tree
        held = dict(self._native_joints())
        for plan in self.trees:
            for link in plan.links:
                held[link.joint] = models.FileJoint(self.ids[link.body], self.links[link.body], 0.0)
        coordinates = []
        for joint in tree.joints:
            if joint.type == "fixed":
                continue
            if joint.type not in ("hinge", "slider") or joint.name not in held:
                raise ValueError(
                    f"joint {joint.name!r} ({joint.type}): the PyBullet adapter probes only "
                    "hinges and sliders of fixed-base multibodies"
                )
            at = held[joint.name]
            coordinates.append(
                Coordinate(at.body, at.index, at.initial, joint.q_slice.start, joint.v_slice.start)
            )
        return coordinates

    def _dynamics(
        self, coordinates: list[Coordinate], q: np.ndarray, nu: np.ndarray
    ) -> tuple[np.ndarray, np.ndarray]:
        """M and the bias C(q, ν)ν + g(q) over ``coordinates`` at the tree state (q, ν), as
        (nv, nv) and (nv,) in the tree's coordinates (rows of other coordinates 0): per
        multibody ``calculateMassMatrix`` and ``calculateInverseDynamics`` with zero
        accelerations, at the file's coordinates (q plus each joint's initial value), rows in
        PyBullet's order of its movable joints."""
        nv = self.scene.joint_tree.nv
        matrix, bias = np.zeros((nv, nv)), np.zeros(nv)
        for body in dict.fromkeys(c.body for c in coordinates):
            mine = {c.index: c for c in coordinates if c.body == body}
            order = models.movable_joints(body, self.client)
            if set(order) != set(mine):
                raise ValueError(f"multibody {body}: a movable joint holds no scene coordinate")
            rows = [mine[j] for j in order]
            positions = [c.initial + float(q[c.q]) for c in rows]
            velocities = [float(nu[c.v]) for c in rows]
            at = [c.v for c in rows]
            matrix[np.ix_(at, at)] = pybullet.calculateMassMatrix(
                body, positions, physicsClientId=self.client
            )
            with self._gravity_in_base_frame(body):
                bias[at] = pybullet.calculateInverseDynamics(
                    body, positions, velocities, [0.0] * len(rows), physicsClientId=self.client
                )
        return matrix, bias

    @contextmanager
    def _gravity_in_base_frame(self, body: int):
        """The world's gravity turned into the fixed base's frame meanwhile (``R_baseᵀ g``):
        ``calculateInverseDynamics`` puts a fixed base at the world's axes, whatever its
        orientation (docs/engines.md 2.6: a Kuka turned 0.6 rad about x got its upright
        gravity torques), so gravity is handed to it in the frame it assumes."""
        rotation = quat_to_matrix(
            from_xyzw(pybullet.getBasePositionAndOrientation(body, physicsClientId=self.client)[1])
        )
        gravity = np.asarray(self.scenario.gravity, dtype=float)
        pybullet.setGravity(*(rotation.T @ gravity), physicsClientId=self.client)
        try:
            yield
        finally:
            pybullet.setGravity(*gravity, physicsClientId=self.client)

    def model_probe(self, q: np.ndarray, nu: np.ndarray) -> ModelProbe:
        """The scene's multibodies at the tree state (q, ν) (``CompiledScene.joint_tree``'s
        coordinates, relative to t = 0) without stepping: every joint coordinate set with
        ``resetJointState`` (``_coordinates``), the bodies read back as ``observe`` reads them
        (``getLinkState`` with forward kinematics), M and the bias from PyBullet's own
        ``calculateMassMatrix`` and ``calculateInverseDynamics`` (``_dynamics``: Bullet's
        inverse dynamics leaves joint damping out, as the tree's bias does; springs and
        applied loads are not in it). ValueError for a scene with a ball joint or a floating
        body or base."""
        coordinates = self._coordinates()
        for c in coordinates:
            pybullet.resetJointState(
                c.body,
                c.index,
                targetValue=c.initial + float(q[c.q]),
                targetVelocity=float(nu[c.v]),
                physicsClientId=self.client,
            )
        state = self.observe()
        matrix, bias = self._dynamics(coordinates, q, nu)
        return ModelProbe(state.pos, state.quat, matrix, bias)

    def _parent_body(self, name: str) -> int | None:
        """The scene index of a joint's parent body; None for the world."""
        names = [body.name for body in self.scenario.bodies]
        return names.index(name) if name in names else None

    def _mass_matrix(self) -> np.ndarray:
        """M(q0) in the joint tree's coordinates (``CompiledScene.joint_tree``'s ν) as
        PyBullet's forward dynamics holds it: the kinetic energy's matrix Σ Jᵀ diag(m, I) J of
        the trees' bodies as PyBullet moves them (``_tree_jacobian``, each body's mass and
        principal moments from ``getDynamicsInfo`` in its inertial frame), a ball's coordinates
        (its spin relative to its parent in the child's inertial frame) carried to the tree's
        (the parent's frame); a free body in no tree adds its mass and world inertia. Read at
        load (the parity gate's t = 0: the probing restores the velocities set then).
        ``calculateMassMatrix`` is not used: it drops a ball joint's child offset from the
        joints above it (engines.md 2.5)."""
        tree = self.scene.joint_tree
        matrix = np.zeros((tree.nv, tree.nv))
        quat = self._read_state()[1]
        inertial = quat_to_matrix(quat)
        slices = {joint.child: joint.v_slice for joint in tree.joints}
        in_trees = {body for plan in self.trees for body in plan.bodies}
        in_trees |= {k for k, part in enumerate(self.parts) if part is not None}  # a model's
        for root in [j.child for j in tree.joints if j.type == "free" and j.child not in in_trees]:
            mass, world = self._world_inertia(root, inertial)
            block = np.block([[mass * np.eye(3), np.zeros((3, 3))], [np.zeros((3, 3)), world]])
            matrix[slices[root], slices[root]] = block
        moving, jacobian = self._tree_jacobian()
        self._set_tree_velocities(self.tree_velocities)
        own = np.zeros((jacobian.shape[1], jacobian.shape[1]))
        for k, body in enumerate(moving):
            mass, world = self._world_inertia(body, inertial)
            linear, angular = jacobian[6 * k : 6 * k + 3], jacobian[6 * k + 3 : 6 * k + 6]
            own += mass * linear.T @ linear + angular.T @ world @ angular
        change = self._tree_coordinates(inertial, quat_to_matrix(self._body_quat(quat)))
        return matrix + change.T @ own @ change + self._loaded_mass_matrix()

    def _loaded_mass_matrix(self) -> np.ndarray:
        """M(q0) of the natively loaded models in the tree's coordinates, as PyBullet moves
        and holds them: Σ Jᵀ diag(m, I) J over their bodies (``models.held_inertia``), each
        column of J the bodies' centre velocities and ω (``models.inertial_state``) with one
        coordinate at 1 (``_set_loaded_velocities``). The velocities are restored after."""
        tree = self.scene.joint_tree
        matrix = np.zeros((tree.nv, tree.nv))
        parts = [part for part in self.parts if part is not None and not part.welded]
        if not parts:
            return matrix
        now = self._set_loaded_velocities(None)
        columns = []
        for column in np.eye(tree.nv):
            self._set_loaded_velocities(column)
            motion = [models.inertial_state(part, self.client)[2:] for part in parts]
            columns.append(np.concatenate([np.concatenate(m) for m in motion]))
        self._set_loaded_velocities(now)
        jacobian = np.array(columns).T
        for k, part in enumerate(parts):
            mass, _, world = models.held_inertia(part, self.client)
            linear, angular = jacobian[6 * k : 6 * k + 3], jacobian[6 * k + 3 : 6 * k + 6]
            matrix += mass * linear.T @ linear + angular.T @ world @ angular
        return matrix

    def _set_loaded_velocities(self, nu: np.ndarray | None) -> np.ndarray:
        """The natively loaded models' velocities set from a tree ν (each joint's rate at its
        current position by ``resetJointState``; a floating base's v and ω, world frame, the
        tree's free coordinates, by ``resetBaseVelocity``); None sets nothing. Returns the
        tree ν they held before (other coordinates 0)."""
        tree = self.scene.joint_tree
        native = self._native_joints()
        before = np.zeros(tree.nv)
        for joint in tree.joints:
            at, part = joint.v_slice.start, self.parts[joint.child]
            if joint.name in native and joint.type in ("hinge", "slider"):
                held = native[joint.name]
                position, before[at] = pybullet.getJointState(
                    held.body, held.index, physicsClientId=self.client
                )[:2]
                if nu is not None:
                    pybullet.resetJointState(
                        held.body, held.index, position, float(nu[at]), physicsClientId=self.client
                    )
            elif joint.type == "free" and part is not None:
                linear, angular = pybullet.getBaseVelocity(part.body, physicsClientId=self.client)
                before[at : at + 6] = [*linear, *angular]
                if nu is not None:
                    pybullet.resetBaseVelocity(
                        part.body,
                        nu[at : at + 3].tolist(),
                        nu[at + 3 : at + 6].tolist(),
                        physicsClientId=self.client,
                    )
        return before

    def _world_inertia(self, body: int, inertial: np.ndarray) -> tuple[float, np.ndarray]:
        """A body's mass and world inertia as PyBullet holds them (``getDynamicsInfo``)."""
        info = pybullet.getDynamicsInfo(
            self.ids[body], self.links[body], physicsClientId=self.client
        )
        return info[0], inertial[body] @ np.diag(info[2]) @ inertial[body].T

    def _tree_coordinates(self, inertial: np.ndarray, body_rot: np.ndarray) -> np.ndarray:
        """T (the trees' velocity coordinates, the tree's ν): a floating base's (v, ω) and a
        hinge's or slider's rate as they are; a ball's parent-frame spin into its child's
        inertial frame, ``R_Cᵀ R_P``."""
        tree = self.scene.joint_tree
        slices = {joint.child: joint.v_slice for joint in tree.joints}
        change = np.zeros((sum(self._velocity_sizes()), tree.nv))
        at = 0
        for plan in self.trees:
            if plan.root != WORLD and not self.scenario.bodies[plan.root].fixed:
                change[at : at + FLOATING_BASE_DOFS, slices[plan.root]] = np.eye(6)
                at += FLOATING_BASE_DOFS
            for link in plan.links:
                size = JOINT_DOFS[link.type]
                block = np.eye(size)
                if link.type == "ball":
                    parent = plan.root if link.parent == BASE else plan.links[link.parent].body
                    turn = np.eye(3) if parent == WORLD else body_rot[parent]
                    block = inertial[link.body].T @ turn
                change[at : at + size, slices[link.body]] = block
                at += size
        return change

    def _model_settings(self, model: models.NativeModel) -> dict[str, object]:
        """A natively loaded model (provenance): its file, PyBullet's loader and flags, and
        the loader's bodies removed (``models._world_geoms``)."""
        layout = model.layout
        from_file = layout.format == "urdf" and self.urdf_inertia == "file"
        return {
            "model": layout.name,
            "file": str(layout.path),
            "loader": models.LOADERS[layout.format],
            "flags": "URDF_USE_INERTIA_FROM_FILE" if from_file else "none",
            "useFixedBase": bool(layout.spec.fixed_base),
            "collisions": bool(layout.spec.collisions),
            "removed_bodies": list(model.removed),
        }

    def _tree_settings(self) -> list[dict[str, object]]:
        """Each multibody (provenance): its base and each link's body, joint, parent, damping
        and limits."""
        names = [body.name for body in self.scenario.bodies]
        limits = {joint.name: joint.limits for joint in self.scenario.joints}
        return [
            {
                "base": "world" if tree.root == WORLD else names[tree.root],
                "links": [
                    {"body": names[link.body], "joint": link.joint, "type": link.type,
                     "parent_link": link.parent, "jointDamping": link.damping,
                     "limits": limits[link.joint]}
                    for link in tree.links
                ],
            }
            for tree in self.trees
        ]  # fmt: skip

    def close(self) -> None:
        """Disconnect this adapter's client (idempotent)."""
        if self.client is not None:
            pybullet.disconnect(physicsClientId=self.client)
            self.client = None

    def __enter__(self) -> PybulletAdapter:
        return self

    def __exit__(self, *exc) -> None:
        self.close()
