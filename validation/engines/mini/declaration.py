"""mini's declaration: its options are the fields of ``mini_engine.Settings`` (dt aside, the
scene's), typed and defaulted from the dataclass, each word option's choices from
``mini_engine.settings.CHOICES``; it imports mini_engine's settings only."""

from __future__ import annotations

from dataclasses import fields

from mini_engine.settings import CHOICES, INTEGRATORS, Settings
from validation.engine_api import (
    API_VERSION,
    BASE_FEATURES,
    BASE_SHAPES,
    JOINT_FEATURES,
    Capabilities,
    Count,
    EngineDeclaration,
    EngineOption,
)

MEANINGS: dict[str, str] = {
    "integrator": "time integrator (semi-implicit Euler is the documented one)",
    "gyroscopic": "the gyroscopic term ω × Iω: dropped (documented), explicit or implicit",
    "orientation_update": "quaternion update from ω: exact exponential map or linearized",
    "position_correction": "penetration handling: none, Baumgarte bias, or split impulse",
    "restitution_threshold": "m/s; restitution applies only to contacts approaching faster",
    "restitution_mix": "pair restitution from the two bodies' values",
    "friction_mix": "pair friction coefficient from the two bodies' values",
    "solver_iterations": "maximum sequential-impulse sweeps over the contacts per step",
    "position_iterations": "maximum sweeps of the split-impulse position solve per step",
    "warm_start": "start each contact's impulses from the previous step's",
    "solver_tolerance": "m/s; the sweeps stop once no contact's velocity changes by more",
    "contact_margin": "m; shapes closer than this count as touching",
    "baumgarte_factor": "fraction of the penetration removed per step by position correction",
    "penetration_slop": "m; penetration allowed before position correction acts",
    "max_correction_speed": "m/s; upper bound of the position-correction bias velocity",
    "broadphase_padding": "m; extra radius of the broad phase's bounding spheres only",
}
"""One line per ``Settings`` field (``mini_engine.settings`` documents each in full)."""


def _option(name: str, default: object) -> EngineOption:
    """The option of one ``Settings`` field: its words, or its type (``Count`` for the
    iteration counts), a doubled default as the conformance suite's example number."""
    if name in CHOICES:
        return EngineOption(name, str, MEANINGS[name], CHOICES[name], default)
    kind = Count if name.endswith("iterations") else type(default)
    example = None if kind is bool else (default * 2 if default else 1.0)
    return EngineOption(name, kind, MEANINGS[name], (), default, example)


def _check(settings: dict[str, object]) -> None:
    """``Settings``' own validation (a negative margin, for example), so that a spec's values
    are checked when it is parsed."""
    Settings(**settings)


DECLARATION = EngineDeclaration(
    name="mini",
    api_version=API_VERSION,
    adapter="validation.engines.mini.adapter:MiniAdapter",
    distribution="physval",
    summary="mini_engine, the documented engine (NumPy, float64)",
    options=tuple(
        _option(item.name, getattr(Settings(), item.name))
        for item in fields(Settings)
        if item.name != "dt"
    ),
    capabilities=Capabilities(
        shapes=BASE_SHAPES,  # mini_engine has no cylinder
        features=frozenset({*BASE_FEATURES, *JOINT_FEATURES, "non_colliding"}),
        integrators=INTEGRATORS,
    ),  # joints and their limits by the documented impulse (mini_engine.joints); no
    # placed_shapes: mini_engine's bodies carry their shape at the centre of mass, on its axes
    check_settings=_check,
)
