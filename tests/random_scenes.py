"""Random scenes shared by the tests that compare two computations of one quantity (mini
against the reference side, a shortcut against the long way)."""

from __future__ import annotations

import numpy as np

from mini_engine import Body, Sphere, Spring, build_model
from validation.reference import loads


def random_unit_quaternions(rng: np.random.Generator, count: int) -> np.ndarray:
    """(count, 4) unit quaternions w x y z, uniform on the sphere."""
    quat = rng.normal(size=(count, 4))
    return quat / np.linalg.norm(quat, axis=1, keepdims=True)


def random_spring_scene(seed: int):
    """A mini model and state of 1-4 spheres (some fixed, each with a constant force and
    torque) joined by 1-6 springs (some to world points), and the same springs as the
    reference's ``Springs``."""
    rng = np.random.default_rng(seed)
    bodies_count, springs_count = int(rng.integers(1, 5)), int(rng.integers(1, 7))
    quat = random_unit_quaternions(rng, bodies_count)
    bodies = [
        Body(
            Sphere(0.1),
            mass=float(rng.uniform(0.1, 10.0)),
            position=rng.normal(size=3),
            orientation=quat[i],
            velocity=rng.normal(size=3),
            angular_velocity=3.0 * rng.normal(size=3),
            force=rng.normal(size=3),
            torque=rng.normal(size=3),
            fixed=bool(rng.random() < 0.2),
        )
        for i in range(bodies_count)
    ]
    springs = []
    for _ in range(springs_count):
        a = int(rng.integers(0, bodies_count))
        b = int(rng.integers(-1, bodies_count))
        springs.append(
            Spring(
                body_a=a,
                body_b=None if b in (-1, a) else b,
                anchor_a=0.3 * rng.normal(size=3),
                anchor_b=0.3 * rng.normal(size=3),
                stiffness=float(rng.uniform(0.0, 1e4)),
                damping=float(rng.uniform(0.0, 10.0)),
                rest_length=float(rng.uniform(0.0, 2.0)),
            )
        )
    model, state = build_model(bodies, springs)
    reference = loads.Springs(
        body_a=np.array([s.body_a for s in springs]),
        body_b=np.array([loads.WORLD if s.body_b is None else s.body_b for s in springs]),
        anchor_a=np.array([s.anchor_a for s in springs]),
        anchor_b=np.array([s.anchor_b for s in springs]),
        stiffness=np.array([s.stiffness for s in springs]),
        damping=np.array([s.damping for s in springs]),
        rest_length=np.array([s.rest_length for s in springs]),
    )
    return model, state, reference
