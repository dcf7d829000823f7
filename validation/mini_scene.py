"""A scenario as a mini_engine model (the mini adapter builds on this; issue 4)."""

from __future__ import annotations

import numpy as np

from mini_engine import Body, Box, Capsule, PairProperties, Plane, Sphere, Spring, build_model
from mini_engine.collision import detect_contacts
from mini_engine.model import Model, State
from mini_engine.rotation import apply, quat_to_matrix
from validation.scenario import BodySpec, Scenario

SHAPE_BUILDERS = {
    "sphere": lambda s: Sphere(s.radius),
    "box": lambda s: Box(tuple(s.half_extents)),
    "capsule": lambda s: Capsule(s.radius, s.half_length),
}

GROUND = "ground"
"""Name of the scene's ground plane in the model (always the last body)."""

OVERLAP_TOLERANCE = 1e-9
"""m. Bodies placed exactly touching overlap by round-off; deeper than this is an overlap."""


def _body(spec: BodySpec) -> Body:
    return Body(
        shape=SHAPE_BUILDERS[spec.shape.type](spec.shape),
        mass=spec.mass,
        inertia=spec.inertia_matrix,
        position=spec.position,
        orientation=spec.orientation,
        velocity=spec.velocity,
        angular_velocity=spec.angular_velocity,
        restitution=spec.restitution,
        friction=spec.friction,
        fixed=spec.fixed,
        name=spec.name,
    )


def build_mini_model(scenario: Scenario) -> tuple[Model, State]:
    """Model and initial state: the scene's bodies in order, then the ground plane if any."""
    bodies = [_body(spec) for spec in scenario.bodies]
    if scenario.ground is not None:
        bodies.append(
            Body(
                Plane(),
                fixed=True,
                restitution=scenario.ground.restitution,
                friction=scenario.ground.friction,
                name=GROUND,
            )
        )
    index = {b.name: i for i, b in enumerate(bodies)}
    springs = [
        Spring(
            body_a=index[s.a],
            body_b=None if s.b == "world" else index[s.b],
            anchor_a=s.anchor_a,
            anchor_b=s.anchor_b,
            stiffness=s.stiffness,
            damping=s.damping,
            rest_length=_rest_length(scenario, s) if s.rest_length is None else s.rest_length,
        )
        for s in scenario.springs
    ]
    pairs = [
        PairProperties(index[p.a], index[p.b], p.restitution, p.friction) for p in scenario.pairs
    ]
    return build_model(bodies, springs, gravity=scenario.gravity, pairs=pairs)


def _rest_length(scenario: Scenario, spring) -> float:
    """Distance between the spring's anchors at t = 0 (its default rest length)."""

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


def initial_overlaps(scenario: Scenario) -> list[tuple[int, str]]:
    """(body index, message) for every pair overlapping at t = 0 (deeper than round-off)."""
    model, state = build_mini_model(scenario)
    contacts = detect_contacts(model, state.pos, quat_to_matrix(state.quat), 0.0)
    deep = contacts.depth > OVERLAP_TOLERANCE
    found: dict[tuple[int, int], float] = {}
    for a, b, depth in zip(
        contacts.body_a[deep], contacts.body_b[deep], contacts.depth[deep], strict=True
    ):
        key = (int(min(a, b)), int(max(a, b)))
        found[key] = max(found.get(key, 0.0), float(depth))
    names = model.body_name
    return [
        (
            a if a < len(scenario.bodies) else b,
            f"{names[a]!r} and {names[b]!r} overlap by {depth:.3g} m at t = 0 (intended for deep-penetration scenes)",
        )
        for (a, b), depth in sorted(found.items())
    ]
