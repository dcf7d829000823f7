"""A scenario as a mini_engine model (the mini adapter builds on this; issue 4)."""

from __future__ import annotations

from mini_engine import Body, PairProperties, Plane, Spring, build_model
from mini_engine.collision import detect_contacts
from mini_engine.model import Model, State
from mini_engine.rotation import quat_to_matrix
from validation.scenario import BodySpec, Scenario
from validation.scene_physics import SHAPE_BUILDERS, rest_length

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
            rest_length=rest_length(scenario, s),
        )
        for s in scenario.springs
    ]
    pairs = [
        PairProperties(index[p.a], index[p.b], p.restitution, p.friction) for p in scenario.pairs
    ]
    return build_model(bodies, springs, gravity=scenario.gravity, pairs=pairs)


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
