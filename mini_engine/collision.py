"""Collision detection: broad phase, then the narrow-phase function of each shape pair.

Candidate pairs are ordered so that body A has the lower ``ShapeType`` (the key
order of ``narrowphase.NARROW_PHASE``), grouped by shape pair, and each group
goes through its narrow-phase function in one batched call.
"""

from __future__ import annotations

import numpy as np

from mini_engine.broadphase import candidate_pairs
from mini_engine.contacts import Contacts
from mini_engine.model import Model
from mini_engine.narrowphase import NARROW_PHASE
from mini_engine.shapes import ShapeType

SHAPE_CODES = len(ShapeType)
"""Base of the combined shape-pair code ``shape_a * SHAPE_CODES + shape_b`` (one sort key)."""


class UnsupportedShapePairError(ValueError):
    """Two shapes that may touch but have no narrow-phase function."""


def detect_contacts(
    model: Model, pos: np.ndarray, rot: np.ndarray, margin: float, padding: float = 0.0
) -> Contacts:
    """All contacts (depth >= -margin) between bodies at poses ``pos (n, 3)``, ``rot (n, 3, 3)``.

    ``padding`` (m) only enlarges the broad phase's bounding spheres; the contacts reported
    are those within ``margin``. Normals point from ``body_a`` to ``body_b``; ``body_a`` has
    the lower shape code.
    """
    a, b = candidate_pairs(model, pos, rot, margin + padding)
    if a.size == 0:
        return Contacts.empty()
    shape_a, shape_b = model.body_shape[a], model.body_shape[b]
    swap = shape_a > shape_b
    if swap.any():
        a, b = np.where(swap, b, a), np.where(swap, a, b)
        shape_a, shape_b = model.body_shape[a], model.body_shape[b]

    pair_code = shape_a * SHAPE_CODES + shape_b  # sorts as the (shape_a, shape_b) keys do
    first = int(pair_code[0])
    codes = np.array([first]) if np.all(pair_code == first) else np.unique(pair_code)
    found = []
    for code in codes.tolist():
        key = divmod(code, SHAPE_CODES)
        collide = NARROW_PHASE.get(key)
        if collide is None:
            raise UnsupportedShapePairError(f"no narrow phase for shape pair {key}")
        if codes.size == 1:  # one shape pair: the whole batch, no gather
            ga, gb = a, b
        else:
            group = np.flatnonzero(pair_code == code)
            ga, gb = a[group], b[group]
        hits = collide(
            pos[ga], rot[ga], model.body_size[ga], pos[gb], rot[gb], model.body_size[gb], margin
        )
        found.append(Contacts(ga[hits.pair], gb[hits.pair], hits.point, hits.normal, hits.depth))
    if len(found) == 1:
        return found[0]
    return Contacts(*(np.concatenate(parts) for parts in zip(*found, strict=True)))
