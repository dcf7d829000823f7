"""Physical values a scenario implies, computed once for every engine adapter.

The adapters must all give an engine the same physics, so the values derived from the
scene (solid inertias, pair restitution and friction, default spring rest lengths) are
defined here, once, and not re-derived per engine. The inertias, rotations and springs come
from the reference side (``validation.reference``), never from mini_engine: MuJoCo and
PyBullet are given the reference's solid inertia, while mini_engine, the engine under test,
is given only the inertia a scene states and computes its own from its shapes otherwise, so
the parity gate compares its formulas with the reference's.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from itertools import combinations_with_replacement

import numpy as np

from validation.reference import contacts, rotation
from validation.reference.loads import WORLD, Springs
from validation.reference.mass_properties import (
    box_inertia,
    capsule_inertia,
    cylinder_inertia,
    sphere_inertia,
)
from validation.scenario.schema import BodySpec, GroundSpec, Scenario, ShapeSpec, SpringSpec

SOLID_INERTIA: dict[str, Callable[[ShapeSpec, float], np.ndarray]] = {
    "sphere": lambda s, mass: sphere_inertia(mass, s.radius),
    "box": lambda s, mass: box_inertia(mass, s.half_extents),
    "capsule": lambda s, mass: capsule_inertia(mass, s.radius, s.half_length),
    "cylinder": lambda s, mass: cylinder_inertia(mass, s.radius, s.half_length),
}
"""Scenario shape type -> the reference's solid inertia (3, 3) kg·m² of a shape and a mass."""

PAIR_RULES: dict[str, Callable[[float, float], float]] = {
    "restitution": max,
    "friction": lambda a, b: math.sqrt(a * b),
}
"""A pair's value from the two bodies' when ``scenario.pairs`` does not state it: Box2D's
rules, the same as mini_engine's defaults ``restitution_mix=max``, ``friction_mix=geometric_mean``."""


def body_inertia(body: BodySpec) -> np.ndarray:
    """(3, 3) kg·m², body frame about the centre of mass: the scene's, or the reference's
    solid shape (``validation.reference.mass_properties``)."""
    if body.inertia_matrix is not None:
        return np.array(body.inertia_matrix, dtype=float)
    return SOLID_INERTIA[body.shape.type](body.shape, body.mass)


AXISYMMETRY_TOLERANCE = 1e-9
"""Relative. Two principal moments within this of each other are equal: a body of
revolution's formulas give them bit-equal, so anything above round-off is a real asymmetry."""


def symmetry_frame(inertia: np.ndarray) -> tuple[int | None, np.ndarray, np.ndarray] | None:
    """The symmetry axis of a body with two equal principal moments, as a right-handed frame
    ``(axis index, e1, e2)`` with ``e1 × e2`` along the axis (body frame): the axis index is
    0, 1 or 2 when the axis is a body axis (then e1, e2 are the next two body axes, cyclic),
    else None. A body whose moments all differ has no such axis: None. Three equal moments
    (a sphere): every axis is one; the body's z axis is taken."""
    moments, vectors = np.linalg.eigh(np.asarray(inertia, dtype=float))
    scale = max(float(np.abs(moments).max()), 1e-300)
    equal = np.abs(np.diff(moments)) <= AXISYMMETRY_TOLERANCE * scale
    if equal.all():
        return 2, np.array([1.0, 0.0, 0.0]), np.array([0.0, 1.0, 0.0])
    if not equal.any():
        return None
    axis = vectors[:, 2] if equal[0] else vectors[:, 0]  # the moment that differs
    axis = axis * np.sign(axis[np.argmax(np.abs(axis))])  # towards the nearest +body axis
    aligned = np.flatnonzero(np.abs(axis) > 1.0 - AXISYMMETRY_TOLERANCE)
    if aligned.size:
        k = int(aligned[0])
        basis = np.eye(3)
        return k, basis[(k + 1) % 3], basis[(k + 2) % 3]
    first = np.cross(axis, np.eye(3)[int(np.argmin(np.abs(axis)))])
    first /= np.linalg.norm(first)
    return None, first, np.cross(axis, first)


def pair_rule(quantity: str, value_a: float, value_b: float, stated: float | None = None) -> float:
    """The one pair rule: the value ``scenario.pairs`` states for the pair, else ``PAIR_RULES``
    applied to the two bodies' own values."""
    return stated if stated is not None else PAIR_RULES[quantity](value_a, value_b)


def pair_value(scenario: Scenario, a: str, b: str, quantity: str) -> float:
    """The scene's ``quantity`` (restitution or friction) for bodies ``a`` and ``b`` (or "ground")."""
    stated = next(
        (
            getattr(pair, quantity)
            for pair in scenario.pairs
            if {pair.a, pair.b} == {a, b} and getattr(pair, quantity) is not None
        ),
        None,
    )
    values = [
        getattr(scenario.ground, quantity)
        if name == "ground"
        else getattr(scenario.body(name), quantity)
        for name in (a, b)
    ]
    return pair_rule(quantity, *values, stated)


def rest_length(scenario: Scenario, spring: SpringSpec) -> float:
    """m: the spring's stated rest length, or its anchors' distance at t = 0 (the default)."""
    if spring.rest_length is not None:
        return spring.rest_length

    def world_point(name: str, anchor) -> np.ndarray:
        if name == "world":
            return np.asarray(anchor, dtype=float)
        body = scenario.body(name)
        rot = rotation.quat_to_matrix(np.asarray(body.orientation, dtype=float))
        return np.asarray(body.position) + rot @ np.asarray(anchor, dtype=float)

    return float(
        np.linalg.norm(
            world_point(spring.b, spring.anchor_b) - world_point(spring.a, spring.anchor_a)
        )
    )


def scene_springs(scenario: Scenario) -> Springs:
    """The scene's springs as the reference evaluates them: body indices in scenario order
    (``WORLD`` for a world point), anchors as written, rest lengths by ``rest_length``."""
    index = {body.name: i for i, body in enumerate(scenario.bodies)}
    springs = scenario.springs
    return Springs(
        body_a=np.array([index[s.a] for s in springs], dtype=np.int64),
        body_b=np.array([WORLD if s.b == "world" else index[s.b] for s in springs], dtype=np.int64),
        anchor_a=np.array([s.anchor_a for s in springs], dtype=float).reshape(-1, 3),
        anchor_b=np.array([s.anchor_b for s in springs], dtype=float).reshape(-1, 3),
        stiffness=np.array([s.stiffness for s in springs], dtype=float),
        damping=np.array([s.damping for s in springs], dtype=float),
        rest_length=np.array([rest_length(scenario, s) for s in springs], dtype=float),
    )


# --- the scene's collision shapes (the reference side's contact finder) ---


GROUND = "ground"
"""Name of the scene's ground plane (always the last shape, after the scene's bodies)."""

OVERLAP_TOLERANCE = 1e-9
"""m. Bodies placed exactly touching overlap by round-off; deeper than this is an overlap."""

SHAPE_SIZES: dict[str, Callable[[ShapeSpec], tuple[float, ...]]] = {
    "sphere": lambda s: (s.radius, 0.0, 0.0),
    "capsule": lambda s: (s.radius, s.half_length, 0.0),
    "box": lambda s: tuple(s.half_extents),
    "cylinder": lambda s: (s.radius, s.half_length, 0.0),
}
"""Scenario shape type -> its ``contacts.Shapes.size`` row (m); the type names are the
reference finder's ``contacts.SHAPES``."""


def scene_shapes(scenario: Scenario) -> contacts.Shapes:
    """The scene's collision shapes for ``validation.reference.contacts``: its bodies in
    scenario order, then the ground plane if any (fixed); a joint's parent and child never
    touch each other, nor does a body with ``collides: false`` touch anything
    (``Shapes.excluded``); each shape placed in its body by its ``offset`` and
    ``orientation`` (``Shapes.offset``, ``Shapes.turn``)."""
    bodies = scenario.bodies
    kinds = [contacts.SHAPES.index(b.shape.type) for b in bodies]
    sizes = [SHAPE_SIZES[b.shape.type](b.shape) for b in bodies]
    fixed = [b.fixed for b in bodies]
    offsets = [b.shape.offset for b in bodies]
    turns = [rotation.quat_to_matrix(np.asarray(b.shape.orientation, dtype=float)) for b in bodies]
    if scenario.ground is not None:
        kinds, sizes, fixed = [*kinds, contacts.PLANE], [*sizes, (0.0, 0.0, 0.0)], [*fixed, True]
        offsets, turns = [*offsets, (0.0, 0.0, 0.0)], [*turns, np.eye(3)]
    index = {body.name: k for k, body in enumerate(bodies)}
    jointed = {
        (min(index[j.parent], index[j.child]), max(index[j.parent], index[j.child]))
        for j in scenario.joints
        if j.parent in index and j.child in index
    }
    apart = {
        (min(k, other), max(k, other))
        for k, body in enumerate(bodies)
        if not body.collides
        for other in range(len(kinds))
        if other != k
    }
    return contacts.Shapes(
        kind=np.array(kinds, dtype=np.int64),
        size=np.array(sizes, dtype=float).reshape(-1, 3),
        fixed=np.array(fixed, dtype=bool),
        excluded=np.array(sorted(jointed | apart), dtype=np.int64).reshape(-1, 2),
        offset=np.array(offsets, dtype=float).reshape(-1, 3),
        turn=np.array(turns, dtype=float).reshape(-1, 3, 3),
    )


def unmeasured_pairs(scenario: Scenario) -> list[tuple[int, int]]:
    """(i, j), i < j shape indices (``scene_shapes``' order), of every pair that can touch
    (not both fixed, not excluded) and that the reference finder has no closed form for
    (``contacts.measured``): its contacts could not be measured. Only the shapes of such
    kinds are paired (a pile of 10,000 spheres costs nothing)."""
    shapes = scene_shapes(scenario)
    found: set[tuple[int, int]] = set()
    for kind_a, kind_b in combinations_with_replacement(np.unique(shapes.kind).tolist(), 2):
        if contacts.measured(kind_a, kind_b):
            continue
        a, b = np.flatnonzero(shapes.kind == kind_a), np.flatnonzero(shapes.kind == kind_b)
        first, second = (x.ravel() for x in np.meshgrid(a, b, indexing="ij"))
        first, second = np.minimum(first, second), np.maximum(first, second)
        can = (first < second) & ~(shapes.fixed[first] & shapes.fixed[second])
        can &= shapes.allowed(first, second)
        found |= set(zip(first[can].tolist(), second[can].tolist(), strict=True))
    return sorted(found)


def ground_pose(ground: GroundSpec) -> tuple[np.ndarray, np.ndarray]:
    """The ground plane's pose: ``point (3,)`` m and the unit quaternion ``(4,)`` w x y z of the
    shortest rotation taking +z to ``ground.normal`` (a half turn about x for -z). Every engine
    places its plane (normal = the body's +z) with this one pose."""
    normal = np.asarray(ground.normal, dtype=float)
    axis = np.cross([0.0, 0.0, 1.0], normal)
    cosine = float(normal[2])
    if cosine <= -1.0 + AXISYMMETRY_TOLERANCE and np.linalg.norm(axis) <= AXISYMMETRY_TOLERANCE:
        return np.asarray(ground.point, dtype=float), np.array([0.0, 1.0, 0.0, 0.0])
    # q = (1 + cos θ, sin θ · axis) normalised: the half-angle formula without trigonometry
    quat = np.concatenate([[1.0 + cosine], axis])
    return np.asarray(ground.point, dtype=float), quat / np.linalg.norm(quat)


def scene_poses(scenario: Scenario) -> tuple[np.ndarray, np.ndarray]:
    """The scene's shapes at t = 0 (``scene_shapes``' order): positions (N, 3) m and unit
    quaternions (N, 4) w x y z."""
    pos = [b.position for b in scenario.bodies]
    quat = [b.orientation for b in scenario.bodies]
    if scenario.ground is not None:
        point, turn = ground_pose(scenario.ground)
        pos, quat = [*pos, point], [*quat, turn]
    unit = np.array(quat, dtype=float).reshape(-1, 4)
    return np.array(pos, dtype=float).reshape(-1, 3), unit / np.linalg.norm(unit, axis=1)[:, None]


def initial_overlaps(scenario: Scenario) -> list[tuple[int, str]]:
    """(body index, message) for every pair overlapping at t = 0 (deeper than round-off),
    found by the reference side's contact finder."""
    pos, quat = scene_poses(scenario)
    rot = rotation.quat_to_matrix(quat)
    found = contacts.find_contacts(scene_shapes(scenario), pos[None], rot[None], 0.0)
    deep = found.depth > OVERLAP_TOLERANCE
    names = [b.name for b in scenario.bodies] + [GROUND]
    pairs = zip(found.body_a[deep], found.body_b[deep], found.depth[deep], strict=True)
    return [
        (
            a if a < len(scenario.bodies) else b,
            f"{names[a]!r} and {names[b]!r} overlap by {depth:.3g} m at t = 0 (intended for deep-penetration scenes)",
        )
        for a, b, depth in sorted((int(min(a, b)), int(max(a, b)), float(d)) for a, b, d in pairs)
    ]
