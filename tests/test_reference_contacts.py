"""The measurement's own contact finder (``validation.reference.contacts``) against closed forms.

Each shape pair is placed where its deepest contact is known by hand (depth, normal from A to
B, the point midway between the surfaces, the centre of a tied patch); then the batched finder
(pairs, margin, states); then agreement with mini_engine's narrow phase on random poses, a
cross-check of two independent implementations (mini_engine is the engine under test: it is
imported here, in a test, never by the finder).
"""

from __future__ import annotations

import numpy as np
import pytest

from validation.reference import contacts
from validation.reference.rotation import quat_to_matrix

ROUND_OFF = 1e-12
"""m. The closed forms below are exact up to a few ulps of metre-scale coordinates."""

EYE = np.eye(3)


def turn(axis, angle: float) -> np.ndarray:
    """(3, 3) rotation by ``angle`` rad about unit ``axis``."""
    axis = np.asarray(axis, dtype=float) / np.linalg.norm(axis)
    return quat_to_matrix(np.concatenate([[np.cos(angle / 2)], np.sin(angle / 2) * axis]))


def one(kind_a, kind_b, a, b):
    """The finder's contact of a single pair, as plain arrays: ``a``, ``b`` each a shape's
    (position, rotation, size)."""
    found = contacts.PAIRS[(kind_a, kind_b)](*(np.asarray(x, dtype=float)[None] for x in (*a, *b)))
    return found.depth[0], found.normal[0], found.point[0]


def check(found, depth, normal, point):
    got_depth, got_normal, got_point = found
    assert got_depth == pytest.approx(depth, abs=ROUND_OFF)
    np.testing.assert_allclose(got_normal, normal, atol=ROUND_OFF)
    np.testing.assert_allclose(got_point, point, atol=ROUND_OFF)


GROUND = ((0, 0, 0), EYE, (0, 0, 0))


def test_a_sphere_on_the_ground_overlaps_by_radius_minus_height():
    found = one(contacts.PLANE, contacts.SPHERE, GROUND, ((1, 2, 0.45), EYE, (0.5, 0, 0)))
    check(found, 0.05, (0, 0, 1), (1, 2, -0.025))


def test_a_tilted_ground_measures_along_its_own_normal():
    tilt = turn((1, 0, 0), 0.3)
    normal = tilt[:, 2]
    centre = np.array([0.0, 0.0, 1.0]) + 0.2 * normal  # 0.2 above the plane through (0, 0, 1)
    found = one(
        contacts.PLANE, contacts.SPHERE, ((0, 0, 1), tilt, (0, 0, 0)), (centre, EYE, (0.25, 0, 0))
    )
    check(found, 0.05, normal, centre - normal * 0.225)


def test_a_flat_box_on_the_ground_touches_at_its_face_centre():
    """Four corners tie: the point is their centroid, under the centre, not a corner."""
    found = one(contacts.PLANE, contacts.BOX, GROUND, ((3, 0, 0.19), EYE, (0.5, 0.3, 0.2)))
    check(found, 0.01, (0, 0, 1), (3, 0, -0.005))


def test_a_box_on_its_edge_touches_at_the_edge_middle_and_a_tipped_one_at_its_corner():
    edge = turn((1, 0, 0), np.pi / 4)  # resting on its edge along x: corners (±0.5, -0.3, -0.2)
    centre = (0.3 + 0.2) / np.sqrt(2) - 0.001
    found = one(contacts.PLANE, contacts.BOX, GROUND, ((0, 0, centre), edge, (0.5, 0.3, 0.2)))
    check(found, 0.001, (0, 0, 1), (0, (-0.3 + 0.2) / np.sqrt(2), -0.0005))
    corner = turn((1, 1, 0), 0.4)
    lowest = (corner @ (contacts._CUBE * [0.5, 0.3, 0.2]).T)[2].min()
    found = one(
        contacts.PLANE, contacts.BOX, GROUND, ((0, 0, -lowest - 0.002), corner, (0.5, 0.3, 0.2))
    )
    assert found[0] == pytest.approx(0.002, abs=ROUND_OFF)
    assert found[2][2] == pytest.approx(-0.001, abs=ROUND_OFF)


def test_a_capsule_lying_on_the_ground_touches_at_its_middle_and_standing_at_its_end():
    lying = turn((0, 1, 0), np.pi / 2)
    check(
        one(contacts.PLANE, contacts.CAPSULE, GROUND, ((1, 0, 0.09), lying, (0.1, 0.4, 0))),
        0.01,
        (0, 0, 1),
        (1, 0, -0.005),
    )
    check(
        one(contacts.PLANE, contacts.CAPSULE, GROUND, ((0, 0, 0.49), EYE, (0.1, 0.4, 0))),
        0.01,
        (0, 0, 1),
        (0, 0, -0.005),
    )


def test_two_spheres_touch_along_their_line_of_centres():
    direction = np.array([1.0, 2.0, 2.0]) / 3.0
    found = one(
        contacts.SPHERE,
        contacts.SPHERE,
        ((0, 0, 0), EYE, (0.5, 0, 0)),
        (0.7 * direction, EYE, (0.3, 0, 0)),
    )
    check(found, 0.1, direction, direction * 0.45)


def test_coincident_spheres_fall_back_to_up():
    found = one(
        contacts.SPHERE,
        contacts.SPHERE,
        ((1, 1, 1), EYE, (0.5, 0, 0)),
        ((1, 1, 1), EYE, (0.3, 0, 0)),
    )
    check(found, 0.8, (0, 0, 1), (1, 1, 1.1))


def test_a_sphere_meets_a_capsule_side_and_cap():
    side = one(
        contacts.SPHERE,
        contacts.CAPSULE,
        ((0.35, 0, 0.1), EYE, (0.2, 0, 0)),
        ((0, 0, 0), EYE, (0.2, 0.5, 0)),
    )
    check(side, 0.05, (-1, 0, 0), (0.175, 0, 0.1))
    cap = one(
        contacts.SPHERE,
        contacts.CAPSULE,
        ((0, 0, 0.85), EYE, (0.2, 0, 0)),
        ((0, 0, 0), EYE, (0.2, 0.5, 0)),
    )
    check(cap, 0.05, (0, 0, -1), (0, 0, 0.675))


def test_crossed_capsules_meet_at_their_axes_closest_points_and_parallel_ones_at_the_overlap_middle():
    along_x, along_y = turn((0, 1, 0), np.pi / 2), turn((1, 0, 0), np.pi / 2)
    crossed = one(
        contacts.CAPSULE,
        contacts.CAPSULE,
        ((0, 0, 0), along_x, (0.1, 1, 0)),
        ((0, 0, 0.19), along_y, (0.1, 1, 0)),
    )
    check(crossed, 0.01, (0, 0, 1), (0, 0, 0.095))
    parallel = one(
        contacts.CAPSULE,
        contacts.CAPSULE,
        ((0, 0, 0), along_x, (0.1, 1, 0)),
        ((1.5, 0, 0.19), along_x, (0.1, 1, 0)),
    )
    check(parallel, 0.01, (0, 0, 1), (0.75, 0, 0.095))  # the overlap is x in [0.5, 1]


def test_a_sphere_meets_a_box_face_edge_corner_and_from_inside():
    half = (0.5, 0.3, 0.2)
    face = one(
        contacts.SPHERE, contacts.BOX, ((0, 0, 0.35), EYE, (0.2, 0, 0)), ((0, 0, 0), EYE, half)
    )
    check(face, 0.05, (0, 0, -1), (0, 0, 0.175))
    edge_centre = np.array([0.6, 0.0, 0.3])  # 0.1 beyond the x face and the z face
    edge = one(
        contacts.SPHERE, contacts.BOX, (edge_centre, EYE, (0.2, 0, 0)), ((0, 0, 0), EYE, half)
    )
    out = np.array([1.0, 0.0, 1.0]) / np.sqrt(2)
    gap = 0.1 * np.sqrt(2)
    midway = 0.5 * ((edge_centre - 0.2 * out) + np.array([0.5, 0.0, 0.2]))
    check(edge, 0.2 - gap, -out, midway)
    inside = one(
        contacts.SPHERE, contacts.BOX, ((0.45, 0, 0), EYE, (0.1, 0, 0)), ((0, 0, 0), EYE, half)
    )
    check(inside, 0.15, (-1, 0, 0), (0.425, 0, 0))  # leaves through +x: surfaces at 0.35, 0.5


def test_a_capsule_lying_on_a_box_touches_at_the_middle_of_what_lies_on_it():
    lying = turn((0, 1, 0), np.pi / 2)  # along x, from x = 0.2 to 1.0 at its centre 0.6
    found = one(
        contacts.CAPSULE,
        contacts.BOX,
        ((0.6, 0, 0.29), lying, (0.1, 0.4, 0)),
        ((0, 0, 0), EYE, (0.5, 0.3, 0.2)),
    )
    check(found, 0.01, (0, 0, -1), (0.35, 0, 0.195))  # the part over the box: x in [0.2, 0.5]


def test_a_capsule_through_a_box_leaves_through_the_face_of_least_overlap():
    found = one(
        contacts.CAPSULE,
        contacts.BOX,
        ((0, 0, 0.15), EYE, (0.05, 0.05, 0)),
        ((0, 0, 0), EYE, (0.5, 0.3, 0.2)),
    )
    # segment z in [0.1, 0.2]: out through +z by 0.2 + 0.05 - 0.1
    assert found[0] == pytest.approx(0.15, abs=ROUND_OFF)
    np.testing.assert_allclose(found[1], (0, 0, -1), atol=ROUND_OFF)


def test_stacked_boxes_touch_at_the_centre_of_their_overlap_patch():
    lower, upper = (0.5, 0.5, 0.2), (0.2, 0.2, 0.1)
    found = one(contacts.BOX, contacts.BOX, ((0, 0, 0), EYE, lower), ((0.4, 0, 0.299), EYE, upper))
    # the upper box's bottom face spans x in [0.2, 0.6]; the lower's top face ends at 0.5
    check(found, 0.001, (0, 0, 1), (0.35, 0, 0.1995))


def test_crossed_box_edges_touch_at_their_closest_points():
    ridge = turn((1, 0, 0), np.pi / 4)  # lower box: an edge along x on top
    crossed = turn((0, 1, 0), np.pi / 4)  # upper box: an edge along y at its bottom
    half = (0.5, 0.5, 0.5)
    top = 0.5 * np.sqrt(2)
    found = one(
        contacts.BOX,
        contacts.BOX,
        ((0, 0, 0), ridge, half),
        ((0, 0, 2 * top - 0.01), crossed, half),
    )
    check(found, 0.01, (0, 0, 1), (0, 0, top - 0.005))


def test_the_finder_orders_pairs_drops_fixed_pairs_and_applies_the_margin():
    shapes = contacts.Shapes(
        kind=np.array([contacts.BOX, contacts.SPHERE, contacts.SPHERE, contacts.PLANE]),
        size=np.array([[0.5, 0.5, 0.5], [0.5, 0, 0], [0.5, 0, 0], [0, 0, 0]]),
        fixed=np.array([True, False, False, True]),
    )
    assert shapes.can_touch
    pos = np.array(
        [
            [[0, 0, -10.0], [0, 0, 0.5 - 2e-7], [5, 0, 0.5 + 5e-7], [0, 0, 0]],
            [[0, 0, 0.95], [0, 0, 3], [9, 0, 3], [0, 0, 0]],  # the ground is fixed: box skipped
        ]
    )
    rot = np.broadcast_to(EYE, (2, 4, 3, 3))
    found = contacts.find_contacts(shapes, pos, rot, 1e-6)
    assert found.observation.tolist() == [0, 0]
    assert list(zip(found.body_a, found.body_b, strict=True)) == [(3, 1), (3, 2)]
    np.testing.assert_allclose(found.depth, [2e-7, -5e-7], atol=ROUND_OFF)
    nothing = contacts.find_contacts(shapes, pos, rot, 1e-7)
    assert nothing.body_b.tolist() == [1]
    assert contacts.find_contacts(shapes, pos[:0], rot[:0], 1e-6).depth.size == 0


def test_the_finder_batches_many_states_like_one_at_a_time(monkeypatch):
    rng = np.random.default_rng(5)
    shapes = contacts.Shapes(
        kind=np.array(
            [contacts.SPHERE, contacts.CAPSULE, contacts.BOX, contacts.BOX, contacts.PLANE]
        ),
        size=np.array([[0.3, 0, 0], [0.2, 0.3, 0], [0.3, 0.2, 0.1], [0.2, 0.2, 0.2], [0, 0, 0]]),
        fixed=np.array([False, False, False, False, True]),
    )
    pos = rng.uniform(-0.4, 0.6, (40, 5, 3))
    pos[:, 4] = 0.0
    quat = rng.normal(size=(40, 5, 4))
    rot = quat_to_matrix(quat / np.linalg.norm(quat, axis=-1, keepdims=True))
    whole = contacts.find_contacts(shapes, pos, rot, 1e-6)
    monkeypatch.setattr(contacts, "PAIR_STATES_PER_CALL", 7)
    pieces = contacts.find_contacts(shapes, pos, rot, 1e-6)
    assert whole.depth.size > 40
    for name in contacts.Found.__dataclass_fields__:
        np.testing.assert_array_equal(getattr(whole, name), getattr(pieces, name))


def random_pairs(kind_a: int, kind_b: int, count: int, rng) -> tuple[np.ndarray, ...]:
    def sizes(kind):
        size = np.zeros((count, 3))
        if kind == contacts.SPHERE:
            size[:, 0] = rng.uniform(0.1, 1, count)
        elif kind == contacts.CAPSULE:
            size[:, 0], size[:, 1] = rng.uniform(0.1, 0.5, count), rng.uniform(0, 1, count)
        elif kind == contacts.BOX:
            size[:] = rng.uniform(0.1, 1, (count, 3))
        return size

    def rotations():
        quat = rng.normal(size=(count, 4))
        return quat_to_matrix(quat / np.linalg.norm(quat, axis=1, keepdims=True))

    rot_a = np.broadcast_to(EYE, (count, 3, 3)).copy() if kind_a == contacts.PLANE else rotations()
    pos_b = rng.uniform(-1.5, 1.5, (count, 3))
    return np.zeros((count, 3)), rot_a, sizes(kind_a), pos_b, rotations(), sizes(kind_b)


MINI_PAIRS = [pair for pair in contacts.PAIRS if contacts.CYLINDER not in pair]
"""The pairs mini_engine's narrow phase has (no cylinder: tests/test_cylinder_reference.py
checks the cylinder pairs against a sampled surface instead)."""


@pytest.mark.parametrize("pair", MINI_PAIRS, ids=lambda p: "-".join(contacts.SHAPES[k] for k in p))
def test_the_finder_agrees_with_an_independent_narrow_phase_on_random_poses(pair):
    """mini_engine's deepest contact of each touching pair: the same depth, normal and point
    to round-off (random poses have no ties), except where a capsule's segment passes through
    a box, which mini_engine measures at the segment's middle and the finder by the face of
    least overlap (both deeper than the capsule's radius: a deep penetration)."""
    from mini_engine.narrowphase import NARROW_PHASE
    from mini_engine.shapes import ShapeType

    arrays = random_pairs(*pair, 2000, np.random.default_rng(sum(pair)))
    mine = contacts.PAIRS[pair](*arrays)
    theirs = NARROW_PHASE[tuple(ShapeType(k) for k in pair)](*arrays, 10.0)
    order = np.lexsort((-theirs.depth, theirs.pair))
    first = np.ones(order.size, dtype=bool)
    first[1:] = theirs.pair[order][1:] != theirs.pair[order][:-1]
    deepest, which = order[first], theirs.pair[order[first]]
    touching = theirs.depth[deepest] > 0
    if pair == (contacts.CAPSULE, contacts.BOX):
        touching &= theirs.depth[deepest] < arrays[2][which, 0]
    assert touching.sum() > 200
    deepest, which = deepest[touching], which[touching]
    np.testing.assert_allclose(mine.depth[which], theirs.depth[deepest], atol=1e-12)
    np.testing.assert_allclose(mine.normal[which], theirs.normal[deepest], atol=1e-11)
    np.testing.assert_allclose(mine.point[which], theirs.point[deepest], atol=1e-12)


def test_a_large_scene_finds_in_grid_cells_what_every_pair_finds(monkeypatch):
    """Spheres of two sizes scattered so that many touch, across cell borders and far out
    (clipped cells), in a few states: the grid's candidates give the same contacts."""
    rng = np.random.default_rng(8)
    count, states = 300, 3
    kind = np.array([contacts.SPHERE] * count + [contacts.BOX, contacts.PLANE])
    size = np.zeros((count + 2, 3))
    size[:count, 0] = rng.choice([0.05, 0.2], count)
    size[count] = (0.3, 0.1, 0.2)
    shapes = contacts.Shapes(kind, size, np.array([False] * count + [True, True]))
    pos = rng.uniform(-1.5, 1.5, (states, count + 2, 3))
    pos[:, :5] *= 1e15  # far away: their cells are clipped together
    pos[:, -1] = 0.0
    rot = np.broadcast_to(EYE, (states, count + 2, 3, 3))
    grid = contacts.find_contacts(shapes, pos, rot, 1e-6)
    monkeypatch.setattr(contacts, "ALL_PAIRS", 10**9)
    every = contacts.find_contacts(shapes, pos, rot, 1e-6)
    assert grid.depth.size > 300
    for name in contacts.Found.__dataclass_fields__:
        np.testing.assert_array_equal(getattr(grid, name), getattr(every, name))
