"""The scenario format (version 1): schema, loader, and problems that name file, line and field.

A scenario is a YAML file; SI units, world frame, z up, quaternions w x y z.
``load_scenario(path)`` returns a frozen, validated ``Scenario`` with every default
filled in, or raises ``ScenarioError`` carrying *every* problem found, each as
``file:line:column: field.path: what was expected; what was found``.

Schema: pydantic models (``extra="forbid"``, numbers strict and finite), so the
JSON Schema that editors use (``physval schema``) comes from the same source as the
loader. Checks that need the whole document (unique names, references between
fields, engine specs, step limits) run after the schema and report in the same form.
"""

from __future__ import annotations

import math
from functools import cached_property
from typing import Annotated, Any, Literal

import numpy as np
from pydantic import (
    AllowInfNan,
    BaseModel,
    ConfigDict,
    Field,
    Strict,
    field_validator,
    model_validator,
)

from validation.scenario.engine_spec import (
    DEFAULT_ENGINES,
    EngineSpec,
    parse_engine_spec,
)

FORMAT_VERSION = 1

MAX_STEPS = 5_000_000
"""Largest duration / dt a scenario may ask for: 50 s at dt = 1e-5, or about an hour of
mini_engine time for a one-body scene. Longer runs are a typo (dt: 1e-7) more often than not."""

UNIT_QUATERNION_TOLERANCE = 1e-6
"""An orientation within this of unit norm is normalised (further off is refused): the format's
own rule, not taken from an engine (the scene side never imports mini_engine, whose model builder
must accept at least as much: ``tests/test_architecture.py``)."""

SYMMETRY_TOLERANCE = 1e-9
"""Relative. An inertia within this of symmetric is symmetrised (further off is refused); the
same contract with mini_engine's model builder as ``UNIT_QUATERNION_TOLERANCE``."""

METRIC_NAMES = (
    "energy_drift",
    "angular_momentum_drift",
    "linear_momentum_drift",
    "position_error",
    "velocity_error",
    "restitution_error",
    "penetration_max",
    "joint_violation",
    "divergence",
    "model_fields",
    "fk_error",
    "mass_matrix_error",
    "bias_force_error",
    "joint_divergence",
    "agreement_time",
)
"""The metrics a ``checks`` entry may name besides the scene's own expectations (CI jobs and scene files use these names)."""

# --- field types -------------------------------------------------------------------------

Finite = Annotated[float, Strict(), AllowInfNan(False)]
Positive = Annotated[float, Strict(), AllowInfNan(False), Field(gt=0)]
NonNegative = Annotated[float, Strict(), AllowInfNan(False), Field(ge=0)]
UnitInterval = Annotated[float, Strict(), AllowInfNan(False), Field(ge=0, le=1)]
Vec3 = tuple[Finite, Finite, Finite]
PositiveVec3 = tuple[Positive, Positive, Positive]
Word = Annotated[str, Strict(), Field(min_length=1, pattern=r"^[A-Za-z0-9_.\-]+$")]
"""A scene's or model's name: letters, digits, ``_ . -``."""
Name = Annotated[
    str, Strict(), Field(min_length=1, pattern=r"^[A-Za-z0-9_.\-]+(/[A-Za-z0-9_.\-]+)?$")
]
"""A body's or joint's name: a ``Word``, or ``<model>/<word>`` for a model's (``ModelSpec``)."""


class _Strict(BaseModel):
    model_config = ConfigDict(extra="forbid", frozen=True)


IDENTITY_QUATERNION = (1.0, 0.0, 0.0, 0.0)


class _PlacedShape(_Strict):
    """Where a shape sits in its body: by default centred on the centre of mass, its axes the
    body's. A shape placed elsewhere needs the body's ``inertia`` stated (the solid shape's
    own would be about another point): a robot link's collision shape, for instance."""

    offset: Vec3 = Field(
        default=(0.0, 0.0, 0.0), description="m, the shape's centre in the body frame"
    )
    orientation: tuple[Finite, Finite, Finite, Finite] = Field(
        default=IDENTITY_QUATERNION,
        description="unit quaternion w x y z, the shape's axes to the body's",
    )

    @field_validator("orientation")
    @classmethod
    def _unit_quaternion(cls, value: tuple[float, ...]) -> tuple[float, ...]:
        return _unit(value)

    @property
    def placed(self) -> bool:
        """Whether the shape sits away from the centre of mass or turned from the body axes."""
        return any(self.offset) or tuple(self.orientation) != IDENTITY_QUATERNION


class SphereShape(_PlacedShape):
    """A solid sphere."""

    type: Literal["sphere"]
    radius: Positive = Field(description="m")


class BoxShape(_PlacedShape):
    """A solid box; half extents along the shape's axes (the body's by default)."""

    type: Literal["box"]
    half_extents: PositiveVec3 = Field(description="m, (hx, hy, hz)")


class CapsuleShape(_PlacedShape):
    """A solid capsule along the shape's z: a cylinder of 2*half_length plus two hemispheres."""

    type: Literal["capsule"]
    radius: Positive = Field(description="m")
    half_length: Positive = Field(description="m, half the cylinder's length")


class CylinderShape(_PlacedShape):
    """A solid cylinder along the shape's z, flat ends: length 2*half_length."""

    type: Literal["cylinder"]
    radius: Positive = Field(description="m")
    half_length: Positive = Field(description="m, half the cylinder's length")


ShapeSpec = Annotated[
    SphereShape | BoxShape | CapsuleShape | CylinderShape, Field(discriminator="type")
]


def _unit(value: tuple[float, ...]) -> tuple[float, ...]:
    """A quaternion normalised, or ValueError when it is not near unit length."""
    norm = math.sqrt(sum(v * v for v in value))
    if abs(norm - 1.0) > UNIT_QUATERNION_TOLERANCE:
        raise ValueError(
            f"expected a unit quaternion w x y z (norm within {UNIT_QUATERNION_TOLERANCE} of 1); "
            f"got norm {norm:.9g}"
        )
    return tuple(v / norm for v in value)


def _inertia_matrix(value: Any) -> np.ndarray:
    """3 principal moments or a symmetric 3x3 -> (3, 3), or ValueError saying what was expected."""
    expected = "3 positive moments [Ixx, Iyy, Izz] or a symmetric 3x3 matrix, kg·m²"
    try:
        array = np.asarray(value, dtype=float)
    except (TypeError, ValueError):
        raise ValueError(f"expected {expected}; got {value!r}") from None
    if any(isinstance(v, bool | str) for v in np.asarray(value, dtype=object).ravel()):
        raise ValueError(f"expected {expected}; got {value!r}")
    if array.shape == (3,):
        array = np.diag(array)
    if array.shape != (3, 3) or not np.isfinite(array).all():
        raise ValueError(f"expected {expected}; got {value!r}")
    if np.abs(array - array.T).max() > SYMMETRY_TOLERANCE * np.abs(array).max():
        raise ValueError(f"expected a symmetric matrix; got {array.tolist()}")
    array = 0.5 * (array + array.T)  # the accepted round-off asymmetry removed, once, here
    moments = np.linalg.eigvalsh(array)
    if moments.min() <= 0:
        raise ValueError(
            f"expected positive definite (principal moments > 0); got {moments.tolist()}"
        )
    a, b, c = sorted(moments)
    if a + b < c * (1 - SYMMETRY_TOLERANCE):
        raise ValueError(
            f"principal moments {moments.tolist()} break the triangle inequality "
            "(A + B >= C): no rigid body has them"
        )
    return array


class BodySpec(_Strict):
    """One rigid body."""

    name: Name = Field(description="unique in the scene")
    shape: ShapeSpec
    mass: Positive = Field(description="kg")
    inertia: list[Any] | None = Field(
        default=None,
        description="kg·m², body frame about the centre of mass: [Ixx, Iyy, Izz] or a full 3x3; "
        "default: the solid shape",
    )
    position: Vec3 = Field(default=(0.0, 0.0, 0.0), description="m, world frame, centre of mass")
    orientation: tuple[Finite, Finite, Finite, Finite] = Field(
        default=(1.0, 0.0, 0.0, 0.0), description="unit quaternion w x y z, body to world"
    )
    velocity: Vec3 = Field(default=(0.0, 0.0, 0.0), description="m/s, world frame, centre of mass")
    angular_velocity: Vec3 = Field(default=(0.0, 0.0, 0.0), description="rad/s, world frame")
    force: Vec3 = Field(
        default=(0.0, 0.0, 0.0),
        description="N, world frame: a constant applied force at the centre of mass",
    )
    torque: Vec3 = Field(
        default=(0.0, 0.0, 0.0), description="N·m, world frame: a constant applied torque"
    )
    restitution: UnitInterval = 0.0
    friction: NonNegative = Field(default=0.0, description="Coulomb μ; 0 is frictionless")
    fixed: Annotated[bool, Strict()] = Field(default=False, description="a static body")
    collides: Annotated[bool, Strict()] = Field(
        default=True,
        description="false: the body takes part in no contact (its shape still gives its "
        "size); a model's links when the model has collisions: false",
    )

    @field_validator("inertia")
    @classmethod
    def _check_inertia(cls, value: list[Any] | None) -> list[Any] | None:
        if value is not None:
            _inertia_matrix(value)
        return value

    @field_validator("orientation")
    @classmethod
    def _unit_quaternion(cls, value: tuple[float, ...]) -> tuple[float, ...]:
        return _unit(value)

    @model_validator(mode="after")
    def _placed_shape_states_inertia(self) -> BodySpec:
        if self.shape.placed and self.inertia is None:
            raise ValueError(
                "expected an inertia: a shape placed off the centre of mass (offset, "
                "orientation) gives no solid inertia about it"
            )
        return self

    @cached_property
    def inertia_matrix(self) -> np.ndarray | None:
        """(3, 3) kg·m² body frame, or None for the solid shape's."""
        return None if self.inertia is None else _inertia_matrix(self.inertia)


MIN_GROUND_NORMAL = 1e-9
"""Shortest ``ground.normal`` accepted (it is normalised): below this the direction is round-off."""


class GroundSpec(_Strict):
    """A static infinite plane through ``point`` with unit normal ``normal`` (the solid side
    below it); default the plane z = 0 with normal +z."""

    normal: Vec3 = Field(
        default=(0.0, 0.0, 1.0),
        description="the plane's outward normal, world frame (normalised; any length > 0)",
    )
    point: Vec3 = Field(default=(0.0, 0.0, 0.0), description="m, world frame, a point on the plane")
    restitution: UnitInterval = 0.0
    friction: NonNegative = 0.0

    @field_validator("normal")
    @classmethod
    def _unit_normal(cls, value: tuple[float, ...]) -> tuple[float, ...]:
        norm = math.sqrt(sum(v * v for v in value))
        if not norm > MIN_GROUND_NORMAL:
            raise ValueError(f"expected a non-zero direction [nx, ny, nz]; got {list(value)}")
        return tuple(v / norm for v in value)


class SpringSpec(_Strict):
    """A linear spring-damper between two bodies, or a body and a world point."""

    a: Name = Field(description="a body name")
    b: Name = Field(description="a body name, or 'world'")
    anchor_a: Vec3 = Field(default=(0.0, 0.0, 0.0), description="m, in a's body frame")
    anchor_b: Vec3 = Field(
        default=(0.0, 0.0, 0.0), description="m, in b's body frame (world: a point)"
    )
    stiffness: NonNegative = Field(description="N/m")
    damping: NonNegative = Field(default=0.0, description="N·s/m")
    rest_length: NonNegative | None = Field(
        default=None,
        description="m; default: the anchors' distance at t = 0 (the spring starts at rest)",
    )


AXIS_JOINT_TYPES = ("hinge", "slider")
"""Joint types with an axis, one coordinate (whose ``period`` is defined) and optional limits;
the others of ``JointSpec.type`` are ball and fixed."""

UNIT_AXIS_TOLERANCE = UNIT_QUATERNION_TOLERANCE
"""A joint axis within this of unit length is normalised; further away it is an error (a typo,
not round-off), as for quaternions."""


class JointSpec(_Strict):
    """A joint between a parent (a body or the world) and a child body, stated at t = 0."""

    name: Name = Field(description="unique among joints")
    type: Literal["hinge", "slider", "ball", "fixed"]
    parent: Name = Field(description="a body name, or 'world'")
    child: Name = Field(description="a body name; each body is the child of at most one joint")
    anchor: Vec3 = Field(description="m, world frame, at t = 0 (a point of both bodies)")
    axis: Vec3 | None = Field(
        default=None, description="hinge and slider: unit axis, world frame at t = 0"
    )
    damping: NonNegative = Field(
        default=0.0, description="N·m·s/rad (hinge, ball) or N·s/m (slider)"
    )
    limits: tuple[Finite, Finite] | None = Field(
        default=None,
        description="hinge and slider: [lower, upper] rad or m from the initial configuration",
    )

    @field_validator("axis")
    @classmethod
    def _unit_axis(cls, value: tuple[float, ...] | None) -> tuple[float, ...] | None:
        if value is None:
            return None
        norm = math.sqrt(sum(v * v for v in value))
        if abs(norm - 1.0) > UNIT_AXIS_TOLERANCE:
            raise ValueError(
                f"expected a unit axis [x, y, z]; got {list(value)} (length {norm:.6g})"
            )
        return tuple(v / norm for v in value)

    @field_validator("limits")
    @classmethod
    def _limits_bracket_zero(cls, value: tuple[float, float] | None) -> tuple[float, float] | None:
        if value is not None and not (value[0] <= 0.0 <= value[1] and value[0] < value[1]):
            raise ValueError(
                f"expected [lower, upper] with lower <= 0 <= upper and lower < upper (the joint "
                f"starts at 0, inside them); got {list(value)}"
            )
        return value


class ModelSpec(_Strict):
    """A robot model read from a URDF or MJCF file and expanded, at load, into the scene's
    bodies and joints (``validation/scenario/urdf.py``), each named ``<name>/<link or joint>``."""

    name: Word = Field(description="the prefix of its bodies and joints: arm/link3, arm/joint2")
    file: Annotated[str, Strict(), Field(min_length=1)] = Field(
        description="a URDF (.urdf) or MJCF (.xml): a path relative to the scene, or "
        "pkg:PACKAGE/path inside an installed Python package"
    )
    position: Vec3 = Field(default=(0.0, 0.0, 0.0), description="m, the model's base in the world")
    orientation: tuple[Finite, Finite, Finite, Finite] = Field(
        default=(1.0, 0.0, 0.0, 0.0), description="unit quaternion w x y z, base to world"
    )
    fixed_base: Annotated[bool, Strict()] = Field(
        default=True,
        description="true: the root link is fixed to the world; false: free (MJCF: the one "
        "top-level body with a <freejoint/>)",
    )
    joint_positions: dict[str, Finite] = Field(
        default={},
        description="rad or m at t = 0 (rad even where an MJCF states degrees), by prefixed "
        "joint name; others 0, or the limit nearest 0 when the limits exclude 0",
    )
    joint_velocities: dict[str, Finite] = Field(
        default={}, description="rad/s or m/s at t = 0, by prefixed joint name; others 0"
    )
    collisions: Annotated[bool, Strict()] = Field(
        default=False,
        description="true: each link's one collision primitive (sphere, box, cylinder, capsule) "
        "is its body's shape and takes part in contacts; false: no model link touches anything",
    )

    @field_validator("orientation")
    @classmethod
    def _unit_quaternion(cls, value: tuple[float, ...]) -> tuple[float, ...]:
        return BodySpec._unit_quaternion(value)


class PairSpec(_Strict):
    """Contact values for one pair that replace the mixing rules."""

    a: Name
    b: Name = Field(description="a body name, or 'ground'")
    restitution: UnitInterval | None = None
    friction: NonNegative | None = None


# --- analytic expectations ---------------------------------------------------------------


class _Expectation(_Strict):
    name: Name | None = Field(default=None, description="metric name; default '<kind>.<body>'")
    body: Name

    @property
    def metric(self) -> str:
        return self.name or f"{self.kind}.{self.body}"


class VelocityAfterImpact(_Expectation):
    """Centre-of-mass velocity of ``body`` just after its first impact (closed-form collision)."""

    kind: Literal["velocity_after_impact"]
    value: Vec3 = Field(description="m/s, world frame")


class PositionAt(_Expectation):
    """Centre-of-mass position of ``body`` at ``time``."""

    kind: Literal["position_at"]
    time: NonNegative = Field(description="s")
    value: Vec3 = Field(description="m, world frame")


class VelocityAt(_Expectation):
    """Centre-of-mass velocity of ``body`` at ``time``."""

    kind: Literal["velocity_at"]
    time: NonNegative = Field(description="s")
    value: Vec3 = Field(description="m/s, world frame")


class BounceHeights(_Expectation):
    """Apex heights of the centre of mass after successive bounces (e² h for a drop)."""

    kind: Literal["bounce_heights"]
    value: list[Positive] = Field(min_length=1, description="m")


class PrecessionRate(_Expectation):
    """Body-frame precession rate of a torque-free axisymmetric body: (I3 - I1)/I1 · ω3."""

    kind: Literal["precession_rate"]
    value: Finite = Field(description="rad/s")


class Flips(_Expectation):
    """How often a body spun near its intermediate axis flips over the run (Dzhanibekov)."""

    kind: Literal["flips"]
    axis: Literal["x", "y", "z"] = Field(default="y", description="body axis whose sign flips")
    value: Annotated[int, Strict(), Field(ge=0)]


class AngularVelocityAt(_Expectation):
    """Angular velocity of ``body`` at ``time``."""

    kind: Literal["angular_velocity_at"]
    time: NonNegative = Field(description="s")
    value: Vec3 = Field(description="rad/s, world frame")


class AngularVelocityAfterImpact(_Expectation):
    """Angular velocity of ``body`` just after its first impact, once the contact has ended."""

    kind: Literal["angular_velocity_after_impact"]
    value: Vec3 = Field(description="rad/s, world frame")


class OrientationAt(_Expectation):
    """Orientation of ``body`` at ``time``; the error is the rotation angle between the two."""

    kind: Literal["orientation_at"]
    time: NonNegative = Field(description="s")
    value: tuple[Finite, Finite, Finite, Finite] = Field(
        description="unit quaternion w x y z, body to world"
    )

    @field_validator("value")
    @classmethod
    def _unit_quaternion(cls, value: tuple[float, ...]) -> tuple[float, ...]:
        return BodySpec._unit_quaternion(value)


class FlipTimes(_Expectation):
    """Times at which a body-axis component of ω changes sign (Dzhanibekov flips)."""

    kind: Literal["flip_times"]
    axis: Literal["x", "y", "z"] = Field(default="y", description="body axis whose sign flips")
    value: list[NonNegative] = Field(min_length=1, description="s")


class ImpactTimes(_Expectation):
    """Times of the body's first impacts (the impulse, as the impact events place it)."""

    kind: Literal["impact_times"]
    value: list[NonNegative] = Field(min_length=1, description="s")


class EnergyAt(_Expectation):
    """The body's own energy at ``time``: kinetic (translation and rotation) plus gravitational."""

    kind: Literal["energy_at"]
    time: NonNegative = Field(description="s")
    value: Finite = Field(description="J")


class _JointExpectation(_Strict):
    """An expectation whose subject is a joint (``JOINT_EXPECTATION_MODELS``), not a body."""

    name: Name | None = Field(default=None, description="metric name; default '<kind>.<joint>'")
    joint: Name = Field(description="a joint name (its subject is a joint, not a body)")

    @property
    def metric(self) -> str:
        return self.name or f"{self.kind}.{self.joint}"


class JointPositionAt(_JointExpectation):
    """The coordinate of ``joint`` at ``time``, relative to t = 0: a hinge's angle (continuous
    over the run), a slider's travel, a ball's rotation vector (in the parent's frame, its angle
    at most π)."""

    kind: Literal["joint_position_at"]
    time: NonNegative = Field(description="s")
    value: Finite | Vec3 = Field(
        description="rad (hinge) or m (slider); a ball: its rotation vector [x, y, z] rad"
    )


class Period(_JointExpectation):
    """Mean time between successive upward crossings of a hinge or slider coordinate about its
    mean over the run."""

    kind: Literal["period"]
    value: Positive = Field(description="s")


JOINT_EXPECTATION_MODELS = (JointPositionAt, Period)
"""The expectation kinds whose subject is a ``joint`` (the others' is a ``body``)."""

EXPECTATION_MODELS = (
    VelocityAfterImpact,
    PositionAt,
    VelocityAt,
    BounceHeights,
    PrecessionRate,
    Flips,
    AngularVelocityAt,
    AngularVelocityAfterImpact,
    OrientationAt,
    FlipTimes,
    ImpactTimes,
    EnergyAt,
    *JOINT_EXPECTATION_MODELS,
)
"""Every expectation kind of format v1, one model each."""

Expectation = Annotated[
    VelocityAfterImpact
    | PositionAt
    | VelocityAt
    | BounceHeights
    | PrecessionRate
    | Flips
    | AngularVelocityAt
    | AngularVelocityAfterImpact
    | OrientationAt
    | FlipTimes
    | ImpactTimes
    | EnergyAt
    | JointPositionAt
    | Period,
    Field(discriminator="kind"),
]

Tolerance = NonNegative | dict[str, NonNegative]


class SweepSpec(_Strict):
    """Error against run time as part of the nightly run: ``physval run`` also sweeps the scene
    over these steps (``physval sweep``'s metrics and references) and reports the fitted
    orders in the scene's card and the history."""

    dt: list[Positive] = Field(min_length=2, description="s, the steps of the sweep (2 or more)")
    engines: list[Annotated[str, Strict()]] | None = Field(
        default=None, min_length=1, description="engine specs; default: the scene's engines"
    )


ANY_METRIC = "*"
"""The ``metric`` of a known finding that covers every row of its (scene, engine spec)."""


class KnownFinding(_Strict):
    """A difference the scene's authors know of: a failing row of ``engine`` and ``metric``
    reads ``known`` (not a failure of the run); the same row passing reads ``fixed``."""

    engine: Annotated[str, Strict()] = Field(
        description="an engine spec, matched as written in engines (e.g. mujoco(integrator=RK4))"
    )
    metric: Annotated[str, Strict(), Field(min_length=1)] = Field(
        description="a metric of this scene (energy_drift, velocity_at.ball, ...), 'status' for "
        "the run's own row (unstable, error), '*' for every row of the engine, or a shell-style "
        "pattern (velocity_after_impact.*)"
    )
    reason: Annotated[str, Strict(), Field(min_length=1)] = Field(
        description="what was measured and where it is documented"
    )

    @field_validator("reason")
    @classmethod
    def _says_something(cls, value: str) -> str:
        if not value.strip():
            raise ValueError("expected what was measured and where it is documented; got blanks")
        return value


class Scenario(_Strict):
    """A scene, version 1. Defaults are the documented ones below each field."""

    version: Literal[1] = FORMAT_VERSION
    name: Word | None = Field(default=None, description="default: the file name without .yaml")
    description: str = Field(default="", description="what the scene stresses and why")
    dt: Positive = Field(description="s, the fixed step")
    duration: Positive = Field(description="s, >= dt")
    gravity: Vec3 = Field(default=(0.0, 0.0, -9.81), description="m/s², world frame")
    ground: GroundSpec | None = Field(
        default=None, description="a static plane (default z = 0, normal +z); none if absent"
    )
    engines: list[Annotated[str, Strict()]] = Field(
        default=list(DEFAULT_ENGINES),
        min_length=1,
        description="engine specs, e.g. mini(gyroscopic=implicit)",
    )
    bodies: list[BodySpec] = Field(min_length=1)
    springs: list[SpringSpec] = []
    joints: list[JointSpec] = Field(
        default=[], description="joints between bodies, or a body and the world (a tree)"
    )
    models: list[ModelSpec] = Field(
        default=[],
        description="robot models (URDF) whose links and joints join bodies and joints at load",
    )
    pairs: list[PairSpec] = Field(default=[], description="per-pair restitution/friction overrides")
    expect: list[Expectation] = Field(default=[], description="analytic expectations")
    checks: dict[str, Tolerance] = Field(
        default={},
        description="tolerance per metric: one number, or {default: x, <engine spec>: y} "
        "(an engine entry applies to exactly that spec as written in engines)",
    )
    known: list[KnownFinding] = Field(
        default=[],
        description="known findings: failing rows they match read 'known' and do not fail the run",
    )
    sweep: SweepSpec | None = Field(
        default=None, description="a dt sweep that physval run runs with the scene (optional)"
    )
    source: str = Field(default="", exclude=True, description="the file it was loaded from")

    @property
    def steps(self) -> int:
        return round(self.duration / self.dt)

    @cached_property
    def engine_specs(self) -> tuple[EngineSpec, ...]:
        return tuple(parse_engine_spec(text) for text in self.engines)

    def body(self, name: str) -> BodySpec:
        return next(b for b in self.bodies if b.name == name)

    def tolerance(self, metric: str, engine: str) -> float | None:
        """The tolerance of ``metric`` for the engine spec labelled ``engine``, or None.

        A per-engine entry applies to exactly that spec (``mini`` is the plain mini, not
        ``mini(gyroscopic=explicit)``); every other spec takes ``default``.
        """
        value = self.checks.get(metric)
        if value is None or isinstance(value, float | int):
            return value
        return value.get(engine, value.get("default"))


def scene_at(scenario: Scenario, dt: float) -> Scenario:
    """The same scene with another step (duration unchanged)."""
    return Scenario.model_validate({**scenario.model_dump(), "dt": dt, "source": scenario.source})
