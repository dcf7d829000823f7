"""freeflight's declaration: its options and capabilities, as data (no solver imported).

It builds every shape and applied loads, and nothing that needs contact: a scene with a
ground, two or more bodies, springs or fixed bodies is ``unsupported`` in it, with the
reason, and never run."""

from validation.engines.base import (
    API_VERSION,
    Capabilities,
    Count,
    EngineDeclaration,
    EngineOption,
)

ROTATIONS = ("rk4", "exponential")
"""``rk4``: q̇ = ½ ω ⊗ q integrated by classical Runge-Kutta with ω = I_world(q)⁻¹ L(t).
``exponential``: q ← exp(½ ω dt) ⊗ q with ω at the step's start (first order)."""

DECLARATION = EngineDeclaration(
    name="freeflight",
    api_version=API_VERSION,
    adapter="physval_freeflight.adapter:FreeFlightAdapter",
    distribution="physval-freeflight",
    summary="free flight only: exact ballistic centres of mass, RK4 rotation (float64)",
    options=(
        EngineOption("rotation", str, "orientation update", ROTATIONS, "rk4"),
        EngineOption("substeps", Count, "rotation sub-steps per scene step", (), 1, 4),
    ),
    capabilities=Capabilities(
        shapes=("sphere", "box", "capsule"),
        features=frozenset({"loads"}),
        integrators=ROTATIONS,
    ),
)
