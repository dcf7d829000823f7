"""Physical values a scenario implies, computed once for every engine adapter.

The adapters must all give an engine the same physics, so the values derived from the
scene (solid inertias, pair restitution and friction, default spring rest lengths) are
defined here, once, and not re-derived per engine.
"""

from __future__ import annotations

import math
from collections.abc import Callable

import numpy as np

from mini_engine.rotation import apply, quat_to_matrix
from mini_engine.shapes import Box, Capsule, Sphere, solid_inertia
from validation.scenario import BodySpec, Scenario, SpringSpec

SHAPE_BUILDERS = {
    "sphere": lambda s: Sphere(s.radius),
    "box": lambda s: Box(tuple(s.half_extents)),
    "capsule": lambda s: Capsule(s.radius, s.half_length),
}
"""Scenario shape type -> the mini_engine shape (whose solid inertia every engine gets)."""

PAIR_RULES: dict[str, Callable[[float, float], float]] = {
    "restitution": max,
    "friction": lambda a, b: math.sqrt(a * b),
}
"""A pair's value from the two bodies' when ``scenario.pairs`` does not state it: Box2D's
rules, the same as mini_engine's defaults ``restitution_mix=max``, ``friction_mix=geometric_mean``."""


def body_inertia(body: BodySpec) -> np.ndarray:
    """(3, 3) kg·m², body frame about the centre of mass: the scene's, or the solid shape's."""
    if body.inertia_matrix is not None:
        return np.array(body.inertia_matrix, dtype=float)
    return solid_inertia(SHAPE_BUILDERS[body.shape.type](body.shape), body.mass)


def pair_value(scenario: Scenario, a: str, b: str, quantity: str) -> float:
    """The scene's ``quantity`` (restitution or friction) for bodies ``a`` and ``b`` (or "ground")."""
    for pair in scenario.pairs:
        stated = getattr(pair, quantity)
        if {pair.a, pair.b} == {a, b} and stated is not None:
            return stated
    values = [
        getattr(scenario.ground, quantity)
        if name == "ground"
        else getattr(scenario.body(name), quantity)
        for name in (a, b)
    ]
    return PAIR_RULES[quantity](*values)


def rest_length(scenario: Scenario, spring: SpringSpec) -> float:
    """m: the spring's stated rest length, or its anchors' distance at t = 0 (the default)."""
    if spring.rest_length is not None:
        return spring.rest_length

    def world_point(name: str, anchor) -> np.ndarray:
        if name == "world":
            return np.asarray(anchor, dtype=float)
        body = scenario.body(name)
        rot = quat_to_matrix(np.array([body.orientation]))
        return np.asarray(body.position) + apply(rot, np.array([anchor]))[0]

    return float(
        np.linalg.norm(
            world_point(spring.b, spring.anchor_b) - world_point(spring.a, spring.anchor_a)
        )
    )
