"""MuJoCo's declaration: its spec options and capabilities, without importing MuJoCo."""

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
"""Every scene shape: geoms ``sphere``, ``box``, ``capsule`` and ``cylinder``
(``mjcf.GEOM_SIZES``)."""

INTEGRATOR_WORDS = ("Euler", "RK4", "implicit", "implicitfast")
"""MuJoCo's integrators as spec words (``mjcf.INTEGRATORS`` maps them to MJCF)."""

DECLARATION = EngineDeclaration(
    name="mujoco",
    api_version=API_VERSION,
    adapter="validation.engines.mujoco.adapter:MujocoAdapter",
    distribution="mujoco",
    summary="MuJoCo, soft-constraint contacts in generalized coordinates (float64)",
    options=(
        EngineOption(
            "profile",
            str,
            "matched: contacts calibrated to the scene's e and μ; defaults: MuJoCo's own",
            ("matched", "defaults"),
            "matched",
        ),
        EngineOption("integrator", str, "MuJoCo's time integrator", INTEGRATOR_WORDS, "Euler"),
        EngineOption(
            "solver",
            str,
            "constraint solver; auto: CG for large matched scenes, Newton otherwise",
            ("auto", "Newton", "CG", "PGS"),
            "auto",
        ),
        EngineOption(
            "cone",
            str,
            "friction cone; unset: elliptic for frictional damper pairs, else pyramidal",
            ("pyramidal", "elliptic"),
        ),
        EngineOption(
            "restitution",
            str,
            "damper: one-step damper calibrated to e; soft: MuJoCo's default soft contact",
            ("damper", "soft"),
            "damper",
        ),
        EngineOption("iterations", Count, "maximum solver iterations per step", (), 100, 50),
        MODEL_LOADER_OPTION,
    ),
    capabilities=Capabilities(
        shapes=SHAPES,
        features=frozenset({*BASE_FEATURES, *JOINT_FEATURES, *MODEL_FEATURES}),
        integrators=INTEGRATOR_WORDS,
    ),
)
