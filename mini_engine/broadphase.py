"""Broad phase: candidate body pairs whose bounding spheres overlap, without n² Python work.

Three kinds of candidates, all vectorized:

1. **planes** (infinite) against every finite body: signed distance of the
   centre along the plane normal minus the bounding radius;
2. **large** finite bodies (bounding radius over ``LARGE_BODY_FACTOR`` times
   the median), and finite bodies of the shared world, against every other finite
   body of their world (all worlds for a shared one), by one broadcast test;
3. **small** finite bodies through a uniform grid whose cell is the largest
   small-body bounding diameter: each body is hashed to the cell of its
   centre *in its own world*, and pairs are found in its own cell and 13 of its
   26 neighbours (each neighbour pair is visited once). Keying cells by world
   keeps many copies of one scene at the same place (an ensemble, or the
   observed states of one run measured at once) from meeting in one cell.

Every candidate then passes the same filter: both bodies collide, not both
fixed, same world (or one in the shared world), bounding spheres within the
padding, and the exact bounding-sphere test.
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np

from mini_engine.model import SHARED_WORLD, Model, per_model
from mini_engine.rotation import einsum
from mini_engine.shapes import ShapeType

LARGE_BODY_FACTOR = 4.0
"""A finite body whose bounding radius exceeds this multiple of the median radius is
tested against all bodies directly instead of inflating the grid cell; 4 keeps the grid
cell small for piles of equal spheres while walls and big boxes go to the direct test."""

GRID_SPAN_LIMIT = 1e6
"""Cells along one axis beyond which the bodies are too spread for a grid (an exploded
state, or bodies kilometres apart): every pair is tested directly instead, and int64 cell
keys can never overflow."""

KEY_LIMIT = 1 << 62
"""Largest cell key (cells per world times worlds) the grid uses; beyond it int64 keys could
overflow and every pair of one world is tested directly."""

CELL_TABLE_LIMIT = 1 << 20
"""Grids with at most this many cells (8 MiB of int64) get a dense cell-start table;
sparser grids fall back to binary search. Sized for piles of thousands of bodies."""

CELL_TABLE_CELLS_PER_BODY = 128
"""A grid with more cells than this per body (a pile spread over the ground) falls back to
binary search too: the table costs a pass over every cell, the search 28 lookups per body.
Measured (216 bodies): table 48 us and search 298 us at 64 cells a body, 1,459 us against
349 us at 1,024."""

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


class BroadPhasePlan(NamedTuple):
    """What the broad phase knows from the model alone, computed once per model.

    Attributes:
        planes, finite: (P,) and (F,) int, collidable planes and collidable finite bodies.
        finite_radius: (F,) m, the bounding radii of those finite bodies.
        plane_admissible: (P, F) bool, plane-body pairs that may touch (``admissible``).
        small: (s,) int, finite bodies that go through the grid.
        small_radius, small_world: (s,) m bounding radii and (s,) int worlds of those.
        small_all_admissible: every pair of small bodies is admissible (none fixed, one world),
            so their grid pairs skip the ``admissible`` test.
        direct_a, direct_b: (d,) int, a < b, the admissible direct pairs (large bodies
            against the finite bodies of their worlds), in ``direct_pairs`` order.
        direct_reach: (d,) m, ``r_a + r_b`` of those pairs (the padding is added per step).
        any_finite_pairs: there are direct pairs or at least two small bodies (else
            ``finite_pairs`` has nothing to test).
        grid_cache: the last step's grid (dims and cell keys) and its pairs, reused while every
            small body keeps its cell (``_grid_pairs``).
    """

    planes: np.ndarray
    finite: np.ndarray
    finite_radius: np.ndarray
    plane_admissible: np.ndarray
    small: np.ndarray
    small_radius: np.ndarray
    small_world: np.ndarray
    small_all_admissible: bool
    direct_a: np.ndarray
    direct_b: np.ndarray
    direct_reach: np.ndarray
    any_finite_pairs: bool
    grid_cache: dict


@per_model
def broadphase_plan(model: Model) -> BroadPhasePlan:
    """The ``BroadPhasePlan`` of ``model``, built on first use and kept per model."""
    collidable = model.body_collides
    is_plane = model.body_shape == ShapeType.PLANE
    planes = np.flatnonzero(collidable & is_plane)
    finite = np.flatnonzero(collidable & ~is_plane)
    radius = model.body_bound_radius
    plane_a, plane_b = np.repeat(planes, finite.size), np.tile(finite, planes.size)
    plane_admissible = admissible(
        model, np.minimum(plane_a, plane_b), np.maximum(plane_a, plane_b)
    ).reshape(planes.size, finite.size)
    empty = np.zeros(0, np.int64)
    small, direct_a, direct_b = empty, empty, empty
    if finite.size >= 2:
        median = np.median(radius[finite])
        large_mask = radius[finite] > LARGE_BODY_FACTOR * median
        large_mask |= model.body_world[finite] == SHARED_WORLD
        large, small = finite[large_mask], finite[~large_mask]
        a, b = direct_pairs(large, finite, model.body_world)
        a, b = np.minimum(a, b), np.maximum(a, b)
        keep = admissible(model, a, b)
        direct_a, direct_b = a[keep], b[keep]
    return BroadPhasePlan(
        planes=planes,
        finite=finite,
        finite_radius=radius[finite],
        plane_admissible=plane_admissible,
        small=small,
        small_radius=radius[small],
        small_world=model.body_world[small],
        small_all_admissible=bool(
            not model.body_fixed[small].any() and np.unique(model.body_world[small]).size <= 1
        ),
        direct_a=direct_a,
        direct_b=direct_b,
        direct_reach=radius[direct_a] + radius[direct_b],
        any_finite_pairs=bool(direct_a.size or small.size >= 2),
        grid_cache={},
    )


def candidate_pairs(
    model: Model, pos: np.ndarray, rot: np.ndarray, padding: float
) -> tuple[np.ndarray, np.ndarray]:
    """Candidate pairs (a, b), each (p,) int with a < b, whose bounding spheres may touch.

    Each unordered pair appears once; the order is deterministic (by construction):
    plane pairs (``plane_pairs``), then finite pairs (``finite_pairs``: direct, then grid).

    Args:
        pos: (n, 3) m, world frame, body centres.
        rot: (n, 3, 3) body-to-world rotations (planes' normals are their +z axes).
        padding: m, added to each bounding radius (contact margin).
    """
    plane, body = plane_pairs(model, pos, rot, padding)
    a, b = finite_pairs(model, pos, padding)
    return (
        np.concatenate([np.minimum(plane, body), a]),
        np.concatenate([np.maximum(plane, body), b]),
    )


def plane_pairs(
    model: Model, pos: np.ndarray, rot: np.ndarray, padding: float
) -> tuple[np.ndarray, np.ndarray]:
    """Admissible (plane, body) pairs, each (p,) int, whose padded bounding sphere reaches the
    plane (all P*F pairs tested at once), in plane-major order; the plane comes first.

    A plane's normal is its body +z axis, the last column of its rotation ``rot (n, 3, 3)``.
    Their bounding-sphere test always passes (a plane's radius is infinite). Arguments as
    in ``candidate_pairs``.
    """
    work = broadphase_plan(model)
    planes, finite = work.planes, work.finite
    if not (planes.size and finite.size):  # plane pairs are admissible or not by index
        return np.zeros(0, np.int64), np.zeros(0, np.int64)
    normal = rot.take(planes, axis=0)[:, :, 2]  # (P, 3) world frame
    offset = pos.take(finite, axis=0)[None, :, :] - pos.take(planes, axis=0)[:, None, :]
    height = einsum("pfi,pi->pf", offset, normal)
    plane_idx, body_idx = np.nonzero(
        (height <= work.finite_radius + padding) & work.plane_admissible
    )
    return planes.take(plane_idx), finite.take(body_idx)


def finite_pairs(model: Model, pos: np.ndarray, padding: float) -> tuple[np.ndarray, np.ndarray]:
    """Candidate pairs (a, b) of finite bodies, each (p,) int with a < b: the direct pairs of
    large bodies, then the grid pairs. Arguments as in ``candidate_pairs``."""
    work = broadphase_plan(model)
    if not work.any_finite_pairs:
        return np.zeros(0, np.int64), np.zeros(0, np.int64)
    a_parts, b_parts = [], []
    if work.direct_a.size:
        a, b = work.direct_a, work.direct_b
        offset = pos.take(a, axis=0) - pos.take(b, axis=0)
        reach = work.direct_reach + 2.0 * padding
        near = einsum("ij,ij->i", offset, offset) <= reach * reach
        a_parts.append(a[near]), b_parts.append(b[near])
    if work.small.size >= 2:
        small = work.small
        a, b = _grid_pairs(
            pos.take(small, axis=0),
            work.small_radius + padding,
            small,
            work.small_world,
            work.grid_cache,
        )
        if a.size:  # every test is symmetric in a and b: order the survivors only
            offset = pos.take(a, axis=0) - pos.take(b, axis=0)
            radius = model.body_bound_radius
            reach = radius.take(a) + radius.take(b) + 2.0 * padding
            keep = einsum("ij,ij->i", offset, offset) <= reach * reach
            if not work.small_all_admissible:
                keep &= admissible(model, a, b)
            kept = keep.nonzero()[0]
            a, b = a.take(kept), b.take(kept)
            a_parts.append(np.minimum(a, b)), b_parts.append(np.maximum(a, b))
    if not a_parts:
        return np.zeros(0, np.int64), np.zeros(0, np.int64)
    if len(a_parts) == 1:
        return a_parts[0], b_parts[0]
    return np.concatenate(a_parts), np.concatenate(b_parts)


def admissible(model: Model, a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """(p,) bool: distinct bodies, not both fixed, in the same world or one shared."""
    world_a, world_b = model.body_world.take(a), model.body_world.take(b)
    same_world = (world_a == world_b) | (world_a == SHARED_WORLD) | (world_b == SHARED_WORLD)
    return (a != b) & ~(model.body_fixed.take(a) & model.body_fixed.take(b)) & same_world


def direct_pairs(
    large: np.ndarray, finite: np.ndarray, body_world: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """Every large body against every other finite body of its world (every finite body for
    a large body of the shared world, and shared finite bodies for every large one), each
    unordered pair once. Order: by large body, then by world, then by index."""
    if large.size == 0:
        return np.zeros(0, np.int64), np.zeros(0, np.int64)
    own = body_world[finite][body_world[finite] != SHARED_WORLD]
    if own.size == 0 or np.all(own == own[0]):
        a = np.repeat(large, finite.size)  # one world: every large body against every body
        b = np.tile(finite, large.size)
    else:
        a, b = _same_world_pairs(large, finite, body_world)
    is_large = np.zeros(finite.max() + 1, dtype=bool)
    is_large[large] = True
    once = ~is_large[b] | (a < b)  # a large-large pair appears twice; keep a < b
    return a[once], b[once]


def _same_world_pairs(
    large: np.ndarray, finite: np.ndarray, body_world: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """(a, b): each large body with the finite bodies of its own world and of the shared world;
    a large body of the shared world with every finite body."""
    world = body_world[finite]
    order = np.argsort(world, kind="stable")
    by_world, sorted_world = finite[order], world[order]
    shared_finite = by_world[sorted_world == SHARED_WORLD]
    large_world = body_world[large]
    start = np.searchsorted(sorted_world, large_world, side="left")
    end = np.searchsorted(sorted_world, large_world, side="right")
    start = np.where(large_world == SHARED_WORLD, 0, start)  # shared: all worlds
    end = np.where(large_world == SHARED_WORLD, by_world.size, end)
    count = end - start
    owner = np.repeat(np.arange(large.size), count)
    within = np.arange(int(count.sum())) - np.repeat(np.cumsum(count) - count, count)
    a = [large[owner]]
    b = [by_world[np.repeat(start, count) + within]]
    own = large_world != SHARED_WORLD
    a.append(np.repeat(large[own], shared_finite.size))  # own-world large bodies see the shared
    b.append(np.tile(shared_finite, int(own.sum())))
    return np.concatenate(a), np.concatenate(b)


def _grid_pairs(
    centre: np.ndarray, radius: np.ndarray, body: np.ndarray, world: np.ndarray, cache: dict
) -> tuple[np.ndarray, np.ndarray]:
    """Pairs of bodies of one world whose centres lie in the same or adjacent grid cells.

    The pairs are a function of the grid's dims and the bodies' cell keys alone (for the
    fixed ``body`` and ``world`` of one plan): while both are bit-for-bit the last call's
    (a settled pile, bodies keeping their cells), ``cache`` gives the last pairs, read-only.

    Args:
        centre: (m, 3) m, world frame. radius: (m,) m, padded bounding radii.
        body: (m,) int, the model indices of these bodies. world: (m,) int, their worlds (>= 0).
        cache: the plan's ``grid_cache``, the last grid and its pairs.
    """
    m = body.size
    if m < 2:
        return np.zeros(0, np.int64), np.zeros(0, np.int64)
    cell_size = 2.0 * radius.max()
    lowest = centre.min(axis=0)
    span = (centre.max(axis=0) - lowest) / cell_size
    if not np.isfinite(span).all() or span.max() > GRID_SPAN_LIMIT:  # exploded: no grid fits
        first, second = np.triu_indices(m, k=1)
        return body[first], body[second]
    cell = np.floor((centre - lowest) / cell_size).astype(np.int64) + 1
    dims = cell.max(axis=0) + 2  # one empty layer of cells on each side
    strides = np.array([dims[1] * dims[2], dims[2], 1])
    per_world = int(np.prod(dims))
    n_cells = per_world * int(world.max() - world.min() + 1)
    if n_cells > KEY_LIMIT:  # keys would overflow
        first, second = np.triu_indices(m, k=1)
        same = world[first] == world[second]
        return body[first[same]], body[second[same]]
    # row-major cell index within the body's world; the empty border keeps cell + offset inside
    key = cell @ strides + (world - world.min()) * per_world
    grid = (dims.tobytes(), key.tobytes())
    if cache.get("grid") == grid:
        return cache["pairs"]
    pairs = _cell_pairs(key, strides, n_cells, body)
    for array in pairs:
        array.flags.writeable = False
    cache.update(grid=grid, pairs=pairs)
    return pairs


def _cell_pairs(
    key: np.ndarray, strides: np.ndarray, n_cells: int, body: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """The pairs of ``_grid_pairs`` from the cell ``key (m,)`` of each of ``body (m,)``, the
    grid's ``strides (3,)`` and its ``n_cells`` (cells of every world)."""
    m = body.size
    order = np.argsort(key, kind="stable")
    sorted_key = key[order]
    rank = np.empty(m, dtype=np.int64)
    rank[order] = np.arange(m)

    if n_cells <= min(CELL_TABLE_LIMIT, CELL_TABLE_CELLS_PER_BODY * m):
        # dense table: where each cell's run starts in sorted order (the bodies before it)
        cell_start = np.zeros(n_cells + 1, dtype=np.int64)
        np.cumsum(np.bincount(key, minlength=n_cells), out=cell_start[1:])

        def run(keys: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
            return cell_start[keys], cell_start[keys + 1]
    else:  # sparse scene: binary search per body

        def run(keys: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
            return (
                np.searchsorted(sorted_key, keys, side="left"),
                np.searchsorted(sorted_key, keys, side="right"),
            )

    # all 14 neighbourhoods at once, (14, m): offset-major, then body order, as one flat list;
    # looked up in sorted order (each offset's keys ascending, so the binary searches walk the
    # sorted keys once) and put back in body order
    sorted_start, sorted_end = run(sorted_key[None, :] + (HALF_NEIGHBOURHOOD @ strides)[:, None])
    start, end = sorted_start[:, rank], sorted_end[:, rank]
    start[0] = np.maximum(start[0], rank + 1)  # own cell (offset 0): each pair once
    count = np.maximum(end - start, 0).ravel()
    total = int(count.sum())
    if total == 0:
        return np.zeros(0, np.int64), np.zeros(0, np.int64)
    # the j-th pair of a run is the run's start + j: start - (pairs before the run) + arange
    run_shift = start.ravel() - (np.cumsum(count) - count)
    first = np.repeat(np.tile(body, HALF_NEIGHBOURHOOD.shape[0]), count)
    second = body.take(order.take(np.arange(total) + np.repeat(run_shift, count)))
    return first, second
