"""The shortcuts of mini_engine's box-contact work give exactly what the long way gives.

Each shortcut reorganises the NumPy calls of a box-contact phase on the promise of the same
numbers bit for bit: ``einsum`` calls NumPy's C kernel without its Python layer, the 15 box
axes come from one broadcast cross product and ``norm``, Sutherland–Hodgman clipping looks
up its slots and packs its vertices without ``take_along_axis``, and a patch of at most 4
points skips the manifold reduction. Each test keeps the long way (the code it replaced) as
the reference and compares bytes.
"""

from __future__ import annotations

import numpy as np
import pytest

from mini_engine import Body, Box, Plane, Settings, build_model, step
from mini_engine.contacts import Contacts
from mini_engine.narrowphase import (
    CLIP_CAPACITY,
    EDGE_AXIS_MIN_SIN,
    MAX_MANIFOLD_POINTS,
    _box_axes,
    _clip_polygon,
    _cross,
    _reduce_manifold,
)
from mini_engine.rotation import einsum, quat_to_matrix, rotation_quat
from mini_engine.solver import ContactReport

CASES = 300
"""Random configurations per test: polygons of every vertex count from 1 to 8 many times."""

REST_TOLERANCE = 1e-3
"""m. A 10 cm box settled on its face for 0.2 s sits at its half height within the
Baumgarte slop and one step's sink (millimetres at most; measured 1e-5 m)."""


def _random_rotations(rng: np.random.Generator, k: int) -> np.ndarray:
    return quat_to_matrix(rotation_quat(rng.normal(size=(k, 3))))


@pytest.mark.parametrize(
    ("subscripts", "shapes"),
    [
        ("ij,ij->i", [(7, 12), (7, 12)]),
        ("ikj,ij->ik", [(7, 2, 12), (7, 12)]),
        ("ik,ikj->ij", [(7, 2), (7, 2, 12)]),
        ("nij,nj->ni", [(7, 3, 3), (7, 3)]),
        ("kji,kmj->kmi", [(7, 3, 3), (7, 15, 3)]),
    ],
)
def test_einsum_is_numpy_einsum_bit_for_bit(subscripts, shapes):
    rng = np.random.default_rng(11)
    operands = [rng.normal(size=shape) for shape in shapes]
    assert einsum(subscripts, *operands).tobytes() == np.einsum(subscripts, *operands).tobytes()


def _box_axes_long_way(rot_a, rot_b):
    """``_box_axes`` as it was: 15 separate columns and crosses, stacked, ``np.linalg.norm``."""
    faces = [rot_a[:, :, i] for i in range(3)] + [rot_b[:, :, j] for j in range(3)]
    edges = [_cross(rot_a[:, :, i], rot_b[:, :, j]) for i in range(3) for j in range(3)]
    axes = np.stack(faces + edges, axis=1)
    length = np.linalg.norm(axes, axis=2)
    usable = np.ones(length.shape, dtype=bool)
    usable[:, 6:] = length[:, 6:] > EDGE_AXIS_MIN_SIN
    return axes / np.where(usable, length, 1.0)[..., None], usable


def test_box_axes_are_the_long_way_bit_for_bit():
    rng = np.random.default_rng(5)
    rot_a, rot_b = _random_rotations(rng, CASES), _random_rotations(rng, CASES)
    rot_b[:10] = rot_a[:10]  # a_i parallel to b_i: the edge axes 6 + 4 i unusable
    axes, usable = _box_axes(rot_a, rot_b)
    expected_axes, expected_usable = _box_axes_long_way(rot_a, rot_b)
    assert np.array_equal(usable, expected_usable) and not usable[:10, [6, 10, 14]].any()
    assert axes[usable].tobytes() == expected_axes[usable].tobytes()


def _clip_polygon_long_way(polygon, count, coord, sign, bound):
    """``_clip_polygon`` as it was: slot arithmetic, ``take_along_axis`` and ``np.stack``."""
    n, capacity, _ = polygon.shape
    slots = np.arange(capacity)[None, :]
    used = slots < count[:, None]
    following = np.where(slots + 1 < count[:, None], slots + 1, 0)
    nxt = np.take_along_axis(polygon, following[..., None], axis=1)
    dist_here = sign * polygon[..., coord] - bound[:, None]
    dist_next = sign * nxt[..., coord] - bound[:, None]
    keep_here = used & (dist_here <= 0.0)
    crosses = used & ((dist_here <= 0.0) != (dist_next <= 0.0))
    fraction = dist_here / np.where(crosses, dist_here - dist_next, 1.0)
    crossing = polygon + fraction[..., None] * (nxt - polygon)
    candidates = np.stack([polygon, crossing], axis=2).reshape(n, 2 * capacity, 3)
    present = np.stack([keep_here, crosses], axis=2).reshape(n, 2 * capacity)
    order = np.argsort(~present, axis=1, kind="stable")[:, :capacity]
    clipped = np.take_along_axis(candidates, order[..., None], axis=1)
    return clipped, np.minimum(present.sum(axis=1), capacity)


@pytest.mark.parametrize(("coord", "sign"), [(0, 1.0), (0, -1.0), (1, 1.0), (1, -1.0)])
def test_clipping_keeps_the_vertices_of_the_long_way_bit_for_bit(coord, sign):
    rng = np.random.default_rng(7 + coord)
    polygon = rng.normal(size=(CASES, CLIP_CAPACITY, 3))
    count = rng.integers(1, CLIP_CAPACITY + 1, size=CASES)
    bound = rng.uniform(-0.5, 0.5, size=CASES)
    clipped, clipped_count = _clip_polygon(polygon, count, coord, sign, bound)
    expected, expected_count = _clip_polygon_long_way(polygon, count, coord, sign, bound)
    assert np.array_equal(clipped_count, expected_count)
    assert set(clipped_count.tolist()) == set(range(CLIP_CAPACITY + 1))  # every count met
    used = np.arange(CLIP_CAPACITY) < clipped_count[:, None]  # the slots anything reads
    assert clipped[used].tobytes() == expected[used].tobytes()


def test_a_patch_of_at_most_four_points_keeps_them_all_in_slot_order():
    """The shortcut (no reduction) gives the slots the reduction's own rule gives them."""
    rng = np.random.default_rng(9)
    plane_xy = rng.normal(size=(CASES, CLIP_CAPACITY, 2))
    depth = rng.normal(size=(CASES, CLIP_CAPACITY))
    valid = np.zeros((CASES, CLIP_CAPACITY), dtype=bool)
    for row, points in enumerate(rng.integers(0, MAX_MANIFOLD_POINTS + 1, size=CASES)):
        valid[row, rng.choice(CLIP_CAPACITY, size=points, replace=False)] = True
    order, keep = _reduce_manifold(plane_xy, depth, valid)
    expected_order = np.argsort(~valid, axis=1, kind="stable")[:, :MAX_MANIFOLD_POINTS]
    assert np.array_equal(order, expected_order)
    assert np.array_equal(keep, np.take_along_axis(valid, expected_order, axis=1))


def test_a_step_without_contacts_reports_the_shared_read_only_empty_record():
    model, state = build_model([Body(Box((0.1, 0.2, 0.3)), mass=1.0, position=(0, 0, 5.0))])
    result = step(model, state, Settings(dt=1e-3))
    assert result.contacts is ContactReport.empty() and result.contacts.contacts is Contacts.empty()
    assert result.contacts.contacts.count == 0 and result.state.contact_memory is None
    with pytest.raises(ValueError, match="read-only"):
        Contacts.empty().depth[...] = 1.0


def test_a_box_resting_on_the_ground_steps_alike_with_the_empty_record_shared():
    """A box that lands (contacts appear after steps without any) is unaffected by sharing."""
    bodies = [
        Body(Plane(), fixed=True),
        Body(Box((0.1, 0.1, 0.1)), mass=1.0, position=(0, 0, 0.12)),
    ]
    model, state = build_model(bodies)
    for _ in range(200):
        state, report = step(model, state, Settings(dt=1e-3))
    assert report.contacts.count == 4
    height = state.pos[1, 2]
    assert abs(height - 0.1) < REST_TOLERANCE, f"box centre at {height} m, expected 0.1 m"
