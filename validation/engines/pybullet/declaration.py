"""PyBullet's declaration: its spec options and capabilities, without importing PyBullet."""

from __future__ import annotations

from validation.engine_api import (
    API_VERSION,
    BASE_FEATURES,
    JOINT_FEATURES,
    Capabilities,
    Count,
    EngineDeclaration,
    EngineOption,
)

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
    ),
    capabilities=Capabilities(
        integrators=("semi_implicit_euler",),
        features=frozenset({*BASE_FEATURES, *JOINT_FEATURES}),
    ),
)
