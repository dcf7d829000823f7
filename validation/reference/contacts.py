"""Where shapes touch: the measurement's own contact finder, from the closed forms.

The measurement finds contacts in every engine's observed states (impacts, the overlap check,
``penetration_max``), so it must not borrow the narrow phase of mini_engine, the engine under
test: a mistake there would move every engine's impact and penetration rows. This module is
that finder, written from the geometry alone and sharing no code with any engine.

Shapes (``SHAPES``): an infinite plane (through its body position, normal = its body +z), a
sphere (radius), a capsule (radius, half length of its segment along body z), a box (half
extents) and a cylinder (radius, half length along body z, flat ends). A shape may be placed
in its body (``Shapes.offset``, ``Shapes.turn``): its pose is the body's pose composed with
its placement. Each pair gives **one** contact, the deepest, which is all the measurement
reads:

- ``depth`` m, positive when the shapes overlap, minus their distance when they are apart;
- ``normal`` unit, from A to B (A has the lower shape code, ``SHAPES``'s order);
- ``point`` m, midway between the two surfaces along the normal.

Where several points are deepest together (a box flat on the ground, a capsule lying on it,
two faces resting on each other: every point of a face or segment within ``TIE`` of the
deepest) the point is their centroid, the centre of the contact patch, so that it does not
depend on the order of corners or on round-off.

The closed forms, per pair (each batched over pairs with NumPy):

- plane and sphere, capsule or box: the lowest point of the shape (the sphere's centre; the
  capsule's segment end; the box's corner) against the plane;
- sphere and sphere, capsule or box; capsule and capsule or box: the closest points of the
  cores (a point, a segment; a box's solid) and the two radii;
- box and box: the separating axis (15 axes: 3 faces each, 9 edge products) of least overlap,
  faces preferred over near-equal edges (``FACE_PREFERENCE``); on a face axis the deepest
  points of the incident face clipped to the reference face, on an edge axis the closest
  points of the two edges.

A core that passes through a box (a capsule's segment or a sphere's centre inside it) is
pushed out through the box face of least overlap.

Cylinders:

- plane and cylinder: per flat end, its lowest rim point, or the end's centre when the whole
  end lies level within ``TIE`` (its rim's heights span ``2 r sin θ <= TIE``): standing on an
  end, the contact is the end's centre; lying on its side, the two ends' rim points tie and
  the contact is the middle of the lowest line; tilted on its rim, the lowest rim point;
- sphere and cylinder: the point of the solid cylinder closest to the sphere's centre; a
  centre inside the cylinder leaves through the side or the end of least overlap;
- a cylinder against a capsule, a box or a cylinder has no closed form here yet (``PAIRS``
  leaves them out: ``measured`` is false): a scene where such a pair can touch is refused by
  ``physval check``.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

SHAPES = ("plane", "sphere", "capsule", "box", "cylinder")
"""Shape codes, by index: a pair's body A is the shape of lower code (the ground, a plane,
always A)."""

PLANE, SPHERE, CAPSULE, BOX, CYLINDER = range(len(SHAPES))

TIE = 1e-9
"""m. Points of one pair within this of the deepest are deepest together (their centroid is
the contact point): a million times the round-off of metre-scale float64 coordinates
(2e-16 m), far below any physical feature of the library's scenes (0.5 mm and up)."""

DEGENERATE = 1e-12
"""m, or unitless for unit vectors. Below this a direction is undefined (coincident centres,
parallel segments, parallel box edges): the fallback direction or formula is used. Four orders
of magnitude above the round-off of metre-scale float64 values."""

EDGE_AXIS_MIN_SIN = 1e-3
"""Unitless. A box-box edge axis ``a_i × b_j`` whose length (the sine between the edges) is
below this is left out: parallel edges need no axis of their own (the face axes separate
them), and a normalised near-zero product would carry round-off amplified by 1/sin."""

FACE_PREFERENCE = 0.95
"""Box-box: an edge axis is taken over the best face axis only if its overlap is below 95 %
of the face's less 1 % of the smaller box's smallest half extent (``FACE_PREFERENCE_ABSOLUTE``),
and a face of B over a face of A likewise (Box2D-Lite's ``relativeTol`` and ``absoluteTol``).
Resting boxes, whose edge and face overlaps are equal, then touch face to face."""

FACE_PREFERENCE_ABSOLUTE = 0.01
"""The absolute part of ``FACE_PREFERENCE``, a fraction of the smallest half extent."""

UP = np.array([0.0, 0.0, 1.0])
"""Fallback normal where the direction between two cores is undefined (coincident centres)."""

_QUAD = np.array([[1.0, 1.0], [-1.0, 1.0], [-1.0, -1.0], [1.0, -1.0]])
"""A box face's corners, in order around it, as signs of its two in-face half extents."""

_CUBE = np.array([[x, y, z] for x in (-1.0, 1.0) for y in (-1.0, 1.0) for z in (-1.0, 1.0)])
"""A box's 8 corners as signs of its half extents."""

_CLIP_SLOTS = 8
"""Vertices a quadrilateral clipped by four slabs can have at most (each cut adds one)."""


@dataclass(frozen=True)
class PairContact:
    """The deepest contact of each of ``k`` pairs (module docstring): ``depth (k,)`` m,
    ``normal (k, 3)`` unit from A to B, ``point (k, 3)`` m, world frame."""

    depth: np.ndarray
    normal: np.ndarray
    point: np.ndarray


# --- small vector helpers -------------------------------------------------------------


def _dot(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    return np.einsum("...i,...i->...", a, b)


def _unit(vector: np.ndarray, fallback: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """``vector / |vector|`` and ``|vector|``; ``fallback`` where the length is degenerate."""
    length = np.linalg.norm(vector, axis=-1)
    safe = length > DEGENERATE
    unit = vector / np.where(safe, length, 1.0)[..., None]
    return np.where(safe[..., None], unit, fallback), length


def _between_spheres(
    centre_a: np.ndarray, radius_a: np.ndarray, centre_b: np.ndarray, radius_b: np.ndarray
) -> PairContact:
    """Two spheres (the closest points of two cores with their radii)."""
    normal, distance = _unit(centre_b - centre_a, UP)
    depth = radius_a + radius_b - distance
    return PairContact(depth, normal, centre_a + normal * (radius_a - 0.5 * depth)[:, None])


def _segment(pos: np.ndarray, rot: np.ndarray, half_length: np.ndarray):
    """A capsule's core: its segment's start (k, 3) and direction times length (k, 3)."""
    axis = rot[:, :, 2] * half_length[:, None]
    return pos - axis, 2.0 * axis


# --- the plane against each shape --------------------------------------------------------


def _against_plane(plane_pos, plane_rot, points: np.ndarray, radius: np.ndarray) -> PairContact:
    """A plane and the candidate lowest points ``points (k, m, 3)`` of a shape whose surface
    is ``radius (k,)`` beyond them (0 for a box's corners): the deepest, tied ones averaged."""
    normal = plane_rot[:, :, 2]
    height = _dot(points - plane_pos[:, None, :], normal[:, None, :])
    lowest = height.min(axis=1)
    tied = (height <= lowest[:, None] + TIE).astype(float)
    centre = np.einsum("km,kmi->ki", tied, points) / tied.sum(axis=1)[:, None]
    depth = radius - lowest
    point = centre - normal * (lowest + radius)[:, None] * 0.5
    return PairContact(depth, normal, point)


def plane_sphere(pos_a, rot_a, size_a, pos_b, rot_b, size_b) -> PairContact:
    return _against_plane(pos_a, rot_a, pos_b[:, None, :], size_b[:, 0])


def plane_capsule(pos_a, rot_a, size_a, pos_b, rot_b, size_b) -> PairContact:
    start, span = _segment(pos_b, rot_b, size_b[:, 1])
    ends = np.stack([start, start + span], axis=1)
    return _against_plane(pos_a, rot_a, ends, size_b[:, 0])


def plane_box(pos_a, rot_a, size_a, pos_b, rot_b, size_b) -> PairContact:
    corners = pos_b[:, None, :] + np.einsum("kij,kmj->kmi", rot_b, _CUBE * size_b[:, None, :])
    return _against_plane(pos_a, rot_a, corners, np.zeros(pos_a.shape[0]))


# --- spheres and capsules: closest points of their cores ----------------------------------


def sphere_sphere(pos_a, rot_a, size_a, pos_b, rot_b, size_b) -> PairContact:
    return _between_spheres(pos_a, size_a[:, 0], pos_b, size_b[:, 0])


def _closest_on_segment(point, start, span) -> np.ndarray:
    """(k,) the parameter in [0, 1] of the point of each segment closest to ``point``."""
    length_sq = _dot(span, span)
    along = _dot(point - start, span) / np.where(length_sq > DEGENERATE**2, length_sq, 1.0)
    return np.clip(along, 0.0, 1.0)


def sphere_capsule(pos_a, rot_a, size_a, pos_b, rot_b, size_b) -> PairContact:
    start, span = _segment(pos_b, rot_b, size_b[:, 1])
    nearest = start + span * _closest_on_segment(pos_a, start, span)[:, None]
    return _between_spheres(pos_a, size_a[:, 0], nearest, size_b[:, 0])


def _closest_between_segments(start_a, span_a, start_b, span_b):
    """The closest points (k, 3) of two segments each (Ericson, *Real-Time Collision
    Detection* §5.1.9); for parallel segments, whose closest points form a set, the middle of
    the part of A facing B (every segment may be a point: ``span`` 0)."""
    offset = start_a - start_b
    aa, bb, ab = _dot(span_a, span_a), _dot(span_b, span_b), _dot(span_a, span_b)
    a_off, b_off = _dot(span_a, offset), _dot(span_b, offset)
    safe_aa, safe_bb = np.where(aa > 0.0, aa, 1.0), np.where(bb > 0.0, bb, 1.0)
    denom = aa * bb - ab * ab
    parallel = denom <= DEGENERATE * np.maximum(aa * bb, DEGENERATE)
    facing = 0.5 * (  # A's parameters nearest B's two ends, averaged
        np.clip(-a_off / safe_aa, 0.0, 1.0) + np.clip((ab - a_off) / safe_aa, 0.0, 1.0)
    )
    crossing = np.clip((ab * b_off - bb * a_off) / np.where(parallel, 1.0, denom), 0.0, 1.0)
    s = np.where(parallel, facing, crossing)
    t = np.clip((ab * s + b_off) / safe_bb, 0.0, 1.0)
    s = np.where(parallel, facing, np.clip((ab * t - a_off) / safe_aa, 0.0, 1.0))
    return start_a + span_a * s[:, None], start_b + span_b * t[:, None]


def capsule_capsule(pos_a, rot_a, size_a, pos_b, rot_b, size_b) -> PairContact:
    near_a, near_b = _closest_between_segments(
        *_segment(pos_a, rot_a, size_a[:, 1]), *_segment(pos_b, rot_b, size_b[:, 1])
    )
    return _between_spheres(near_a, size_a[:, 0], near_b, size_b[:, 0])


# --- a core against a box ----------------------------------------------------------------


def _segment_breakpoints(start, span, half) -> np.ndarray:
    """(k, m) parameters in [0, 1] where the squared distance of a segment's point to a box
    (box frame: ``start``, ``span`` (k, 3), ``half`` (k, 3)) can be least: the ends, where the
    point crosses a face plane (the pieces' ends), and each piece's own minimum."""
    with np.errstate(divide="ignore", invalid="ignore"):
        crossings = np.concatenate([(half - start) / span, (-half - start) / span], axis=1)
    crossings = np.clip(np.nan_to_num(crossings, nan=0.0, posinf=0.0, neginf=0.0), 0.0, 1.0)
    cuts = np.sort(
        np.concatenate(
            [np.zeros((start.shape[0], 1)), crossings, np.ones((start.shape[0], 1))], axis=1
        ),
        axis=1,
    )
    middle = 0.5 * (cuts[:, 1:] + cuts[:, :-1])
    inside = start[:, None, :] + middle[..., None] * span[:, None, :]
    bound = np.clip(inside, -half[:, None, :], half[:, None, :])
    outside = (inside != bound).astype(float)  # the axes clamped on each piece
    excess = (start[:, None, :] - bound) * outside
    directional = span[:, None, :] * outside
    weight = _dot(directional, directional)
    with np.errstate(divide="ignore", invalid="ignore"):
        stationary = -_dot(excess, directional) / weight
    stationary = np.clip(np.where(weight > 0, stationary, 0.0), cuts[:, :-1], cuts[:, 1:])
    return np.concatenate([cuts, stationary], axis=1)


def _core_box(start, span, radius, pos_b, rot_b, half) -> PairContact:
    """A sphere-swept segment (``start``, ``span`` (k, 3) world, a point when ``span`` is 0;
    ``radius (k,)``) as A and a box as B: its points closest to the box, tied ones averaged;
    a core inside the box leaves through the face of least overlap."""
    local_start = np.einsum("kji,kj->ki", rot_b, start - pos_b)
    local_span = np.einsum("kji,kj->ki", rot_b, span)
    t = _segment_breakpoints(local_start, local_span, half)
    points = local_start[:, None, :] + t[..., None] * local_span[:, None, :]
    on_box = np.clip(points, -half[:, None, :], half[:, None, :])
    distance = np.linalg.norm(points - on_box, axis=-1)
    nearest = distance.min(axis=1)
    tied = distance <= nearest[:, None] + TIE
    t_mid = 0.5 * (np.where(tied, t, np.inf).min(axis=1) + np.where(tied, t, -np.inf).max(axis=1))
    core = local_start + t_mid[:, None] * local_span
    surface = np.clip(core, -half, half)
    away, gap = _unit(surface - core, -UP)  # from the core to the box: A to B
    outside = gap > DEGENERATE
    # inside: SAT over the box's faces, the segment's extent along each
    ends = np.stack([local_start, local_start + local_span], axis=1)
    through_plus = half + radius[:, None] - ends.min(axis=1)  # leave through the +face
    through_minus = half + radius[:, None] + ends.max(axis=1)
    overlaps = np.concatenate([through_plus, through_minus], axis=1)
    face = np.argmin(overlaps, axis=1)
    rows = np.arange(face.size)
    axis, sign = face % 3, np.where(face < 3, 1.0, -1.0)
    inward = np.zeros_like(core)
    inward[rows, axis] = -sign  # the capsule leaves along +sign: the box lies along -sign
    depth = np.where(outside, radius - gap, overlaps[rows, face])
    local_normal = np.where(outside[:, None], away, inward)
    deepest = ends[
        rows,
        np.where(sign > 0, ends[rows, :, axis].argmin(axis=1), ends[rows, :, axis].argmax(axis=1)),
    ]
    anchor = np.where(outside[:, None], core, deepest)
    local_point = anchor + local_normal * (radius - 0.5 * depth)[:, None]
    normal = np.einsum("kij,kj->ki", rot_b, local_normal)
    point = pos_b + np.einsum("kij,kj->ki", rot_b, local_point)
    return PairContact(depth, normal, point)


def sphere_box(pos_a, rot_a, size_a, pos_b, rot_b, size_b) -> PairContact:
    return _core_box(pos_a, np.zeros_like(pos_a), size_a[:, 0], pos_b, rot_b, size_b)


def capsule_box(pos_a, rot_a, size_a, pos_b, rot_b, size_b) -> PairContact:
    start, span = _segment(pos_a, rot_a, size_a[:, 1])
    return _core_box(start, span, size_a[:, 0], pos_b, rot_b, size_b)


# --- box and box: separating axes ----------------------------------------------------------


def _box_axes(rot_a: np.ndarray, rot_b: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(k, 15, 3) unit candidate axes (A's faces, B's faces, ``a_i × b_j`` at ``6 + 3i + j``)
    and (k, 15) whether each is usable (edge axes of near-parallel edges are not)."""
    faces_a, faces_b = rot_a.swapaxes(1, 2), rot_b.swapaxes(1, 2)  # rows: the body axes
    edges = np.cross(faces_a[:, :, None, :], faces_b[:, None, :, :]).reshape(-1, 9, 3)
    axes = np.concatenate([faces_a, faces_b, edges], axis=1)
    length = np.linalg.norm(axes, axis=-1)
    usable = np.ones(length.shape, dtype=bool)
    usable[:, 6:] = length[:, 6:] > EDGE_AXIS_MIN_SIN
    return axes / np.where(usable, length, 1.0)[..., None], usable


def _reach(rot: np.ndarray, half: np.ndarray, axes: np.ndarray) -> np.ndarray:
    """(k, m) m, a box's half width along each unit axis ``axes (k, m, 3)``."""
    return np.einsum("kmj,kj->km", np.abs(np.einsum("kji,kmj->kmi", rot, axes)), half)


def _least_overlap_axis(overlap: np.ndarray, half_a, half_b) -> np.ndarray:
    """(k,) the axis of least overlap (``FACE_PREFERENCE``): A's best face, replaced by B's
    best face, then by the best edge, only where clearly smaller."""
    rows = np.arange(overlap.shape[0])
    absolute = FACE_PREFERENCE_ABSOLUTE * np.minimum(half_a.min(axis=1), half_b.min(axis=1))
    best = np.argmin(overlap[:, 0:3], axis=1)
    for first, last in ((3, 6), (6, 15)):
        candidate = first + np.argmin(overlap[:, first:last], axis=1)
        old, new = overlap[rows, best], overlap[rows, candidate]
        clearly = new < old - (1.0 - FACE_PREFERENCE) * np.abs(old) - absolute
        best = np.where(clearly, candidate, best)
    return best


def _clip(polygon: np.ndarray, count: np.ndarray, coord: int, sign: float, bound: np.ndarray):
    """One Sutherland-Hodgman cut: the part of each polygon (k, ``_CLIP_SLOTS``, 3), its first
    ``count (k,)`` vertices in order, where ``sign * x[coord] <= bound (k,)``."""
    k = polygon.shape[0]
    slots = np.arange(_CLIP_SLOTS)
    used = slots[None, :] < count[:, None]
    following = np.where(slots[None, :] + 1 < count[:, None], slots[None, :] + 1, 0)
    rows = np.arange(k)[:, None]
    beyond = sign * polygon[..., coord] - bound[:, None]
    beyond_next = beyond[rows, following]
    inside = beyond <= 0.0
    crosses = used & (inside != (beyond_next <= 0.0))
    with np.errstate(divide="ignore", invalid="ignore"):
        fraction = np.where(crosses, beyond / (beyond - beyond_next), 0.0)
    crossing = polygon + fraction[..., None] * (polygon[rows, following] - polygon)
    candidates = np.stack([polygon, crossing], axis=2).reshape(k, 2 * _CLIP_SLOTS, 3)
    present = np.stack([used & inside, crosses], axis=2).reshape(k, 2 * _CLIP_SLOTS)
    order = np.argsort(~present, axis=1, kind="stable")[:, :_CLIP_SLOTS]
    return candidates[rows, order], np.minimum(present.sum(axis=1), _CLIP_SLOTS)


def _face_contact(pos_r, rot_r, half_r, face, normal_r, pos_i, rot_i, half_i):
    """Reference box's face ``face (k,)`` (outward ``normal_r``, towards the incident box)
    against the incident box's face most opposed to it: the incident face clipped to the
    reference face's sides; its deepest vertices (tied ones averaged), placed midway between
    the vertex and the reference face. Returns depth (k,), point (k, 3), found (k,) bool."""
    rows = np.arange(face.size)
    first, second = (face + 1) % 3, (face + 2) % 3
    tangents = np.stack([rot_r[rows, :, first], rot_r[rows, :, second], normal_r], axis=1)
    face_centre = pos_r + half_r[rows, face][:, None] * normal_r
    alignment = np.einsum("kji,kj->ki", rot_i, normal_r)
    incident = np.argmax(np.abs(alignment), axis=1)
    outward = -np.sign(alignment[rows, incident])
    u, v = (incident + 1) % 3, (incident + 2) % 3
    centre = pos_i + (outward * half_i[rows, incident])[:, None] * rot_i[rows, :, incident]
    spans = np.stack(
        [
            half_i[rows, u][:, None] * rot_i[rows, :, u],
            half_i[rows, v][:, None] * rot_i[rows, :, v],
        ],
        axis=1,
    )
    corners = centre[:, None, :] + np.einsum("cs,ksj->kcj", _QUAD, spans)
    polygon = np.zeros((face.size, _CLIP_SLOTS, 3))
    polygon[:, :4] = np.einsum("kcj,kaj->kca", corners - face_centre[:, None, :], tangents)
    count = np.full(face.size, 4)
    for coord, half in ((0, half_r[rows, first]), (1, half_r[rows, second])):
        for sign in (1.0, -1.0):
            polygon, count = _clip(polygon, count, coord, sign, half)
    valid = np.arange(_CLIP_SLOTS)[None, :] < count[:, None]
    height = np.where(valid, polygon[..., 2], np.inf)
    lowest = height.min(axis=1)
    tied = (valid & (height <= lowest[:, None] + TIE)).astype(float)
    local = np.einsum("km,kma->ka", tied, polygon) / np.maximum(tied.sum(axis=1), 1.0)[:, None]
    local[:, 2] *= 0.5  # midway between the vertex and the reference face
    point = face_centre + np.einsum("ka,kaj->kj", local, tangents)
    return -lowest, point, count > 0


def _support_edge(pos, rot, half, edge, direction):
    """The box's edge along body axis ``edge (k,)`` furthest along ``direction (k, 3)``: its
    start (k, 3) and span (k, 3)."""
    rows = np.arange(edge.size)
    signs = np.sign(np.einsum("kji,kj->ki", rot, direction))
    signs = np.where(signs == 0.0, 1.0, signs)
    signs[rows, edge] = 0.0
    middle = pos + np.einsum("kij,kj->ki", rot, signs * half)
    axis = rot[rows, :, edge] * half[rows, edge][:, None]
    return middle - axis, 2.0 * axis


def box_box(pos_a, rot_a, size_a, pos_b, rot_b, size_b) -> PairContact:
    axes, usable = _box_axes(rot_a, rot_b)
    offset = pos_b - pos_a
    along = np.einsum("kmj,kj->km", axes, offset)
    overlap = _reach(rot_a, size_a, axes) + _reach(rot_b, size_b, axes) - np.abs(along)
    overlap = np.where(usable, overlap, np.inf)
    best = _least_overlap_axis(overlap, size_a, size_b)
    rows = np.arange(best.size)
    normal = axes[rows, best] * np.where(along[rows, best] < 0.0, -1.0, 1.0)[:, None]
    depth = overlap[rows, best]
    point = 0.5 * (pos_a + pos_b)
    face_a, face_b, edge = best < 3, (best >= 3) & (best < 6), best >= 6
    for chosen, ref, inc, sign in ((face_a, 0, 1, 1.0), (face_b, 1, 0, -1.0)):
        if not chosen.any():
            continue
        boxes = ((pos_a, rot_a, size_a), (pos_b, rot_b, size_b))
        (p_r, r_r, h_r), (p_i, r_i, h_i) = (tuple(x[chosen] for x in boxes[j]) for j in (ref, inc))
        found_depth, found_point, found = _face_contact(
            p_r, r_r, h_r, best[chosen] % 3, sign * normal[chosen], p_i, r_i, h_i
        )
        where = np.flatnonzero(chosen)[found]
        depth[where], point[where] = found_depth[found], found_point[found]
    if edge.any():
        axis_a, axis_b = np.divmod(best[edge] - 6, 3)
        near_a, near_b = _closest_between_segments(
            *_support_edge(pos_a[edge], rot_a[edge], size_a[edge], axis_a, normal[edge]),
            *_support_edge(pos_b[edge], rot_b[edge], size_b[edge], axis_b, -normal[edge]),
        )
        point[edge] = 0.5 * (near_a + near_b)
    return PairContact(depth, normal, point)


# --- cylinders: the lowest rim point, the closest point of the solid --------------------------


def plane_cylinder(pos_a, rot_a, size_a, pos_b, rot_b, size_b) -> PairContact:
    normal, axis = rot_a[:, :, 2], rot_b[:, :, 2]
    radius, half_length = size_b[:, 0], size_b[:, 1]
    across = normal - _dot(normal, axis)[:, None] * axis  # the normal within an end's plane
    up, tilt = _unit(across, np.zeros(3))  # tilt: sin θ, θ the angle of the ends to the plane
    level = 2.0 * radius * tilt <= TIE  # the end's whole face is deepest: its centre
    down = -up * np.where(level, 0.0, radius)[:, None]
    ends = (
        pos_b[:, None, :]
        + np.stack([1.0, -1.0])[None, :, None] * (axis * half_length[:, None])[:, None, :]
    )
    return _against_plane(pos_a, rot_a, ends + down[:, None, :], np.zeros(pos_a.shape[0]))


def sphere_cylinder(pos_a, rot_a, size_a, pos_b, rot_b, size_b) -> PairContact:
    radius, half_length = size_b[:, 0], size_b[:, 1]
    local = np.einsum("kji,kj->ki", rot_b, pos_a - pos_b)  # the sphere's centre, B's frame
    outward, reach = _unit(local * [1.0, 1.0, 0.0], np.array([1.0, 0.0, 0.0]))
    side = outward * np.minimum(reach, radius)[:, None]
    nearest = side + np.clip(local[:, 2], -half_length, half_length)[:, None] * UP
    outside = (reach > radius) | (np.abs(local[:, 2]) > half_length)
    # inside: leave through the side (along ``outward``) or the nearer end, the lesser overlap
    through_side, through_end = radius - reach, half_length - np.abs(local[:, 2])
    by_side = through_side <= through_end
    end_way = np.where(local[:, 2] < 0.0, -1.0, 1.0)[:, None] * UP
    leave = np.where(by_side[:, None], outward, end_way)
    overlap = np.where(by_side, through_side, through_end)
    surface = np.where(outside[:, None], nearest, local + leave * overlap[:, None])
    world = pos_b + np.einsum("kij,kj->ki", rot_b, surface)
    apart = _between_spheres(pos_a, size_a[:, 0], world, np.zeros_like(radius))
    exit_normal = -np.einsum("kij,kj->ki", rot_b, leave)  # the cylinder lies against the exit
    depth = np.where(outside, apart.depth, size_a[:, 0] + overlap)
    normal = np.where(outside[:, None], apart.normal, exit_normal)
    point = pos_a + normal * (size_a[:, 0] - 0.5 * depth)[:, None]
    return PairContact(depth, normal, point)


PAIRS = {
    (PLANE, SPHERE): plane_sphere,
    (PLANE, CAPSULE): plane_capsule,
    (PLANE, BOX): plane_box,
    (SPHERE, SPHERE): sphere_sphere,
    (SPHERE, CAPSULE): sphere_capsule,
    (SPHERE, BOX): sphere_box,
    (CAPSULE, CAPSULE): capsule_capsule,
    (CAPSULE, BOX): capsule_box,
    (BOX, BOX): box_box,
    (PLANE, CYLINDER): plane_cylinder,
    (SPHERE, CYLINDER): sphere_cylinder,
}
"""(shape A, shape B), A's code the lower -> the closed form of their deepest contact, each
``f(pos_a, rot_a, size_a, pos_b, rot_b, size_b) -> PairContact`` over ``k`` pairs: ``pos``
(k, 3) m, ``rot`` (k, 3, 3) shape to world, ``size`` (k, 3) m (``Shapes.size``)."""


def measured(kind_a: int, kind_b: int) -> bool:
    """Whether the pair of shape codes has a closed form (``PAIRS``, either order)."""
    return (min(kind_a, kind_b), max(kind_a, kind_b)) in PAIRS


def _closed_form(kind_a: int, kind_b: int):
    """``PAIRS``' closed form of a candidate pair; a pair without one (which ``physval check``
    refuses before any run) is an error naming the shapes, never a pair left out silently."""
    if not measured(kind_a, kind_b):
        raise ValueError(
            f"a {SHAPES[kind_a]} against a {SHAPES[kind_b]} has no closed form in the "
            "reference contact finder (physval check refuses such scenes)"
        )
    return PAIRS[(kind_a, kind_b)]


# --- every touching pair of many states ---------------------------------------------------


@dataclass(frozen=True)
class Shapes:
    """A scene's collision shapes (``N`` bodies, the ground a plane among them).

    Attributes:
        kind: (N,) int, ``SHAPES`` codes. size: (N, 3) m: sphere (radius, 0, 0), capsule
            and cylinder (radius, half length, 0), box (half extents), plane zeros.
        fixed: (N,) bool, never moves (two fixed shapes are never a pair).
        excluded: (e, 2) int, pairs of shapes that never touch each other, lower index first:
            the parent and child of a joint (as MuJoCo's parent filter and Bullet's adjacent
            links do), whose shapes meet at the joint by construction.
        offset: (N, 3) m, each shape's centre in its body's frame (from the body's position,
            its centre of mass); zeros by default.
        turn: (N, 3, 3) each shape's axes to its body's axes; identities by default.
    """

    kind: np.ndarray
    size: np.ndarray
    fixed: np.ndarray
    excluded: np.ndarray = field(default_factory=lambda: np.zeros((0, 2), dtype=np.int64))
    offset: np.ndarray | None = None
    turn: np.ndarray | None = None

    def __post_init__(self) -> None:
        count = self.kind.size
        if self.offset is None:
            object.__setattr__(self, "offset", np.zeros((count, 3)))
        if self.turn is None:
            object.__setattr__(self, "turn", np.broadcast_to(np.eye(3), (count, 3, 3)))

    @property
    def placed(self) -> np.ndarray:
        """(N,) bool, the shapes off their body's centre of mass or turned from its axes."""
        return self.offset.any(axis=1) | (self.turn != np.eye(3)).any(axis=(1, 2))

    def poses(self, pos: np.ndarray, rot: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """The shapes' poses (``pos (..., N, 3)``, ``rot (..., N, 3, 3)``) of their bodies'
        poses: each body's pose composed with its shape's placement (``offset``, ``turn``)."""
        if not self.placed.any():
            return pos, rot
        return pos + np.einsum("...ij,...j->...i", rot, self.offset), rot @ self.turn

    @property
    def shape_radius(self) -> np.ndarray:
        """(N,) m, each shape's bounding sphere about its own centre (inf for a plane)."""
        size = self.size
        return np.select(
            [
                self.kind == SPHERE,
                self.kind == CAPSULE,
                self.kind == BOX,
                self.kind == CYLINDER,
            ],
            [
                size[:, 0],
                size[:, 0] + size[:, 1],
                np.linalg.norm(size, axis=1),
                np.hypot(*size[:, :2].T),
            ],
            np.inf,
        )

    @property
    def bound_radius(self) -> np.ndarray:
        """(N,) m, each shape's bounding sphere about its body's centre of mass: its own
        (``shape_radius``) grown by the distance ``|offset|`` its centre sits from it."""
        return self.shape_radius + np.linalg.norm(self.offset, axis=1)

    @property
    def can_touch(self) -> bool:
        """Whether two shapes, not both fixed and not an excluded pair, exist (then some pair
        can touch)."""
        count = self.kind.size
        if count < 2 or bool(self.fixed.all()):
            return False
        pairs = count * (count - 1) // 2 - int(self.fixed.sum()) * (int(self.fixed.sum()) - 1) // 2
        return pairs > self.excluded.shape[0]

    def allowed(self, a: np.ndarray, b: np.ndarray) -> np.ndarray:
        """(c,) bool: the pairs ``a, b (c,)`` that are not ``excluded``."""
        if not self.excluded.size:
            return np.ones(a.shape, dtype=bool)
        count = self.kind.size
        keys = np.minimum(a, b) * count + np.maximum(a, b)
        return ~np.isin(keys, self.excluded[:, 0] * count + self.excluded[:, 1])


@dataclass(frozen=True)
class Found:
    """The deepest contact of every touching (state, pair): ``observation (c,)`` which state,
    ``body_a, body_b (c,)`` indices, ``point (c, 3)`` m, ``normal (c, 3)`` unit from A to B,
    ``depth (c,)`` m; sorted by (state, a, b)."""

    observation: np.ndarray
    body_a: np.ndarray
    body_b: np.ndarray
    point: np.ndarray
    normal: np.ndarray
    depth: np.ndarray


PAIR_STATES_PER_CALL = 1 << 20
"""(state, pair) candidates judged in one call at most: bounds the broad phase's temporaries
(a few hundred bytes each) while a small scene's whole batch of states is one call."""

ALL_PAIRS = 4096
"""Pairs of finite shapes up to which every pair is a broad-phase candidate (90 bodies);
larger scenes (piles of 1,000 to 10,000 spheres) look only in neighbouring grid cells."""

NEIGHBOUR_CELLS = np.array(
    [(x, y, z) for x in (-1, 0, 1) for y in (-1, 0, 1) for z in (-1, 0, 1) if (x, y, z) > (0, 0, 0)]
)
"""The 13 grid cells after a cell (half of its 26 neighbours): each pair of neighbouring
cells is visited once; pairs within one cell separately."""

CELL_INDEX_BITS = 62
"""A (state, cell) key is one int64: the state and three clipped cell coordinates packed in
62 bits (clipping keeps neighbours neighbours, so no pair is lost; far cells merge, which
only adds candidates that the exact check drops)."""


def find_contacts(shapes: Shapes, pos: np.ndarray, rot: np.ndarray, margin: float) -> Found:
    """Every pair touching (``depth >= -margin``) in each of ``s`` states of the bodies,
    ``pos (s, N, 3)``, ``rot (s, N, 3, 3)``: each shape at its pose (``Shapes.poses``), the
    broad phase's candidates (planes against every shape; finite shapes whose bounding spheres
    about their own centres come within ``margin``), then each pair's closed form
    (``PAIRS``)."""
    pos, rot = shapes.poses(pos, rot)
    finite = np.flatnonzero(shapes.kind != PLANE)
    load = finite.size * (finite.size - 1) // 2
    load = load if load <= ALL_PAIRS else finite.size * (NEIGHBOUR_CELLS.shape[0] + 1)
    per_call = max(1, PAIR_STATES_PER_CALL // max(load + shapes.kind.size, 1))
    parts = [
        _touching(shapes, pos[first : first + per_call], rot[first : first + per_call], margin)
        for first in range(0, pos.shape[0], per_call)
    ]
    parts = [
        (part[0] + first, *part[1:])
        for part, first in zip(parts, range(0, pos.shape[0], per_call), strict=True)
    ]
    return Found(*(np.concatenate(p) for p in zip(_empty(), *parts, strict=True)))


def _empty() -> tuple[np.ndarray, ...]:
    none = np.zeros(0, dtype=np.int64)
    return none, none, none, np.zeros((0, 3)), np.zeros((0, 3)), np.zeros(0)


def _touching(shapes: Shapes, pos, rot, margin: float) -> tuple[np.ndarray, ...]:
    """``Found``'s arrays for the states ``pos``, ``rot`` (numbered from 0)."""
    state, a, b = _candidates(shapes, pos, margin)
    found = [_empty()]
    codes = shapes.kind[a] * len(SHAPES) + shapes.kind[b]
    for code in np.unique(codes):
        rows = codes == code
        s, i, j = state[rows], a[rows], b[rows]
        contact = _closed_form(*divmod(int(code), len(SHAPES)))(
            pos[s, i], rot[s, i], shapes.size[i], pos[s, j], rot[s, j], shapes.size[j]
        )
        near = contact.depth >= -margin
        found.append(
            (
                s[near],
                i[near],
                j[near],
                contact.point[near],
                contact.normal[near],
                contact.depth[near],
            )
        )
    joined = [np.concatenate(p) for p in zip(*found, strict=True)]
    order = np.lexsort((joined[2], joined[1], joined[0]))
    return tuple(x[order] for x in joined)


def _candidates(shapes: Shapes, pos, margin: float) -> tuple[np.ndarray, ...]:
    """(state, a, b), each (c,) int: the pairs the broad phase keeps, not both fixed, A the
    lower shape code (the lower index between equal codes)."""
    plane, finite = np.flatnonzero(shapes.kind == PLANE), np.flatnonzero(shapes.kind != PLANE)
    states = np.arange(pos.shape[0])
    s, p, f = (g.ravel() for g in np.meshgrid(states, plane, finite, indexing="ij"))
    near = _finite_candidates(shapes, pos[:, finite], finite, margin)
    state, i, j = (np.concatenate(x) for x in zip((s, p, f), near, strict=True))
    keep = ~(shapes.fixed[i] & shapes.fixed[j]) & shapes.allowed(i, j)
    state, i, j = state[keep], i[keep], j[keep]
    swap = (shapes.kind[j] < shapes.kind[i]) | ((shapes.kind[j] == shapes.kind[i]) & (j < i))
    return state, np.where(swap, j, i), np.where(swap, i, j)


def _finite_candidates(shapes: Shapes, centres, index, margin: float) -> tuple[np.ndarray, ...]:
    """(state, i, j) of the finite shapes ``index (m,)`` at ``centres (s, m, 3)`` whose
    bounding spheres come within ``margin``: every pair of a small scene, the pairs of
    neighbouring grid cells (cells as wide as the largest bounding diameter) of a large one."""
    radius = shapes.shape_radius[index]
    if index.size * (index.size - 1) // 2 <= ALL_PAIRS:
        first, second = np.triu_indices(index.size, k=1)
        state = np.repeat(np.arange(centres.shape[0]), first.size)
        first, second = np.tile(first, centres.shape[0]), np.tile(second, centres.shape[0])
    else:
        state, first, second = _grid_pairs(centres, 2.0 * float(radius.max()) + margin)
    gap = np.linalg.norm(centres[state, second] - centres[state, first], axis=-1)
    near = gap <= radius[first] + radius[second] + margin
    return state[near], index[first[near]], index[second[near]]


def _grid_pairs(centres: np.ndarray, width: float) -> tuple[np.ndarray, ...]:
    """(state, i, j) of every two points of one state in the same or neighbouring cells of a
    grid of cube cells ``width`` wide (``centres (s, m, 3)``), each pair once."""
    states, count = centres.shape[:2]
    base = int((2.0**CELL_INDEX_BITS / max(states, 1)) ** (1.0 / 3.0))  # digits of a key
    limit = (base - 3) // 2  # cells -limit..limit, then 1..base - 2 with room for ±1
    cell = np.clip(np.floor(centres / width), -limit, limit).astype(np.int64) + limit + 1
    state = np.repeat(np.arange(states), count)
    body = np.tile(np.arange(count), states)

    def key(cells: np.ndarray) -> np.ndarray:
        return ((state * base + cells[:, 0]) * base + cells[:, 1]) * base + cells[:, 2]

    own = key(cell.reshape(-1, 3))
    order = np.argsort(own, kind="stable")
    sorted_keys = own[order]
    rank = np.empty_like(order)
    rank[order] = np.arange(order.size)
    pairs = []
    for offset in [None, *NEIGHBOUR_CELLS]:
        if offset is None:  # the same cell: the members after this one
            start = rank + 1
            stop = np.searchsorted(sorted_keys, own, side="right")
        else:
            wanted = key(cell.reshape(-1, 3) + offset)
            start = np.searchsorted(sorted_keys, wanted, side="left")
            stop = np.searchsorted(sorted_keys, wanted, side="right")
        width_of = np.maximum(stop - start, 0)
        owner = np.repeat(np.arange(own.size), width_of)
        step = np.arange(owner.size) - np.repeat(np.cumsum(width_of) - width_of, width_of)
        other = order[np.repeat(start, width_of) + step]
        pairs.append((state[owner], body[owner], body[other]))
    return tuple(np.concatenate(p) for p in zip(*pairs, strict=True))
