"""PyBullet's declaration: its spec options and capabilities, without importing PyBullet."""

from __future__ import annotations

from validation.engine_api import (
    API_VERSION,
    BASE_FEATURES,
    JOINT_FEATURES,
    MODEL_FEATURES,
    MODEL_LOADER_OPTION,
    Capabilities,
    Count,
    EngineDeclaration,
    EngineOption,
)

SHAPES = ("sphere", "box", "capsule", "cylinder")
"""Every scene shape: ``GEOM_SPHERE``, ``GEOM_BOX``, ``GEOM_CAPSULE`` and ``GEOM_CYLINDER``
(along the shape's z), at the shape's offset and orientation (``collisionFramePosition``)."""

INERTIA_MODES = ("file", "shapes")
"""The ``urdf_inertia`` option: ``file`` (``URDF_USE_INERTIA_FROM_FILE``: the URDF's
``<inertial>``) or ``shapes`` (PyBullet's own default: the file's mass, and an inertia computed
from the link's collision shapes)."""

DECLARATION = EngineDeclaration(
    name="pybullet",
    api_version=API_VERSION,
    adapter="validation.engines.pybullet.adapter:PybulletAdapter",
    distribution="pybullet",
    summary="PyBullet (Bullet 3), sequential impulses, float64",
    options=(
        EngineOption(
            "profile",
            str,
            "matched: set up to integrate the scene's model; defaults: what a new user gets",
            ("matched", "defaults"),
            "matched",
        ),
        EngineOption(
            "bodies",
            str,
            "btRigidBody (maximal) or btMultiBody; unset: maximal when matched, else multibody "
            "(jointed bodies: always a btMultiBody per tree)",
            ("maximal", "multibody"),
        ),
        EngineOption(
            "solver_iterations",
            Count,
            "numSolverIterations; unset: PyBullet's 50",
            (),
            None,
            20,
        ),
        MODEL_LOADER_OPTION,
        EngineOption(
            "urdf_inertia",
            str,
            "a natively loaded URDF's link inertia: file (URDF_USE_INERTIA_FROM_FILE, the "
            "<inertial> as written) or shapes (PyBullet's own default: computed from the "
            "collision shapes)",
            INERTIA_MODES,
            "file",
        ),
    ),
    capabilities=Capabilities(
        shapes=SHAPES,
        integrators=("semi_implicit_euler",),
        features=frozenset({*BASE_FEATURES, *JOINT_FEATURES, *MODEL_FEATURES}),
    ),
)
