"""Broad phase: candidate body pairs whose bounding spheres overlap, without n² Python work.

Three kinds of candidates, all vectorized:

1. **planes** (infinite) against every finite body: signed distance of the
   centre along the plane normal minus the bounding radius;
2. **large** finite bodies (bounding radius over ``LARGE_BODY_FACTOR`` times
   the median) against every other finite body, by one broadcast test;
3. **small** finite bodies through a uniform grid whose cell is the largest
   small-body bounding diameter: each body is hashed to the cell of its
   centre, and pairs are found in its own cell and 13 of its 26 neighbours
   (each neighbour pair is visited once).

Every candidate then passes the same filter: both bodies collide, not both
fixed, same world (or one in the shared world), bounding spheres within the
padding, and the exact bounding-sphere test.
"""

from __future__ import annotations

import numpy as np

from mini_engine.model import SHARED_WORLD, Model
from mini_engine.shapes import ShapeType

LARGE_BODY_FACTOR = 4.0
"""A finite body whose bounding radius exceeds this multiple of the median radius is
tested against all bodies directly instead of inflating the grid cell; 4 keeps the grid
cell small for piles of equal spheres while walls and big boxes go to the direct test."""

GRID_SPAN_LIMIT = 1e6
"""Cells along one axis beyond which the bodies are too spread for a grid (an exploded
state, or bodies kilometres apart): every pair is tested directly instead, and int64 cell
keys can never overflow."""

CELL_TABLE_LIMIT = 1 << 20
"""Grids with at most this many cells (8 MiB of int64) get a dense cell-start table;
sparser grids fall back to binary search. Sized for piles of thousands of bodies."""

HALF_NEIGHBOURHOOD = np.array(
    [(0, 0, 0)]
    + [
        (dx, dy, dz)
        for dx in (-1, 0, 1)
        for dy in (-1, 0, 1)
        for dz in (-1, 0, 1)
        if (dx, dy, dz) > (0, 0, 0)
    ],
    dtype=np.int64,
)
"""The cell itself and the 13 lexicographically positive neighbour offsets (14, 3)."""


def candidate_pairs(
    model: Model, pos: np.ndarray, rot: np.ndarray, padding: float
) -> tuple[np.ndarray, np.ndarray]:
    """Candidate pairs (a, b), each (p,) int with a < b, whose bounding spheres may touch.

    Each unordered pair appears once; the order is deterministic (by construction).

    Args:
        pos: (n, 3) m, world frame, body centres.
        rot: (n, 3, 3) body-to-world rotations (planes' normals are their +z axes).
        padding: m, added to each bounding radius (contact margin).
    """
    collidable = model.body_collides
    is_plane = model.body_shape == ShapeType.PLANE
    planes = np.flatnonzero(collidable & is_plane)
    finite = np.flatnonzero(collidable & ~is_plane)
    radius = model.body_bound_radius

    pairs = [_plane_pairs(model, pos, rot, planes, finite, padding)]
    if finite.size >= 2:
        median = np.median(radius[finite])
        large_mask = radius[finite] > LARGE_BODY_FACTOR * median
        large, small = finite[large_mask], finite[~large_mask]
        pairs.append(_direct_pairs(large, finite))
        pairs.append(_grid_pairs(pos[small], radius[small] + padding, small))
    a = np.concatenate([p[0] for p in pairs])
    b = np.concatenate([p[1] for p in pairs])
    a, b = np.minimum(a, b), np.maximum(a, b)
    keep = _admissible(model, a, b)
    finite_pair = ~(is_plane[a] | is_plane[b])
    offset = pos[a] - pos[b]
    reach = np.where(finite_pair, radius[a] + radius[b] + 2.0 * padding, np.inf)
    keep &= np.einsum("ij,ij->i", offset, offset) <= reach * reach
    return a[keep], b[keep]


def _admissible(model: Model, a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """(p,) bool: distinct bodies, not both fixed, in the same world or one shared."""
    world_a, world_b = model.body_world[a], model.body_world[b]
    same_world = (world_a == world_b) | (world_a == SHARED_WORLD) | (world_b == SHARED_WORLD)
    return (a != b) & ~(model.body_fixed[a] & model.body_fixed[b]) & same_world


def _plane_pairs(model, pos, rot, planes, finite, padding) -> tuple[np.ndarray, np.ndarray]:
    """Plane-body pairs (P*F tested at once) whose padded bounding sphere reaches the plane.

    A plane's normal is its body +z axis, the last column of its rotation ``rot (n, 3, 3)``.
    """
    if planes.size == 0 or finite.size == 0:
        return np.zeros(0, np.int64), np.zeros(0, np.int64)
    normal = rot[planes][:, :, 2]  # (P, 3) world frame
    height = np.einsum("pfi,pi->pf", pos[finite][None, :, :] - pos[planes][:, None, :], normal)
    reach = model.body_bound_radius[finite][None, :] + padding
    plane_idx, body_idx = np.nonzero(height <= reach)
    return planes[plane_idx], finite[body_idx]


def _direct_pairs(large: np.ndarray, finite: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Every large body against every other finite body, each unordered pair once."""
    if large.size == 0:
        return np.zeros(0, np.int64), np.zeros(0, np.int64)
    a = np.repeat(large, finite.size)
    b = np.tile(finite, large.size)
    is_large = np.zeros(finite.max() + 1, dtype=bool)
    is_large[large] = True
    once = ~is_large[b] | (a < b)  # a large-large pair appears twice; keep a < b
    return a[once], b[once]


def _grid_pairs(
    centre: np.ndarray, radius: np.ndarray, body: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """Pairs of bodies whose centres lie in the same or adjacent grid cells.

    Args:
        centre: (m, 3) m, world frame. radius: (m,) m, padded bounding radii.
        body: (m,) int, the model indices of these bodies.
    """
    m = body.size
    if m < 2:
        return np.zeros(0, np.int64), np.zeros(0, np.int64)
    cell_size = 2.0 * radius.max()
    span = (centre.max(axis=0) - centre.min(axis=0)) / cell_size
    if not np.isfinite(span).all() or span.max() > GRID_SPAN_LIMIT:  # exploded: no grid fits
        first, second = np.triu_indices(m, k=1)
        return body[first], body[second]
    cell = np.floor((centre - centre.min(axis=0)) / cell_size).astype(np.int64) + 1
    dims = cell.max(axis=0) + 2  # one empty layer of cells on each side
    strides = np.array([dims[1] * dims[2], dims[2], 1])
    key = cell @ strides  # row-major cell index; the empty border keeps cell + offset inside
    order = np.argsort(key, kind="stable")
    sorted_key = key[order]
    rank = np.empty(m, dtype=np.int64)
    rank[order] = np.arange(m)

    n_cells = int(np.prod(dims))
    if n_cells <= CELL_TABLE_LIMIT:  # dense table: where each cell's run starts in sorted order
        cell_start = np.searchsorted(sorted_key, np.arange(n_cells + 1))

        def run(keys: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
            return cell_start[keys], cell_start[keys + 1]
    else:  # sparse scene: binary search per body

        def run(keys: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
            return (
                np.searchsorted(sorted_key, keys, side="left"),
                np.searchsorted(sorted_key, keys, side="right"),
            )

    firsts, seconds = [], []
    for offset in HALF_NEIGHBOURHOOD:
        start, end = run(key + int(offset @ strides))
        if not offset.any():
            start = np.maximum(start, rank + 1)  # own cell: each pair once
        count = np.maximum(end - start, 0)
        total = int(count.sum())
        if total == 0:
            continue
        owner = np.repeat(np.arange(m), count)
        within = np.arange(total) - np.repeat(np.cumsum(count) - count, count)
        firsts.append(body[owner])
        seconds.append(body[order[np.repeat(start, count) + within]])
    if not firsts:
        return np.zeros(0, np.int64), np.zeros(0, np.int64)
    return np.concatenate(firsts), np.concatenate(seconds)
