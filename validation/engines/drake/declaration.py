"""Drake's declaration, as data: what the adapter offers and needs, without importing pydrake.

``physval list``, spec parsing and the install hint read this module; only
``validation.engines.drake.adapter`` imports the engine. Two profiles (``PROFILES``):

- ``discrete`` (the default): a discrete ``MultibodyPlant`` at the scene's dt, stepped by its
  default contact solver (SAP with the ``lagged`` approximation in Drake 1.51); ``advance(n)``
  is n plant steps (``stepping: fixed``).
- ``continuous``: a continuous plant (time_step 0) integrated by an error-controlled integrator
  (``runge_kutta3`` by default) to a stated ``accuracy``; dt is only the observation interval
  (``stepping: error_controlled``, ``advance_tolerance`` = the accuracy). ``physval sweep``
  sweeps such a spec over the accuracy instead of dt (``validation.jobs.sweep``).

Restitution is not a Drake parameter (its compliant point contact dissipates by Hunt-Crossley
or the solver's own relaxation, not by a coefficient of restitution), so no profile declares
the ``restitution`` feature: a scene stating e > 0 on a contact is ``unsupported`` in Drake,
with the reason, and never approximated (docs/engines-drake.md 5).
"""

from __future__ import annotations

import math

from validation.engine_api import (
    API_VERSION,
    MODEL_LOADER_OPTION,
    Capabilities,
    EngineDeclaration,
    EngineOption,
)

NAME = "drake"
"""The engine's spec name."""

DISTRIBUTION = "drake"
"""The PyPI distribution whose version is the engine's version (its import name is pydrake)."""

MODULE = "pydrake"
"""The module the adapter imports."""

ADAPTER = "validation.engines.drake.adapter:DrakeAdapter"
"""``module:Class`` of the adapter, imported on first use."""

INSTALL_HINT = 'pip install "physval[drake]"'
"""What to run when ``pydrake`` is missing (the optional extra of pyproject.toml)."""

SUMMARY = (
    "Drake (pydrake MultibodyPlant): discrete contact solver at dt, or error-controlled "
    "continuous integration"
)

DISCRETE, CONTINUOUS = "discrete", "continuous"
PROFILES = (DISCRETE, CONTINUOUS)
"""The two profiles: Drake's discrete plant at the scene's dt, and the continuous plant under
an error-controlled integrator."""

CONTACT_APPROXIMATIONS = ("lagged", "sap", "similar", "tamsi")
"""``DiscreteContactApproximation`` by Drake's own names (``kLagged`` ...); the discrete plant's
default is ``lagged`` in Drake 1.51 (measured: ``get_discrete_contact_approximation``)."""

INTEGRATORS = ("runge_kutta3", "runge_kutta5", "bogacki_shampine3", "radau3", "implicit_euler")
"""The error-controlled integrators the continuous profile offers, by the names of
``pydrake.systems.analysis.GetIntegrationSchemes`` (``ResetIntegratorFromFlags``);
``runge_kutta3`` is Drake's default (``SimulatorConfig.integration_scheme``)."""

DEFAULT_INTEGRATOR = "runge_kutta3"

DEFAULT_ACCURACY = 1e-4
"""Drake's ``SimulatorConfig.accuracy`` default: the integrator's target accuracy (Drake's
error norm: a weighted, mostly relative measure of the local error per step)."""

ACCURACY_EXAMPLE = 1e-6
"""An accuracy other than the default, for the conformance suite's provenance check."""

DISCRETE_STEPPING = "discrete"
"""The discrete profile's time integration as ``Capabilities.integrators`` names it: one
plant step of dt (semi-implicit Euler of the free motion with the contact solve)."""

SHAPES = ("sphere", "box", "capsule", "cylinder")
"""``pydrake.geometry.Sphere``, ``Box`` (full widths: twice the half-extents), ``Capsule`` and
``Cylinder`` (radius and cylinder length, twice the scene's ``half_length``, along the shape's
z), each at the shape's offset and orientation in its body (``placed_shapes``)."""

FEATURES = (
    "ground",
    "tilted_ground",
    "contacts",
    "fixed_bodies",
    "springs",
    "loads",
    "friction",
    "joints",
    "non_colliding",
    "placed_shapes",
)
"""Every scene feature but ``restitution`` (and ``joint_limits``: ``DISCRETE_FEATURES``): the
ground is a ``HalfSpace`` on the world body at the scene's pose (tilted too), fixed bodies are
collision geometry of the world body, springs are ``LinearSpringDamper`` force elements (a rest
length of 0, which Drake's element refuses, is an isotropic ``LinearBushingRollPitchYaw`` when
undamped), constant loads are ``ExternallyAppliedSpatialForce`` values fixed on the plant's
applied spatial force port, friction is ``CoulombFriction`` per geometry (Drake combines a pair
by 2μ₁μ₂/(μ₁+μ₂)), and joints are Drake's ``RevoluteJoint``, ``PrismaticJoint``,
``BallRpyJoint`` and ``WeldJoint`` (``validation.engines.drake.joints``), and a body with
``collides: false`` registers no collision geometry (a native model's links with
``collisions: false``: their file's geometry is not registered or is filtered,
``validation.engines.drake.models``)."""

DISCRETE_FEATURES = ("joint_limits",)
"""Features of the discrete profile only: its SAP solver enforces a hinge's or slider's limits
as constraints (measured: a pendulum resting on its limit 1.6e-8 rad past it); the continuous
plant ignores them (the same pendulum swings through to 3.14 rad), so that profile's scenes
with limits are ``unsupported`` (docs/engines-drake.md 9)."""

OPTIONS = (
    EngineOption(
        "profile",
        str,
        "discrete: the plant steps at the scene's dt with its contact solver; continuous: "
        "error-controlled integration to `accuracy` (default: continuous when accuracy= or "
        "integrator= is set, else discrete)",
        PROFILES,
    ),
    EngineOption(
        "contact_approximation",
        str,
        "discrete only: DiscreteContactApproximation; unset: Drake's default (lagged)",
        CONTACT_APPROXIMATIONS,
    ),
    EngineOption(
        "accuracy",
        float,
        f"continuous only: the integrator's target accuracy; unset: {DEFAULT_ACCURACY:g} "
        "(Drake's SimulatorConfig)",
        example=ACCURACY_EXAMPLE,
    ),
    EngineOption(
        "integrator",
        str,
        f"continuous only: the error-controlled integrator; unset: {DEFAULT_INTEGRATOR} "
        "(Drake's default)",
        INTEGRATORS,
    ),
    MODEL_LOADER_OPTION,
)
"""The settings a Drake spec may carry; ``model_loader`` (native, the default: Drake's
``Parser`` reads a scene's model files, ``validation.engines.drake.models``; physval: the
bodies and joints physval expanded them into)."""

NATIVE = str(MODEL_LOADER_OPTION.default)
"""The ``model_loader`` value of Drake's own parser."""

CONTINUOUS_ONLY = ("accuracy", "integrator")
DISCRETE_ONLY = ("contact_approximation",)


def profile_of(settings: dict[str, object]) -> str:
    """The spec's profile: the stated one, else continuous when a continuous-only option is
    set, else discrete."""
    stated = settings.get("profile")
    if stated is not None:
        return str(stated)
    return CONTINUOUS if any(k in settings for k in CONTINUOUS_ONLY) else DISCRETE


def accuracy_of(settings: dict[str, object]) -> float:
    """The continuous profile's target accuracy (the spec's, else ``DEFAULT_ACCURACY``)."""
    return float(settings.get("accuracy", DEFAULT_ACCURACY))


def check_settings(settings: dict[str, object]) -> None:
    """One line for options of the other profile, and for an accuracy that is not in (0, 1)."""
    profile = profile_of(settings)
    wrong = DISCRETE_ONLY if profile == CONTINUOUS else CONTINUOUS_ONLY
    for key in wrong:
        if key in settings:
            other = DISCRETE if profile == CONTINUOUS else CONTINUOUS
            raise ValueError(f"setting {key!r} applies to profile={other} only; this is {profile}")
    if profile == CONTINUOUS:
        accuracy = accuracy_of(settings)
        if not (math.isfinite(accuracy) and 0.0 < accuracy < 1.0):
            raise ValueError(f"setting 'accuracy': expected a number in (0, 1); got {accuracy!r}")


BASE = Capabilities(
    shapes=SHAPES,
    features=frozenset({*FEATURES, *DISCRETE_FEATURES}),
    integrators=(DISCRETE_STEPPING, *INTEGRATORS),
    precision="float64",
)


def capabilities_for(settings: dict[str, object]) -> Capabilities:
    """discrete: fixed steps, advance(n) exactly n steps; continuous: error-controlled, and
    advance(n) equals n x advance(1) to the stated accuracy."""
    if profile_of(settings) == DISCRETE:
        return Capabilities(
            shapes=SHAPES,
            features=frozenset({*FEATURES, *DISCRETE_FEATURES}),
            integrators=(DISCRETE_STEPPING,),
        )
    return Capabilities(
        shapes=SHAPES,
        features=frozenset(FEATURES),
        integrators=(str(settings.get("integrator", DEFAULT_INTEGRATOR)),),
        stepping="error_controlled",
        advance_tolerance=accuracy_of(settings),
    )


DECLARATION = EngineDeclaration(
    name=NAME,
    api_version=API_VERSION,
    adapter=ADAPTER,
    distribution=DISTRIBUTION,
    summary=SUMMARY,
    options=OPTIONS,
    capabilities=BASE,
    check_settings=check_settings,
    capabilities_for=capabilities_for,
    requires=(MODULE,),
    install=INSTALL_HINT,
)
"""Drake as the adapter contract declares an engine (an entry point of ``physval.engines``)."""
