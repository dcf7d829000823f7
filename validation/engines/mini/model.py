"""The scene as a mini_engine model: what the mini adapter (and its sabotage) run.

It lives with the engine, not in ``scenario/``: the measurement and the reference side never
import mini_engine (``tests/test_architecture.py``), and the compiled scene carries no mini
model; mini_engine, the engine under test, is given the scene as every other engine is.
"""

from __future__ import annotations

from mini_engine import Body, Joint, PairProperties, Plane, Spring, build_model
from mini_engine.joints import WORLD
from mini_engine.model import SHARED_WORLD, Model, State
from mini_engine.shapes import Box, Capsule, Sphere
from validation.scenario.physics import GROUND, ground_pose, rest_length
from validation.scenario.schema import BodySpec, Scenario

SHAPE_BUILDERS = {
    "sphere": lambda s: Sphere(s.radius),
    "box": lambda s: Box(tuple(s.half_extents)),
    "capsule": lambda s: Capsule(s.radius, s.half_length),
}
"""Scenario shape type -> the mini_engine shape: its collision geometry, and its own solid
inertia when the scene states none (the engine under test computes that one itself)."""


def _body(spec: BodySpec) -> Body:
    return Body(
        shape=SHAPE_BUILDERS[spec.shape.type](spec.shape),
        mass=spec.mass,
        inertia=spec.inertia_matrix,
        position=spec.position,
        orientation=spec.orientation,
        velocity=spec.velocity,
        angular_velocity=spec.angular_velocity,
        force=spec.force,
        torque=spec.torque,
        restitution=spec.restitution,
        friction=spec.friction,
        fixed=spec.fixed,
        collides=spec.collides,
        name=spec.name,
    )


def build_mini_model(scenario: Scenario) -> tuple[Model, State]:
    """Model and initial state: the scene's bodies in order, then the ground plane if any;
    the scene's joints as mini's (``mini_engine.joints``, the documented impulse with e = 0)."""
    bodies = [_body(spec) for spec in scenario.bodies]
    if scenario.ground is not None:
        point, quat = ground_pose(scenario.ground)
        bodies.append(
            Body(
                Plane(),
                position=point,
                orientation=quat,
                fixed=True,
                restitution=scenario.ground.restitution,
                friction=scenario.ground.friction,
                name=GROUND,
                world=SHARED_WORLD,  # one plane for every world when the scene is replicated
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
    joints = [
        Joint(
            type=j.type,
            body_a=WORLD if j.parent == "world" else index[j.parent],
            body_b=index[j.child],
            anchor=j.anchor,
            axis=(0.0, 0.0, 0.0) if j.axis is None else j.axis,
            damping=j.damping,
            name=j.name,
            limits=j.limits,
        )
        for j in scenario.joints
    ]
    return build_model(bodies, springs, gravity=scenario.gravity, pairs=pairs, joints=joints)
