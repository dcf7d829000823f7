"""Collision detection: broad phase, then the narrow-phase function of each shape pair.

Candidate pairs are ordered so that body A has the lower ``ShapeType`` (the key
order of ``narrowphase.NARROW_PHASE``), grouped by shape pair, and each group
goes through its narrow-phase function in one batched call. Plane pairs (shape
codes below every finite pair's) come first, then the finite pairs.
"""

from __future__ import annotations

import numpy as np

from mini_engine.broadphase import finite_pairs, plane_pairs
from mini_engine.contacts import Contacts
from mini_engine.model import Model, per_model
from mini_engine.narrowphase import NARROW_PHASE
from mini_engine.shapes import ShapeType

SHAPE_CODES = len(ShapeType)
"""Base of the combined shape-pair code ``shape_a * SHAPE_CODES + shape_b`` (one sort key)."""

ShapePair = tuple[int, int]
"""``(shape_a, shape_b)`` with ``shape_a <= shape_b``: a key of ``NARROW_PHASE``."""


SPHERE_ROTATIONS = np.broadcast_to(np.eye(3), (1 << 40, 3, 3))
"""Rotations handed to the narrow phase for spheres: identities, as a read-only zero-stride
view sliced to the batch length. A sphere's contacts do not depend on its orientation (no
narrow-phase function reads a sphere's rotation), so sphere rotations are not gathered.
2**40 rows: more pairs than any batch that fits in memory."""


class UnsupportedShapePairError(ValueError):
    """Two shapes that may touch but have no narrow-phase function."""


@per_model
def known_shape_pairs(model: Model) -> tuple[ShapePair | None, ShapePair | None]:
    """The shape pair of every plane pair and of every finite pair when all collidable finite
    bodies have one shape (a pile of spheres), else None (then each step sorts the pairs)."""
    collidable = model.body_shape[model.body_collides]
    shapes = np.unique(collidable[collidable != ShapeType.PLANE]).tolist()
    if len(shapes) != 1:
        return None, None
    return (int(ShapeType.PLANE), shapes[0]), (shapes[0], shapes[0])


def detect_contacts(
    model: Model, pos: np.ndarray, rot: np.ndarray, margin: float, padding: float = 0.0
) -> Contacts:
    """All contacts (depth >= -margin) between bodies at poses ``pos (n, 3)``, ``rot (n, 3, 3)``.

    ``padding`` (m) only enlarges the broad phase's bounding spheres; the contacts reported
    are those within ``margin``. Normals point from ``body_a`` to ``body_b``; ``body_a`` has
    the lower shape code.
    """
    plane_pair, finite_pair = known_shape_pairs(model)
    reach = margin + padding
    found = _collide_pairs(
        model, pos, rot, margin, *plane_pairs(model, pos, rot, reach), plane_pair
    )
    found += _collide_pairs(model, pos, rot, margin, *finite_pairs(model, pos, reach), finite_pair)
    if not found:
        return Contacts.empty()
    contacts = (
        found[0]
        if len(found) == 1
        else Contacts(*(np.concatenate(parts) for parts in zip(*found, strict=True)))
    )
    return contacts if model.joints is None else _without_jointed_pairs(model, contacts)


def _without_jointed_pairs(model: Model, contacts: Contacts) -> Contacts:
    """``contacts`` less those between a joint's two bodies: jointed bodies meet at their
    anchor by construction, and their joint, not a contact, holds them (MuJoCo's parent
    filter and Bullet's adjacent links do the same)."""
    n = model.n_bodies
    keys = np.minimum(contacts.body_a, contacts.body_b) * n + np.maximum(
        contacts.body_a, contacts.body_b
    )
    keep = ~np.isin(keys, model.joints.pair_keys(n))
    if keep.all():
        return contacts
    return Contacts(*(np.asarray(field)[keep] for field in contacts))


def _collide_pairs(
    model: Model,
    pos: np.ndarray,
    rot: np.ndarray,
    margin: float,
    a: np.ndarray,
    b: np.ndarray,
    known: ShapePair | None,
) -> list[Contacts]:
    """The contacts of candidate pairs ``a, b (p,)``, one ``Contacts`` per shape pair in code
    order; ``known`` is the shape pair of them all when the model fixes it."""
    if a.size == 0:
        return []
    if known is not None:
        return [_narrow_phase(model, pos, rot, margin, known, a, b)]
    shape_a, shape_b = model.body_shape.take(a), model.body_shape.take(b)
    swap = shape_a > shape_b
    if swap.any():
        a, b = np.where(swap, b, a), np.where(swap, a, b)
        shape_a, shape_b = model.body_shape.take(a), model.body_shape.take(b)
    pair_code = shape_a * SHAPE_CODES + shape_b  # sorts as the (shape_a, shape_b) keys do
    codes = np.flatnonzero(np.bincount(pair_code, minlength=SHAPE_CODES * SHAPE_CODES))
    if codes.size == 1:  # one shape pair: the whole batch, no gather
        return [_narrow_phase(model, pos, rot, margin, divmod(int(codes[0]), SHAPE_CODES), a, b)]
    found = []
    for code in codes.tolist():
        group = np.flatnonzero(pair_code == code)
        key = divmod(code, SHAPE_CODES)
        found.append(_narrow_phase(model, pos, rot, margin, key, a.take(group), b.take(group)))
    return found


def _narrow_phase(
    model: Model,
    pos: np.ndarray,
    rot: np.ndarray,
    margin: float,
    key: ShapePair,
    a: np.ndarray,
    b: np.ndarray,
) -> Contacts:
    """The contacts of pairs ``a, b (k,)`` of shapes ``key``, by its narrow-phase function."""
    collide = NARROW_PHASE.get(key)
    if collide is None:
        raise UnsupportedShapePairError(f"no narrow phase for shape pair {key}")
    size = model.body_size
    hits = collide(
        pos.take(a, axis=0),
        _rotations_of(rot, a, key[0]),
        size.take(a, axis=0),
        pos.take(b, axis=0),
        _rotations_of(rot, b, key[1]),
        size.take(b, axis=0),
        margin,
    )
    return Contacts(a.take(hits.pair), b.take(hits.pair), hits.point, hits.normal, hits.depth)


def _rotations_of(rot: np.ndarray, bodies: np.ndarray, shape: int) -> np.ndarray:
    """The rotations (k, 3, 3) of ``bodies (k,)``, all of one ``shape``; identities for
    spheres (``SPHERE_ROTATIONS``), whose contacts do not depend on them."""
    if shape == ShapeType.SPHERE:
        return SPHERE_ROTATIONS[: bodies.size]
    return rot.take(bodies, axis=0)
