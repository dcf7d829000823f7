"""Rapier's declaration, as data: what the adapter offers and needs, without importing rapier3d.

``physval list``, spec parsing and the install hint read this module; only
``validation.engines.rapier.adapter`` imports the engine. The fields map one to one onto the
public declaration of an engine (name, distribution, summary, options with their meaning and
default, capabilities: shapes, features, integrators, precision).
"""

from __future__ import annotations

from dataclasses import dataclass, replace

from validation.engine_api import (
    API_VERSION,
    JOINT_FEATURES,
    MODEL_FEATURES,
    Capabilities,
    Count,
    EngineDeclaration,
    EngineOption,
)

NAME = "rapier"
"""The engine's spec name."""

DISTRIBUTION = "rapier3d"
"""The PyPI distribution (and its import name) whose version is the engine's version."""

ADAPTER = "validation.engines.rapier.adapter:RapierAdapter"
"""``module:Class`` of the adapter, imported on first use."""

INSTALL_HINT = 'pip install "physval[rapier]"'
"""What to run when ``rapier3d`` is missing (the optional extra of pyproject.toml)."""

SUMMARY = "Rapier (rapier3d), impulse-based with soft contacts and substeps, float32"

PRECISION = "float32"
"""Rapier's Python bindings are built on the f32 crate: every position, velocity, mass and
inertia is a 32-bit float (machine epsilon 1.19e-7), dt included (1e-3 s is stored as
0.0010000000475). The parity gate takes the float32 tolerance, and the provenance says so."""

SHAPES = ("sphere", "box", "capsule", "cylinder")
"""Every scene shape: ``Collider.ball``, ``Collider.cuboid`` (half-extents), ``Collider.capsule_z``
(half-height of the cylinder along body z, as the scene's ``half_length``), ``Collider.cylinder``
(half-height and radius; Rapier's axis is y, turned onto the shape's z), each at the shape's
offset and orientation relative to its rigid body (``placed_shapes``)."""

FEATURES = (
    "ground",
    "tilted_ground",
    "contacts",
    "fixed_bodies",
    "springs",
    "loads",
    "restitution",
    "friction",
    *JOINT_FEATURES,
    *MODEL_FEATURES,
)
"""Every scene feature: the ground is a fixed ``halfspace`` collider (any normal), fixed bodies
are ``RigidBody.fixed()``, constant loads are Rapier's persistent user force and torque,
springs are forces applied before every step from the reference's load law, restitution and
friction are per-collider with per-pair combine rules, and a scene's ``pairs:`` overrides
are set on the contact by a ``modify_solver_contacts`` hook; joints (hinge, slider, ball,
fixed) are Rapier ``GenericJoint``s, multibody (reduced coordinates) or impulse joints by the
``joints`` option, their limits Rapier's joint limits on the free axis
(``validation.engines.rapier.joints``)."""

INTEGRATORS = ("symplectic_euler_substeps",)
"""Rapier's only time integration: ``num_solver_iterations`` substeps of dt/k per step, each a
symplectic (semi-implicit) Euler step of the velocity then the position (measured: a body
falling 1 s at dt = 1e-3 drops 4.906228 m, 4.905 + g·t·(dt/4)/2 with k = 4)."""


@dataclass(frozen=True)
class Profile:
    """How one profile sets Rapier up; each field is one option's default."""

    gyroscopic: str
    """``on``: the body's gyroscopic term ω × Iω is integrated; ``off``: dropped."""
    ccd: str
    """``on``: continuous collision detection on every moving body (no tunnelling)."""
    friction_model: str
    """``simplified``: one friction constraint per manifold of up to four points plus a twist
    constraint (Rapier's default); ``coulomb``: one per contact point."""
    combine: str
    """``scene``: the scene's pair rules (restitution by max, friction by geometric mean, and
    its ``pairs:`` overrides); ``rapier``: Rapier's own (the average of the two colliders')."""
    sleeping: bool
    """Whether bodies may fall asleep (a sleeping body is no longer integrated)."""
    prediction_distance: float | None
    """m, ``IntegrationParameters.normalized_prediction_distance`` (length unit 1 m): how far
    apart two shapes get a (speculative) contact; None keeps Rapier's 0.02."""


MATCHED_PREDICTION_DISTANCE = 1e-6
"""m. Rapier's speculative contacts (default band 0.02 m) stop an approaching body the step
before it would touch: a sphere dropped from 1 m rebounds with e = 0.5 exactly but from 5.1 mm
above the ground (measured), an impulse at a distance that the scene's rigid contact does not
have, and that the harness, which sees an impact when shapes touch within its detection gap
(``validation.measure.recording.DETECTION_GAP``, 1e-6 m), reads as "no impact". With the band
at that gap the contact acts when the shapes touch or overlap: the same drop penetrates
3.6 mm (v·dt) and rebounds with e = 0.5 exactly, from 0.1 mm to 3 m (measured); a body at rest
sinks the same 68 µm either way (Rapier's allowed linear error). PyBullet's matched profile
removes Bullet's speculative band for the same reason (``MATCHED_CONTACT_BREAKING_THRESHOLD``)."""


PROFILES: dict[str, Profile] = {
    # matched: Rapier set up to integrate the scene's model.
    #  - gyroscopic on: the scene's rigid bodies obey Euler's equations, gyroscopic term included
    #    (Rapier's default too; off conserves energy but not the direction of L).
    #  - ccd on: the scene's bodies never pass through each other; CCD only acts on a body
    #    that would cross a collider within a step, so it changes no bounce that the
    #    speculative contact already catches (measured: the 1 m drop's rebound bit-identical).
    #  - friction_model simplified (Rapier's default): one friction constraint per manifold of
    #    up to four points plus a twist constraint. Measured against the per-point COULOMB
    #    model on the library: a 0.4 x 0.4 x 0.1 m box sliding at 1 m/s with μ = 0.2
    #    (box_slide_stop) decelerates at μg exactly under SIMPLIFIED (v = 0.5095 m/s at 0.25 s,
    #    the closed form) and at 0.87 μg under COULOMB (0.5721 m/s); on the eight frictional
    #    scenes SIMPLIFIED passed 31 rows and COULOMB 24, and no row was better under COULOMB.
    #  - combine scene: the pair rules of validation.scenario.physics.PAIR_RULES exactly
    #    (CoefficientCombineRule.MAX and GEOMETRIC_MEAN on every collider; pairs: by hook).
    #  - no sleeping: a body at rest keeps being integrated, as in every other engine.
    #  - prediction distance MATCHED_PREDICTION_DISTANCE: contacts act on touching shapes.
    # The solver iterations (substeps) stay at Rapier's 4 unless the spec says otherwise:
    # they are the integration's substeps, not a tolerance of the contact solve.
    "matched": Profile(
        gyroscopic="on",
        ccd="on",
        friction_model="simplified",
        combine="scene",
        sleeping=False,
        prediction_distance=MATCHED_PREDICTION_DISTANCE,
    ),
    # defaults: what a new user gets: Rapier's own settings, with the scene's masses,
    # inertias, shapes, gravity, dt and per-body contact values (combined by Rapier's
    # AVERAGE rule, so a pair's value is not the scene's where the two bodies' differ).
    "defaults": Profile(
        gyroscopic="on",
        ccd="off",
        friction_model="simplified",
        combine="rapier",
        sleeping=True,
        prediction_distance=None,
    ),
}

SOLVER_ITERATIONS_EXAMPLE = 8
"""A solver_iterations value other than Rapier's 4, for the conformance suite's provenance check."""

JOINT_KINDS = ("multibody", "impulse")
"""Rapier's two joint sets: ``multibody``: reduced coordinates (``MultibodyJointSet``, a
Featherstone articulation whose damping is its own per coordinate); ``impulse``: constraints
between free rigid bodies (``ImpulseJointSet``, solved with the contacts, a joint's damping a
force-based velocity motor of target 0)."""

DEFAULT_JOINTS = "multibody"
"""Both profiles build multibody joints unless the spec says ``joints=impulse``: measured
(engines-rapier.md 9), a multibody keeps a pendulum's energy to 3e-7 over a period and its
hinges and sliders to float32 (its ball joints drift 8e-5 m in 1 s), where impulse joints lose
0.16 % of the energy per period in Rapier's stabilization pass."""

OPTIONS = (
    EngineOption(
        "profile",
        str,
        "matched: set up to integrate the scene's model; "
        "defaults: what a new user gets (default matched)",
        ("matched", "defaults"),
        "matched",
    ),
    EngineOption(
        "gyroscopic", str, "RigidBody gyroscopic_forces; unset: the profile's (on)", ("on", "off")
    ),
    EngineOption(
        "ccd",
        str,
        "continuous collision detection on moving bodies; unset: on when matched, off for defaults",
        ("on", "off"),
    ),
    EngineOption(
        "friction_model",
        str,
        "IntegrationParameters.friction_model; unset: simplified (per manifold, Rapier's "
        "default); coulomb: one constraint per contact point",
        ("simplified", "coulomb"),
    ),
    EngineOption(
        "solver_iterations",
        Count,
        "IntegrationParameters.num_solver_iterations (substeps per step); unset: Rapier's 4",
        example=SOLVER_ITERATIONS_EXAMPLE,
    ),
    EngineOption(
        "joints",
        str,
        "the Rapier joints a scene's joints become: multibody (reduced coordinates, "
        "MultibodyJointSet) or impulse (constraints, ImpulseJointSet) (default multibody)",
        JOINT_KINDS,
        DEFAULT_JOINTS,
    ),
)
"""The settings a Rapier spec may carry; unset ones take the profile's value (``PROFILES``)."""


RAPIER_SUBSTEPS = 4
"""``IntegrationParameters.num_solver_iterations``'s default: substeps per step (engines-rapier.md 3)."""

CAPABILITIES = Capabilities(
    shapes=SHAPES,
    features=frozenset(FEATURES),
    integrators=INTEGRATORS,
    precision=PRECISION,
    substeps=RAPIER_SUBSTEPS,
)
"""What every Rapier spec represents; only the substep count depends on the settings."""


def capabilities_for(settings: dict[str, object]) -> Capabilities:
    """The capabilities of a spec: ``solver_iterations`` substeps per step (Rapier's 4 unset)."""
    substeps = settings.get("solver_iterations", RAPIER_SUBSTEPS)
    return replace(CAPABILITIES, substeps=int(substeps))  # type: ignore[call-overload]


DECLARATION = EngineDeclaration(
    name=NAME,
    api_version=API_VERSION,
    adapter=ADAPTER,
    distribution=DISTRIBUTION,
    summary=SUMMARY,
    options=OPTIONS,
    capabilities=CAPABILITIES,
    capabilities_for=capabilities_for,
    requires=(DISTRIBUTION,),
    install=INSTALL_HINT,
)
"""Rapier as the adapter contract declares an engine (an entry point of ``physval.engines``)."""
