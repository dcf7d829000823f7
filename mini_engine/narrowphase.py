"""Vectorized narrow phase: contact points between pairs of shapes, batched over pairs.

One function per shape pair, ``collide_<a>_<b>``, all with the signature::

    collide_a_b(pos_a, rot_a, size_a, pos_b, rot_b, size_b, margin) -> PairContacts

for a batch of ``k`` candidate pairs of the same shape types:

- ``pos_a, pos_b (k, 3)`` m, world frame, body positions (centre of mass = shape centre);
- ``rot_a, rot_b (k, 3, 3)`` body-to-world rotation matrices;
- ``size_a, size_b (k, 3)`` m, the ``body_size`` rows of ``mini_engine.shapes``;
- ``margin`` m, >= 0: contacts are reported while ``depth >= -margin``.

Conventions (those of ``mini_engine.contacts``): body A is the shape with the lower
``ShapeType`` value; the normal is a unit vector **from A to B**; ``depth > 0`` means
overlap; the point is midway between the two surfaces along the normal. The returned
``PairContacts.pair`` indexes the batch (0..k-1); a pair may give several contacts
(up to 4), listed in pair order.

Every function is written over the whole batch: per-pair candidate contacts live in
fixed-size arrays ``(k, m, ...)`` with a validity mask ``(k, m)`` and are flattened at
the end by ``_emit``. Python loops only run over fixed small sets (the 15 box axes, the
4 clipping planes, polygon slots). Every normalisation is guarded: where a direction is
undefined (coincident sphere centres, a sphere centre on a capsule axis, crossing
capsule axes) a documented fallback direction is used, so no NaN is ever produced.

The table ``NARROW_PHASE`` maps ``(ShapeType_A, ShapeType_B)`` with ``A <= B`` to the
function; it is the interface used by the engine.
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np

from mini_engine.contacts import PairContacts
from mini_engine.rotation import einsum, last_axis_sum, norm
from mini_engine.shapes import ShapeType

# ---------------------------------------------------------------------------------------
# Tuning constants
# ---------------------------------------------------------------------------------------

DISTANCE_EPS = 1e-12
"""m. Below this distance two points are treated as coincident and the direction between
them as undefined (a fallback normal is used). Four orders of magnitude above the rounding
of metre-scale float64 coordinates (eps 2.2e-16 m), far below any physical gap."""

DIRECTION_EPS = 1e-12
"""Unitless. A direction component smaller than this is treated as zero when dividing by
it (slab clipping, segment breakpoints); same reasoning as ``DISTANCE_EPS`` for unit
vectors."""

PARALLEL_SIN = 1e-3
"""Unitless, sine of the angle (0.057°) between two capsule axes below which the capsules
count as lying along each other: where their projections overlap, both ends of the overlap
become contact candidates, so a capsule resting on a capsule gets two contacts (a resting
capsule is parallel to its support to rounding, far inside this). The closest-point pair
stays a candidate, so the deepest point is never lost. At this angle the line–line
formula (denominator ``sin²``, Ericson, *Real-Time Collision Detection* §5.1.9) locates
the closest points only to ~eps/sin² = 2e-10 m: the same number bounds box edge axes."""

FACE_NORMAL_SIN = 1e-3
"""Unitless, sine of the angle between a capsule–box normal and a box face normal below
which the contact is treated as a face contact (and may get two points). Same value and
reason as ``PARALLEL_SIN``: a capsule resting on a face is parallel to it to rounding."""

SAME_POINT_EPS = 1e-9
"""m. Two candidate contacts of one pair closer than this along a segment are one contact
(e.g. the two 'ends' of a zero-length overlap, the two cap centres of a zero-length
capsule). 1 nm: far below any contact-patch size, far above rounding."""

FACE_AXIS_RELATIVE_TOL = 0.95
"""Box–box axis choice (Box2D-Lite ``Collide.cpp``, ``relativeTol = 0.95``): a later axis
(face of B over face of A, edge over face) is chosen only if its separation exceeds
``sep_old + (1 - 0.95) |sep_old| + absolute tolerance``. For overlap (sep < 0) this is
exactly Box2D-Lite's ``sep_new > 0.95 sep_old + ...``; ODE's ``dBoxBox`` uses the same
5 % (``fudge_factor = 1.05``) against edge axes. Resting stacks then keep face contacts."""

FACE_AXIS_ABSOLUTE_TOL = 0.01
"""Box–box axis choice, absolute part of the bias as a fraction of the smallest half
extent of the two boxes (Box2D-Lite ``absoluteTol = 0.01``, times the half extent)."""

EDGE_AXIS_MIN_SIN = PARALLEL_SIN
"""Unitless. A box–box edge axis ``a_i × b_j`` is skipped when ``|a_i × b_j|`` (the sine of
the angle between the edges) is below this: the normalised axis then carries rounding
amplified by 1/sin and the edge–edge closest points by 1/sin² (see ``PARALLEL_SIN``).
Parallel edge pairs need no axis of their own: the face axes cover them (SAT), and near
parallel ones are separated along a face axis to within ~sin × edge length."""

TIE_TOL = 1e-9
"""m (or unitless for cosines). Scores within this of the best (depths, distances,
separations, face alignments) are ties, resolved by the first candidate in body-frame
order rather than by rounding noise, so that one configuration gives the same contacts in
any world pose and from step to step. 1 nm is 1e7 times the rounding of metre-scale
float64 values and far below any physical feature."""

MAX_MANIFOLD_POINTS = 4
"""Contacts kept per box face contact (plane–box, box–box), as in Box2D v3, Bullet's
persistent manifold and MuJoCo's box–box: 4 points span any face patch stably."""

CLIP_CAPACITY = 8
"""Vertex slots of a clipped polygon: a quadrilateral clipped by 4 half-planes has at most
4 + 4 = 8 vertices (each half-plane adds at most one vertex to a convex polygon)."""

_QUAD_SIGNS = np.array([[1.0, 1.0], [-1.0, 1.0], [-1.0, -1.0], [1.0, -1.0]])
"""(4, 2) face-corner signs along the two face tangents, in order around the face."""

_CLIP_SLOTS = np.arange(CLIP_CAPACITY)
"""(CLIP_CAPACITY,) the vertex slots of a clipped polygon."""

_USED_SLOTS = _CLIP_SLOTS[None, :] < np.arange(CLIP_CAPACITY + 1)[:, None]
"""(CLIP_CAPACITY + 1, CLIP_CAPACITY) bool: row ``count``, which slots a polygon of
``count`` vertices uses."""

_FOLLOWING_SLOT = np.where(
    _CLIP_SLOTS[None, :] + 1 < np.arange(CLIP_CAPACITY + 1)[:, None], _CLIP_SLOTS + 1, 0
)
"""(CLIP_CAPACITY + 1, CLIP_CAPACITY) int: row ``count``, the slot of each vertex's successor
around a polygon of ``count`` vertices (the last one's is slot 0)."""

_CUBE_SIGNS = np.array([[x, y, z] for x in (-1.0, 1.0) for y in (-1.0, 1.0) for z in (-1.0, 1.0)])
"""(8, 3) box-vertex signs along the body axes."""

_Z_AXIS = np.array([0.0, 0.0, 1.0])
"""+z: the fallback normal of coincident sphere centres (world frame); also the formal
fallback of a never-zero direction in ``_capsule_box`` (box frame)."""


# ---------------------------------------------------------------------------------------
# Small batched helpers
# ---------------------------------------------------------------------------------------


def _dot(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Dot products over the last axis: ``(..., 3) · (..., 3) -> (...)``."""
    return last_axis_sum(a * b)


def _cross(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Cross products over the last axis, ``(..., 3) × (..., 3) -> (..., 3)``, right-handed."""
    return np.stack(
        [
            a[..., 1] * b[..., 2] - a[..., 2] * b[..., 1],
            a[..., 2] * b[..., 0] - a[..., 0] * b[..., 2],
            a[..., 0] * b[..., 1] - a[..., 1] * b[..., 0],
        ],
        axis=-1,
    )


def _sign(x: np.ndarray) -> np.ndarray:
    """+1 where ``x >= -TIE_TOL``, -1 elsewhere (never 0, unlike ``np.sign``).

    Values within ``TIE_TOL`` of 0 count as positive, so that a symmetric configuration
    (a sphere centre exactly at a box centre, coincident box centres) picks the same side
    whatever the rounding noise of its world pose.
    """
    return np.where(x >= -TIE_TOL, 1.0, -1.0)


def _normalize(v: np.ndarray, fallback: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Unit vectors ``(..., 3)`` along ``v (..., 3)`` and the lengths ``(...)``.

    Where ``|v| <= DISTANCE_EPS`` the (unit) ``fallback`` (broadcast to ``v``) is returned.
    """
    length = np.sqrt(_dot(v, v))  # np.linalg.norm's operations, without its dispatch
    defined = length > DISTANCE_EPS
    if np.count_nonzero(defined) == defined.size:  # every direction defined: no fallback
        return v / length[..., None], length
    unit = v / np.where(defined, length, 1.0)[..., None]
    return np.where(defined[..., None], unit, fallback), length


def _select(mask: np.ndarray, if_true: np.ndarray, if_false: np.ndarray) -> np.ndarray:
    """``np.where`` with a row mask ``(n,)`` broadcast over the trailing axes of ``(n, ...)``."""
    return np.where(mask.reshape(-1, *[1] * (if_true.ndim - 1)), if_true, if_false)


def _first_within(score: np.ndarray) -> np.ndarray:
    """Index (...) of the first entry of ``score (..., m)`` within ``TIE_TOL`` of its maximum.

    An ``argmax`` that ignores rounding-level differences (see ``TIE_TOL``); entries equal
    to ``-inf`` are never preferred to finite ones.
    """
    best = score.max(axis=-1, keepdims=True)
    return (score >= best - TIE_TOL).argmax(axis=-1)


def _orient(direction: np.ndarray, towards: np.ndarray) -> np.ndarray:
    """``direction (..., 3)`` flipped where ``direction · towards < -TIE_TOL`` (see ``_sign``)."""
    return direction * _sign(_dot(direction, towards))[..., None]


def _column(rot: np.ndarray, index: np.ndarray) -> np.ndarray:
    """Body axes ``rot[n, :, index[n]]`` (n, 3), world frame, from ``rot (n, 3, 3)``."""
    return rot[np.arange(rot.shape[0]), :, index]


def _to_world(pos: np.ndarray, rot: np.ndarray, local: np.ndarray) -> np.ndarray:
    """World points ``pos + R local``: ``pos (n, 3)``, ``rot (n, 3, 3)``, ``local (n, m, 3)``."""
    return pos[:, None, :] + einsum("nij,nmj->nmi", rot, local)


def _to_local(rot: np.ndarray, vector: np.ndarray) -> np.ndarray:
    """Body-frame vectors ``Rᵀ v`` (n, 3) of world ``vector (n, 3)``, ``rot (n, 3, 3)``."""
    return einsum("nji,nj->ni", rot, vector)


def _emit(
    valid: np.ndarray, point: np.ndarray, normal: np.ndarray, depth: np.ndarray
) -> PairContacts:
    """Flatten per-pair candidate contacts into ``PairContacts``, in pair then slot order.

    Args:
        valid: (k, m) bool, which candidate slots are contacts.
        point: (k, m, 3) m, world frame.
        normal: (k, m, 3) unit, world frame, A to B (or (k, 3), one per pair).
        depth: (k, m) m.
    """
    pair, slot = np.nonzero(valid)
    return PairContacts(
        pair=pair.astype(np.int64, copy=False),
        point=point[pair, slot],
        normal=normal[pair] if normal.ndim == 2 else normal[pair, slot],  # one per pair
        depth=depth[pair, slot],
    )


def _emit_one_per_pair(
    valid: np.ndarray, point: np.ndarray, normal: np.ndarray, depth: np.ndarray
) -> PairContacts:
    """``_emit`` for functions with at most one contact per pair: ``valid (k,)``,
    ``point (k, 3)``, ``normal (k, 3)``, ``depth (k,)``. When every pair touches (a resting
    scene) the arrays are passed on (made contiguous, as a gather would), without gathers."""
    if np.count_nonzero(valid) == valid.size:  # valid.all(), without its Python wrapper
        return PairContacts(
            np.arange(valid.size),
            np.ascontiguousarray(point),
            np.ascontiguousarray(normal),
            np.ascontiguousarray(depth),
        )
    pair = valid.nonzero()[0]
    return PairContacts(pair, point.take(pair, axis=0), normal.take(pair, axis=0), depth.take(pair))


def _sphere_pair(
    centre_a: np.ndarray,
    radius_a: np.ndarray,
    centre_b: np.ndarray,
    radius_b: np.ndarray,
    fallback: np.ndarray,
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Contact between spheres: ``(point, normal, depth)``, shapes ``(..., 3), (..., 3), (...)``.

    ``centre_* (..., 3)`` m world, ``radius_* (...)`` m. The normal is the unit vector from
    centre A to centre B, ``fallback (..., 3)`` (unit) where the centres coincide; the depth
    is ``r_a + r_b - |c_b - c_a|``; the point is midway between the two surface points
    ``c_a + r_a n`` and ``c_b - r_b n``.
    """
    normal, distance = _normalize(centre_b - centre_a, fallback)
    depth = radius_a + radius_b - distance
    point = 0.5 * (
        centre_a + radius_a[..., None] * normal + centre_b - radius_b[..., None] * normal
    )
    return point, normal, depth


# ---------------------------------------------------------------------------------------
# Segment geometry
# ---------------------------------------------------------------------------------------


def _closest_segment_params(
    centre_a: np.ndarray,
    axis_a: np.ndarray,
    half_a: np.ndarray,
    centre_b: np.ndarray,
    axis_b: np.ndarray,
    half_b: np.ndarray,
) -> tuple[np.ndarray, np.ndarray]:
    """Closest points of segments ``c_a + s u_a, |s| <= h_a`` and ``c_b + t u_b, |t| <= h_b``.

    Ericson, *Real-Time Collision Detection* §5.1.9, with unit directions and centred
    parameters: ``s`` of the closest points of the two lines (denominator ``sin²`` of the
    angle between the axes, taken as ``|u_a × u_b|²`` for accuracy at small angles), clamped;
    then ``t`` for that ``s``, clamped; then ``s`` again for that ``t``. Where the axes are
    parallel to rounding (``sin < DIRECTION_EPS``) ``s`` starts at the middle of the overlap
    of B's projection onto A (or at A's nearer end when they do not overlap), a closest pair
    too. Near-parallel axes locate ``s`` poorly (error ~ eps / sin²) but the distance well
    (error ≲ min(eps / sin, L sin) ≤ sqrt(eps L), ~1e-8 m for L = 1 m).

    Args:
        centre_*: (n, 3) m, world frame; axis_*: (n, 3) unit; half_*: (n,) m, half lengths.

    Returns:
        s, t: (n,) m, parameters of the closest points along A and B.
    """
    offset = centre_a - centre_b
    cos_ab = _dot(axis_a, axis_b)
    c = _dot(axis_a, offset)
    f = _dot(axis_b, offset)
    normal = _cross(axis_a, axis_b)
    sin2 = _dot(normal, normal)
    parallel = sin2 < DIRECTION_EPS**2

    s_lines = (cos_ab * f - c) / np.where(parallel, 1.0, sin2)
    low, high = _projected_overlap(c, cos_ab, half_a, half_b)
    s = np.clip(np.where(parallel, 0.5 * (low + high), s_lines), -half_a, half_a)
    t = np.clip(f + s * cos_ab, -half_b, half_b)
    s = np.clip(t * cos_ab - c, -half_a, half_a)
    return s, t


def _projected_overlap(
    c: np.ndarray, cos_ab: np.ndarray, half_a: np.ndarray, half_b: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """Interval ``[low, high]`` (n,), m, of A's parameter covered by B's projection onto A.

    B's end points project to ``s = -c ± h_b cos_ab`` (``c = u_a · (c_a - c_b)``); the
    interval is intersected with ``[-h_a, h_a]``, so ``low > high`` when they do not overlap.
    """
    reach = half_b * np.abs(cos_ab)
    return np.maximum(-c - reach, -half_a), np.minimum(-c + reach, half_a)


def _clip_segment_to_slabs(
    centre: np.ndarray, direction: np.ndarray, half: np.ndarray, extent: np.ndarray, use: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """Parameter interval ``[t0, t1]`` (n,) of a segment inside slabs of a box.

    The segment is ``centre + t direction``, ``|t| <= half``.

    Liang–Barsky clipping against the slabs ``|x_i| <= extent_i`` for the axes ``i`` where
    ``use (n, 3)`` is true. Box frame: ``centre (n, 3)`` m, ``direction (n, 3)`` unit,
    ``half (n,)`` m, ``extent (n, 3)`` m. The interval is empty where ``t0 > t1``.
    """
    t0, t1 = -half, half.copy()
    for i in range(3):
        moving = np.abs(direction[:, i]) > DIRECTION_EPS
        safe = np.where(moving, direction[:, i], 1.0)
        enter_a = (-extent[:, i] - centre[:, i]) / safe
        enter_b = (extent[:, i] - centre[:, i]) / safe
        inside = np.abs(centre[:, i]) <= extent[:, i]
        low = np.where(moving, np.minimum(enter_a, enter_b), np.where(inside, -np.inf, np.inf))
        high = np.where(moving, np.maximum(enter_a, enter_b), np.where(inside, np.inf, -np.inf))
        t0 = np.where(use[:, i], np.maximum(t0, low), t0)
        t1 = np.where(use[:, i], np.minimum(t1, high), t1)
    return t0, t1


def _box_excess_sq(point: np.ndarray, extent: np.ndarray) -> np.ndarray:
    """Squared distance (n,), m², from box-frame ``point (n, 3)`` to the box ``|x| <= extent``."""
    excess = point - np.clip(point, -extent, extent)
    return _dot(excess, excess)


def _closest_segment_to_box(
    centre: np.ndarray, direction: np.ndarray, half: np.ndarray, extent: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """Point of the segment ``centre + t direction, |t| <= half`` nearest the box, exactly.

    Box frame: ``centre (n, 3)`` m, ``direction (n, 3)`` unit, ``half (n,)`` m,
    ``extent (n, 3)`` m half extents. The squared distance to the box along the segment is
    convex and piecewise quadratic in ``t``, with breakpoints where a coordinate crosses
    ``±extent_i``. Between consecutive breakpoints the set of clamped coordinates is fixed,
    so the piece's minimiser is the vertex of its parabola clipped to the piece; the best
    piece gives the global minimiser (convexity). Ties within ``TIE_TOL`` (a segment
    parallel to a face or an edge, or inside the box) resolve to the smallest ``t``.

    Returns:
        t: (n,) m, parameter of the nearest segment point; distance: (n,) m, to the box.
    """
    moving = np.abs(direction) > DIRECTION_EPS
    safe = np.where(moving, direction, 1.0)
    h = half[:, None]
    crossings = [np.where(moving, (bound - centre) / safe, -h) for bound in (-extent, extent)]
    breaks = np.clip(np.concatenate([-h, h, *crossings], axis=1), -h, h)
    breaks.sort(axis=1)

    best_t = -half
    best_distance = np.full(half.shape, np.inf)
    for piece in range(breaks.shape[1] - 1):
        low, high = breaks[:, piece], breaks[:, piece + 1]
        middle = centre + (0.5 * (low + high))[:, None] * direction
        clamped = np.abs(middle) > extent
        target = np.clip(middle, -extent, extent)
        curvature = np.sum(np.where(clamped, direction**2, 0.0), axis=1)
        slope = np.sum(np.where(clamped, direction * (centre - target), 0.0), axis=1)
        curved = curvature > DIRECTION_EPS**2
        vertex = -slope / np.where(curved, curvature, 1.0)
        t = np.where(curved, np.clip(vertex, low, high), low)
        distance = np.sqrt(_box_excess_sq(centre + t[:, None] * direction, extent))
        better = distance < best_distance - TIE_TOL
        best_t = np.where(better, t, best_t)
        best_distance = np.where(better, distance, best_distance)
    return best_t, best_distance


# ---------------------------------------------------------------------------------------
# Plane pairs
# ---------------------------------------------------------------------------------------


def collide_plane_sphere(
    pos_a: np.ndarray,
    rot_a: np.ndarray,
    size_a: np.ndarray,
    pos_b: np.ndarray,
    rot_b: np.ndarray,
    size_b: np.ndarray,
    margin: float,
) -> PairContacts:
    """Plane A (normal = body +z through ``pos_a``) against sphere B of radius ``size_b[:, 0]``.

    The plane is a half-space: a sphere below it is penetrating. One contact per pair:
    normal = plane normal (A to B), depth ``r - h`` with ``h`` the centre's signed height
    above the plane, point midway between the sphere's lowest point and the plane.

    Batch arrays (``pos (k, 3)`` m world, ``rot (k, 3, 3)``, ``size (k, 3)`` m) as in the
    module docstring; returns ``PairContacts`` (c ≤ k).
    """
    if len(pos_a) == 0:
        return PairContacts.empty()
    normal = rot_a[:, :, 2]
    radius = size_b[:, 0]
    height = _dot(pos_b - pos_a, normal)
    depth = radius - height
    point = pos_b - (0.5 * (radius + height))[:, None] * normal
    return _emit_one_per_pair(depth >= -margin, point, normal, depth)


def collide_plane_capsule(
    pos_a: np.ndarray,
    rot_a: np.ndarray,
    size_a: np.ndarray,
    pos_b: np.ndarray,
    rot_b: np.ndarray,
    size_b: np.ndarray,
    margin: float,
) -> PairContacts:
    """Plane A against capsule B: the two cap centres as spheres of the capsule radius.

    Up to 2 contacts per pair (one per cap within the margin; one when ``half_length`` is
    0). The deepest point of a capsule on a half-space is always on a cap, so this is exact;
    a capsule lying flat gets both caps, which makes it rest stably. Shapes as in the module
    docstring.
    """
    if len(pos_a) == 0:
        return PairContacts.empty()
    normal = rot_a[:, :, 2]
    radius, half = size_b[:, 0], size_b[:, 1]
    ends = (
        pos_b[:, None, :]
        + np.array([1.0, -1.0])[None, :, None] * (half[:, None] * rot_b[:, :, 2])[:, None, :]
    )
    height = _dot(ends - pos_a[:, None, :], normal[:, None, :])
    depth = radius[:, None] - height
    point = ends - (0.5 * (radius[:, None] + height))[..., None] * normal[:, None, :]
    valid = depth >= -margin
    valid[:, 1] &= half > SAME_POINT_EPS
    return _emit(valid, point, normal, depth)


def collide_plane_box(
    pos_a: np.ndarray,
    rot_a: np.ndarray,
    size_a: np.ndarray,
    pos_b: np.ndarray,
    rot_b: np.ndarray,
    size_b: np.ndarray,
    margin: float,
) -> PairContacts:
    """Plane A against box B: the box vertices within the margin, at most the 4 deepest.

    Each vertex ``v`` with height ``h`` above the plane gives depth ``-h`` and point
    ``v - (h/2) n``. A box resting on a face gives exactly its 4 bottom vertices; a box on
    an edge gives 2, on a vertex 1.
    Batch arrays (``pos (k, 3)`` m world, ``rot (k, 3, 3)``, ``size (k, 3)`` m) as in the
    module docstring.
    """
    if len(pos_a) == 0:
        return PairContacts.empty()
    normal = rot_a[:, :, 2]
    vertices = _to_world(pos_b, rot_b, _CUBE_SIGNS[None] * size_b[:, None, :])
    height = _dot(vertices - pos_a[:, None, :], normal[:, None, :])
    depth = -height
    valid = depth >= -margin
    deepest_first = np.argsort(np.where(valid, -depth, np.inf), axis=1, kind="stable")
    keep = deepest_first[:, :MAX_MANIFOLD_POINTS]
    pairs = np.arange(keep.shape[0])[:, None]
    valid, depth, vertices = valid[pairs, keep], depth[pairs, keep], vertices[pairs, keep]
    point = vertices + (0.5 * depth)[..., None] * normal[:, None, :]
    return _emit(valid, point, normal, depth)


# ---------------------------------------------------------------------------------------
# Sphere and capsule pairs
# ---------------------------------------------------------------------------------------


def collide_sphere_sphere(
    pos_a: np.ndarray,
    rot_a: np.ndarray,
    size_a: np.ndarray,
    pos_b: np.ndarray,
    rot_b: np.ndarray,
    size_b: np.ndarray,
    margin: float,
) -> PairContacts:
    """Sphere A against sphere B: one contact along the line of centres.

    Normal from centre A to centre B; **world +z when the centres coincide** (closer than
    ``DISTANCE_EPS``). Depth ``r_a + r_b - |c_b - c_a|``.
    Batch arrays (``pos (k, 3)`` m world, ``rot (k, 3, 3)``, ``size (k, 3)`` m) as in the
    module docstring.
    """
    if len(pos_a) == 0:
        return PairContacts.empty()
    point, normal, depth = _sphere_pair(pos_a, size_a[:, 0], pos_b, size_b[:, 0], _Z_AXIS)
    return _emit_one_per_pair(depth >= -margin, point, normal, depth)


def collide_sphere_capsule(
    pos_a: np.ndarray,
    rot_a: np.ndarray,
    size_a: np.ndarray,
    pos_b: np.ndarray,
    rot_b: np.ndarray,
    size_b: np.ndarray,
    margin: float,
) -> PairContacts:
    """Sphere A against capsule B: sphere against the nearest point of B's axis segment.

    One contact per pair. Where the sphere centre lies on the capsule axis the normal is
    the capsule's body +x axis (a direction of least penetration, perpendicular to the
    axis).
    Batch arrays (``pos (k, 3)`` m world, ``rot (k, 3, 3)``, ``size (k, 3)`` m) as in the
    module docstring.
    """
    if len(pos_a) == 0:
        return PairContacts.empty()
    axis, half = rot_b[:, :, 2], size_b[:, 1]
    t = np.clip(_dot(pos_a - pos_b, axis), -half, half)
    nearest = pos_b + t[:, None] * axis
    point, normal, depth = _sphere_pair(pos_a, size_a[:, 0], nearest, size_b[:, 0], rot_b[:, :, 0])
    return _emit_one_per_pair(depth >= -margin, point, normal, depth)


def collide_capsule_capsule(
    pos_a: np.ndarray,
    rot_a: np.ndarray,
    size_a: np.ndarray,
    pos_b: np.ndarray,
    rot_b: np.ndarray,
    size_b: np.ndarray,
    margin: float,
) -> PairContacts:
    """Capsule A against capsule B: spheres at the closest points of the two axis segments.

    One contact per pair, at the closest points (``_closest_segment_params``), except where
    the axes are parallel within ``PARALLEL_SIN`` and their projections overlap: there the
    candidates are both ends of the overlap (each with its nearest point on B) and the
    closest pair, and the two kept are the deepest and the one farthest from it along A.
    Exactly parallel capsules thus get the two ends of the overlap (a capsule lying on a
    capsule rests stably) and slightly crossing ones keep their true deepest point.
    Fallback normal where the two points coincide: ``u_a × u_b`` oriented towards B (the
    direction separating crossing axes), or A's body +x where the axes are parallel to
    rounding (``|u_a × u_b| <= DISTANCE_EPS``).
    Batch arrays (``pos (k, 3)`` m world, ``rot (k, 3, 3)``, ``size (k, 3)`` m) as in the
    module docstring.
    """
    if len(pos_a) == 0:
        return PairContacts.empty()
    axis_a, axis_b = rot_a[:, :, 2], rot_b[:, :, 2]
    radius_a, half_a = size_a[:, 0], size_a[:, 1]
    radius_b, half_b = size_b[:, 0], size_b[:, 1]
    s, t = _closest_segment_params(pos_a, axis_a, half_a, pos_b, axis_b, half_b)

    crossing, sin_ab = _normalize(_cross(axis_a, axis_b), rot_a[:, :, 0])
    parallel = sin_ab < PARALLEL_SIN
    fallback = _orient(crossing, pos_b - pos_a)

    cos_ab = _dot(axis_a, axis_b)
    f = _dot(axis_b, pos_a - pos_b)
    low, high = _projected_overlap(_dot(axis_a, pos_a - pos_b), cos_ab, half_a, half_b)
    two_ends = parallel & (high - low > SAME_POINT_EPS)
    s_candidates = np.stack([low, high, s], axis=1)
    s_candidates[:, :2] = np.clip(s_candidates[:, :2], -half_a[:, None], half_a[:, None])
    t_candidates = np.clip(
        f[:, None] + s_candidates * cos_ab[:, None], -half_b[:, None], half_b[:, None]
    )
    t_candidates[:, 2] = t
    point, normal, depth = _sphere_pair(
        pos_a[:, None] + s_candidates[..., None] * axis_a[:, None],
        radius_a[:, None],
        pos_b[:, None] + t_candidates[..., None] * axis_b[:, None],
        radius_b[:, None],
        fallback[:, None],
    )

    candidate = np.stack([two_ends, two_ends, np.ones(len(pos_a), dtype=bool)], axis=1)
    keep, valid = _deepest_and_farthest(depth, s_candidates, candidate & (depth >= -margin))
    return _emit(
        valid,
        np.take_along_axis(point, keep[..., None], axis=1),
        np.take_along_axis(normal, keep[..., None], axis=1),
        np.take_along_axis(depth, keep, axis=1),
    )


def _deepest_and_farthest(
    depth: np.ndarray, param: np.ndarray, candidate: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """Two contacts out of a few candidates along a segment: the deepest, and the candidate
    farthest from it along the segment (more than ``SAME_POINT_EPS`` away).

    Args:
        depth: (n, m) m; param: (n, m) m, position of each candidate along the segment;
        candidate: (n, m) bool, which candidates are usable (e.g. within the margin).

    Returns:
        keep: (n, 2) int, candidate slots; valid: (n, 2) bool, whether each is a contact.
    """
    rows = np.arange(depth.shape[0])
    deepest = _first_within(np.where(candidate, depth, -np.inf))
    spread = np.abs(param - param[rows, deepest][:, None])
    apart = candidate & (spread > SAME_POINT_EPS)
    farthest = _first_within(np.where(apart, spread, -np.inf))
    keep = np.stack([deepest, farthest], axis=1)
    valid = np.stack([candidate[rows, deepest], apart[rows, farthest]], axis=1)
    return keep, valid


def _capsule_box(
    centre: np.ndarray,
    axis: np.ndarray,
    half: np.ndarray,
    radius: np.ndarray,
    pos_b: np.ndarray,
    rot_b: np.ndarray,
    size_b: np.ndarray,
    margin: float,
) -> PairContacts:
    """Capsule (segment ``centre + t axis, |t| <= half``, ``radius``) A against box B.

    ``centre (k, 3)`` m world, ``axis (k, 3)`` unit world, ``half, radius (k,)`` m; box as in
    the module docstring. The algorithm, in the box frame:

    1. the exact nearest segment point to the box (``_closest_segment_to_box``);
    2. separated segment: the normal is the direction from that point to the box;
       segment touching or inside the box: the middle of the part of the segment inside
       the box is pushed out through its face of least penetration (as for a sphere);
    3. the nearest-point contact: depth ``radius - distance`` (separated) or
       ``radius + penetration`` (inside), normal from step 2;
    4. when that normal is a face normal (within ``FACE_NORMAL_SIN``), the segment is also
       clipped to the face's column (its two side slabs), and both ends of the clipped
       segment are candidates, normal = the face normal, depth ``radius - height above
       the face``;
    5. of the candidates within the margin, the deepest and the one farthest from it along
       the segment are kept (``_deepest_and_farthest``).

    A capsule lying on a face thus gets the two ends of its overlap with the face, a tilted
    or standing one its lowest point, one over an edge or vertex the nearest point; the
    deepest point is always kept. Up to 2 contacts per pair; with ``half = 0`` this is the
    sphere–box contact.
    """
    k = centre.shape[0]
    rows = np.arange(k)
    extent = size_b
    c = _to_local(rot_b, centre - pos_b)
    d = _to_local(rot_b, axis)
    t_near, distance = _closest_segment_to_box(c, d, half, extent)
    near = c + t_near[:, None] * d
    inside_box = distance <= DISTANCE_EPS

    # Outward box normal towards the capsule (box frame), separated and inside cases.
    outward_sep, _ = _normalize(near - np.clip(near, -extent, extent), _Z_AXIS)
    t_in, t_out = _clip_segment_to_slabs(c, d, half, extent, np.ones((k, 3), dtype=bool))
    inside_middle = 0.5 * (np.where(inside_box, t_in, 0.0) + np.where(inside_box, t_out, 0.0))
    t_mid = np.clip(np.where(inside_box, inside_middle, t_near), -half, half)
    middle = c + t_mid[:, None] * d
    penetration = extent - np.abs(middle)
    least = _first_within(-penetration)
    outward_in = np.zeros((k, 3))
    outward_in[rows, least] = _sign(middle[rows, least])
    outward = np.where(inside_box[:, None], outward_in, outward_sep)

    # Single nearest-point contact.
    face_point_in = middle.copy()
    face_point_in[rows, least] = outward_in[rows, least] * extent[rows, least]
    box_point = np.where(inside_box[:, None], face_point_in, np.clip(near, -extent, extent))
    capsule_centre = np.where(inside_box[:, None], middle, near)
    single_depth = np.where(inside_box, radius + penetration[rows, least], radius - distance)
    single_point = 0.5 * (box_point + capsule_centre - radius[:, None] * outward)

    # Face contact: the segment clipped to the face's column.
    face = _first_within(np.abs(outward))
    face_sign = _sign(outward[rows, face])
    along = np.abs(outward[rows, face])
    is_face = inside_box | (1.0 - along**2 < FACE_NORMAL_SIN**2)
    column = np.ones((k, 3), dtype=bool)
    column[rows, face] = False
    f0, f1 = _clip_segment_to_slabs(c, d, half, extent, column)
    use_face = is_face & (f0 <= f1)
    face_normal = np.zeros((k, 3))
    face_normal[rows, face] = face_sign
    f0 = np.where(use_face, f0, 0.0)
    f1 = np.where(use_face, f1, 0.0)
    ends = c[:, None, :] + np.stack([f0, f1], axis=1)[..., None] * d[:, None, :]
    height = face_sign[:, None] * ends[rows, :, face] - extent[rows, face][:, None]
    face_depth = radius[:, None] - height
    face_points = ends - (0.5 * (radius[:, None] + height))[..., None] * face_normal[:, None]

    # Candidates: the two column ends (face case only) and the single nearest-point contact.
    depth = np.concatenate([face_depth, single_depth[:, None]], axis=1)
    param = np.stack([f0, f1, t_mid], axis=1)
    local_point = np.concatenate([face_points, single_point[:, None, :]], axis=1)
    local_normal = -np.stack([face_normal, face_normal, outward], axis=1)
    candidate = np.stack([use_face, use_face, np.ones(k, dtype=bool)], axis=1)
    keep, valid = _deepest_and_farthest(depth, param, candidate & (depth >= -margin))
    point = _to_world(pos_b, rot_b, np.take_along_axis(local_point, keep[..., None], axis=1))
    normal = einsum(
        "kij,kmj->kmi", rot_b, np.take_along_axis(local_normal, keep[..., None], axis=1)
    )
    return _emit(valid, point, normal, np.take_along_axis(depth, keep, axis=1))


def collide_sphere_box(
    pos_a: np.ndarray,
    rot_a: np.ndarray,
    size_a: np.ndarray,
    pos_b: np.ndarray,
    rot_b: np.ndarray,
    size_b: np.ndarray,
    margin: float,
) -> PairContacts:
    """Sphere A against box B: sphere against the closest point of the box.

    Centre outside the box: normal from the centre to the closest box point, depth
    ``r - distance``. Centre inside (or on) the box: pushed out through the face of least
    penetration, normal = minus that face's outward normal, depth ``r + penetration``.
    One contact per pair.
    Batch arrays (``pos (k, 3)`` m world, ``rot (k, 3, 3)``, ``size (k, 3)`` m) as in the
    module docstring.
    """
    if len(pos_a) == 0:
        return PairContacts.empty()
    zeros = np.zeros(len(pos_a))
    return _capsule_box(pos_a, rot_b[:, :, 2], zeros, size_a[:, 0], pos_b, rot_b, size_b, margin)


def collide_capsule_box(
    pos_a: np.ndarray,
    rot_a: np.ndarray,
    size_a: np.ndarray,
    pos_b: np.ndarray,
    rot_b: np.ndarray,
    size_b: np.ndarray,
    margin: float,
) -> PairContacts:
    """Capsule A against box B: exact nearest point of the axis segment, plus face clipping.

    Up to 2 contacts per pair; see ``_capsule_box`` for the algorithm. Limitation: a
    segment passing through the box (penetration deeper than the radius) is pushed out
    through the face of least penetration of the middle of its inside part, which is a
    plausible but not minimal direction.
    Batch arrays (``pos (k, 3)`` m world, ``rot (k, 3, 3)``, ``size (k, 3)`` m) as in the
    module docstring.
    """
    if len(pos_a) == 0:
        return PairContacts.empty()
    return _capsule_box(
        pos_a, rot_a[:, :, 2], size_a[:, 1], size_a[:, 0], pos_b, rot_b, size_b, margin
    )


# ---------------------------------------------------------------------------------------
# Box–box
# ---------------------------------------------------------------------------------------


def _box_axes(rot_a: np.ndarray, rot_b: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The 15 separating-axis candidates of two boxes, world frame.

    Order: A's body axes (0-2), B's body axes (3-5), ``a_i × b_j`` at ``6 + 3 i + j``.

    Returns:
        axes: (k, 15, 3) unit (arbitrary where unusable);
        usable: (k, 15) bool, false for edge axes with ``|a_i × b_j| < EDGE_AXIS_MIN_SIN``.
    """
    faces_a, faces_b = rot_a.transpose(0, 2, 1), rot_b.transpose(0, 2, 1)  # rows: body axes
    edges = _cross(faces_a[:, :, None, :], faces_b[:, None, :, :]).reshape(-1, 9, 3)  # 3 i + j
    axes = np.concatenate([faces_a, faces_b, edges], axis=1)
    length = norm(axes)
    usable = np.ones(length.shape, dtype=bool)
    usable[:, 6:] = length[:, 6:] > EDGE_AXIS_MIN_SIN
    return axes / np.where(usable, length, 1.0)[..., None], usable


def _projected_radius(rot: np.ndarray, size: np.ndarray, axes: np.ndarray) -> np.ndarray:
    """Half widths (k, m), m, of the boxes along unit world ``axes (k, m, 3)``.

    Boxes: ``rot (k, 3, 3)`` body to world, ``size (k, 3)`` m half extents.
    """
    return last_axis_sum(np.abs(einsum("kji,kmj->kmi", rot, axes)) * size[:, None, :])


def _clearly_better(new: np.ndarray, old: np.ndarray, absolute: np.ndarray) -> np.ndarray:
    """Where separation ``new`` beats ``old`` by the Box2D-Lite bias (``FACE_AXIS_*_TOL``)."""
    return new > old + (1.0 - FACE_AXIS_RELATIVE_TOL) * np.abs(old) + absolute


def _choose_axis(separation: np.ndarray, size_a: np.ndarray, size_b: np.ndarray) -> np.ndarray:
    """Index (k,) of the axis of largest separation, biased: faces of A, then of B, then edges.

    ``separation (k, 15)`` m, ``-inf`` on unusable axes. An axis of a later group replaces
    the current choice only if it is clearly better (``_clearly_better``), so ties and
    near-ties (resting stacks, where an edge axis can equal a face axis) give face contacts.
    """
    rows = np.arange(separation.shape[0])
    absolute = FACE_AXIS_ABSOLUTE_TOL * np.minimum(size_a.min(axis=1), size_b.min(axis=1))
    best = _first_within(separation[:, 0:3])
    for start, stop in ((3, 6), (6, 15)):
        candidate = start + _first_within(separation[:, start:stop])
        better = _clearly_better(separation[rows, candidate], separation[rows, best], absolute)
        best = np.where(better, candidate, best)
    return best


def _clip_polygon(
    polygon: np.ndarray, count: np.ndarray, coord: int, sign: float, bound: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """One Sutherland–Hodgman step: keep the part of each polygon with ``sign x[coord] <= bound``.

    Args:
        polygon: (n, CLIP_CAPACITY, 3) vertices in order, first ``count`` slots used.
        count: (n,) int, vertices per polygon.
        coord: which coordinate the clipping plane constrains; sign: ±1.
        bound: (n,) the plane offset.

    Returns:
        The clipped polygons (n, CLIP_CAPACITY, 3) and their vertex counts (n,).
    """
    n, capacity, _ = polygon.shape
    pairs = np.arange(n)[:, None]
    used, following = _USED_SLOTS[count], _FOLLOWING_SLOT[count]
    nxt = polygon[pairs, following]
    dist_here = sign * polygon[..., coord] - bound[:, None]
    dist_next = dist_here[pairs, following]  # the following vertex's own distance
    inside_here = dist_here <= 0.0
    keep_here = used & inside_here
    crosses = used & (inside_here != (dist_next <= 0.0))
    fraction = dist_here / np.where(crosses, dist_here - dist_next, 1.0)
    crossing = polygon + fraction[..., None] * (nxt - polygon)

    # each vertex, then its edge's crossing, in order: kept entries packed to the front
    candidates = np.empty((n, capacity, 2, 3))
    candidates[:, :, 0], candidates[:, :, 1] = polygon, crossing
    present = np.empty((n, capacity, 2), dtype=bool)
    present[:, :, 0], present[:, :, 1] = keep_here, crosses
    present = present.reshape(n, 2 * capacity)
    order = np.argsort(~present, axis=1, kind="stable")[:, :capacity]
    clipped = candidates.reshape(n, 2 * capacity, 3)[pairs, order]
    return clipped, np.minimum(np.count_nonzero(present, axis=1), capacity)


def _reduce_manifold(
    plane_xy: np.ndarray, depth: np.ndarray, valid: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """Choose at most ``MAX_MANIFOLD_POINTS`` contacts per pair from a clipped patch.

    Pairs with at most 4 valid points keep them all. Otherwise (Bullet's
    ``sortCachedPoints`` / Box2D v3's manifold reduction): the deepest point; the point
    farthest from it; the point farthest on the left of the line through those two; the
    point farthest on its right. That spans the patch (largest quadrilateral, greedily).
    Ties within ``TIE_TOL`` go to the first slot.

    Args:
        plane_xy: (n, m, 2) m, coordinates in the contact plane; depth: (n, m) m;
        valid: (n, m) bool.

    Returns:
        order: (n, 4) int, slots to keep (in the order chosen), keep: (n, 4) bool.
    """
    n, m = valid.shape
    rows = np.arange(n)
    points = np.count_nonzero(valid, axis=1)
    if (points <= MAX_MANIFOLD_POINTS).all():  # every patch kept whole: nothing to choose
        return _packed(valid, rows)
    chosen = np.zeros((n, m), dtype=bool)

    def take(index: np.ndarray) -> np.ndarray:
        chosen[rows, index] = True
        return plane_xy[rows, index]

    first = take(_first_within(np.where(valid, depth, -np.inf)))
    spread = norm(plane_xy - first[:, None])
    second = take(_first_within(np.where(valid & ~chosen, spread, -np.inf)))
    edge, _ = _normalize(
        np.concatenate([second - first, np.zeros((n, 1))], axis=1), np.array([1.0, 0.0, 0.0])
    )
    rel = plane_xy - first[:, None]
    offset = edge[:, None, 0] * rel[..., 1] - edge[:, None, 1] * rel[..., 0]
    take(_first_within(np.where(valid & ~chosen, offset, -np.inf)))
    take(_first_within(np.where(valid & ~chosen, -offset, -np.inf)))

    return _packed(np.where((points <= MAX_MANIFOLD_POINTS)[:, None], valid, chosen), rows)


def _packed(keep: np.ndarray, rows: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The first ``MAX_MANIFOLD_POINTS`` slots (n, 4) of ``keep (n, m)`` once its kept slots
    are moved to the front in slot order (a stable sort), and whether each is kept (n, 4)."""
    order = np.argsort(~keep, axis=1, kind="stable")[:, :MAX_MANIFOLD_POINTS]
    return order, keep[rows[:, None], order]


def _face_contacts(
    pos_r: np.ndarray,
    rot_r: np.ndarray,
    size_r: np.ndarray,
    face: np.ndarray,
    normal_r: np.ndarray,
    pos_i: np.ndarray,
    rot_i: np.ndarray,
    size_i: np.ndarray,
    margin: float,
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Face contact of a reference box and an incident box, by clipping.

    The incident face (the face of the incident box most anti-parallel to the reference
    normal) is clipped against the 4 side planes of the reference face (Sutherland–Hodgman);
    clipped vertices at height ``z <= margin`` above the reference face are contacts of
    depth ``-z``, reduced to at most 4 (``_reduce_manifold``). Each point is placed midway
    between the incident vertex and its projection onto the reference face.

    Args:
        pos_r, rot_r, size_r: (n, 3), (n, 3, 3), (n, 3) the reference box (world, m).
        face: (n,) int, body axis of the reference face.
        normal_r: (n, 3) unit world, outward normal of the reference face (towards the
            incident box).
        pos_i, rot_i, size_i: the incident box.

    Returns:
        point (n, 4, 3) m world, depth (n, 4) m, valid (n, 4) bool.
    """
    n = pos_r.shape[0]
    rows = np.arange(n)
    tangent_1, tangent_2 = _column(rot_r, (face + 1) % 3), _column(rot_r, (face + 2) % 3)
    half_1, half_2 = size_r[rows, (face + 1) % 3], size_r[rows, (face + 2) % 3]
    face_centre = pos_r + size_r[rows, face][:, None] * normal_r

    alignment = _to_local(rot_i, normal_r)
    incident = _first_within(np.abs(alignment))
    outward = -_sign(alignment[rows, incident])
    u, v = (incident + 1) % 3, (incident + 2) % 3
    incident_centre = pos_i + (outward * size_i[rows, incident])[:, None] * _column(rot_i, incident)
    spans = np.empty((n, 2, 3))
    spans[:, 0] = size_i[rows, u][:, None] * _column(rot_i, u)
    spans[:, 1] = size_i[rows, v][:, None] * _column(rot_i, v)
    corners = incident_centre[:, None, :] + einsum("cs,nsj->ncj", _QUAD_SIGNS, spans)

    relative = corners - face_centre[:, None, :]
    polygon = np.zeros((n, CLIP_CAPACITY, 3))
    for coord, axis in enumerate((tangent_1, tangent_2, normal_r)):
        polygon[:, :4, coord] = _dot(relative, axis[:, None, :])
    count = np.full(n, 4)
    for coord, half in ((0, half_1), (1, half_2)):
        for sign in (1.0, -1.0):
            polygon, count = _clip_polygon(polygon, count, coord, sign, half)

    height = polygon[..., 2]
    depth = -height
    valid = (count[:, None] > _CLIP_SLOTS) & (depth >= -margin)
    order, keep = _reduce_manifold(polygon[..., :2], depth, valid)
    kept = polygon[rows[:, None], order]
    point = (
        face_centre[:, None, :]
        + kept[..., 0:1] * tangent_1[:, None, :]
        + kept[..., 1:2] * tangent_2[:, None, :]
        + 0.5 * kept[..., 2:3] * normal_r[:, None, :]
    )
    return point, -kept[..., 2], keep


def _edge_contacts(
    pos_a: np.ndarray,
    rot_a: np.ndarray,
    size_a: np.ndarray,
    pos_b: np.ndarray,
    rot_b: np.ndarray,
    size_b: np.ndarray,
    edge_axis: np.ndarray,
    normal: np.ndarray,
) -> np.ndarray:
    """Edge–edge contact point (n, 3), m world: midway between the closest points of the edges.

    ``edge_axis (n,)`` int in 0..8 is ``3 i + j`` for the axis ``a_i × b_j``; ``normal (n, 3)``
    is that axis, unit, oriented from A to B. A's edge is its edge along ``a_i`` furthest
    along the normal, B's its edge along ``b_j`` furthest against it (the support edges).
    """
    i, j = edge_axis // 3, edge_axis % 3
    rows = np.arange(len(i))
    toward_a = _sign(_to_local(rot_a, normal)) * size_a
    toward_a[rows, i] = 0.0
    toward_b = -_sign(_to_local(rot_b, normal)) * size_b
    toward_b[rows, j] = 0.0
    centre_a = pos_a + einsum("nij,nj->ni", rot_a, toward_a)
    centre_b = pos_b + einsum("nij,nj->ni", rot_b, toward_b)
    axis_a, axis_b = _column(rot_a, i), _column(rot_b, j)
    s, t = _closest_segment_params(
        centre_a, axis_a, size_a[rows, i], centre_b, axis_b, size_b[rows, j]
    )
    return 0.5 * (centre_a + s[:, None] * axis_a + centre_b + t[:, None] * axis_b)


def collide_box_box(
    pos_a: np.ndarray,
    rot_a: np.ndarray,
    size_a: np.ndarray,
    pos_b: np.ndarray,
    rot_b: np.ndarray,
    size_b: np.ndarray,
    margin: float,
) -> PairContacts:
    """Box A against box B: separating-axis test, then face clipping or edge–edge contact.

    1. Separation along the 15 axes (``_box_axes``): ``|d · L| - r_a(L) - r_b(L)``; a pair
       with any separation above ``margin`` has no contact.
    2. The axis of largest separation, with the Box2D-Lite bias towards face axes
       (``_choose_axis``); the normal is that axis oriented from A to B.
    3. Face axis: the face of that box is the reference face; the other box's most
       anti-parallel face is clipped against it (``_face_contacts``), up to 4 contacts.
       Edge axis: 1 contact midway between the closest points of the two support edges
       (``_edge_contacts``), depth = minus the separation along the normal.


    Batch arrays (``pos (k, 3)`` m world, ``rot (k, 3, 3)``, ``size (k, 3)`` m) as in the
    module docstring.
    """
    k = len(pos_a)
    if k == 0:
        return PairContacts.empty()
    rows = np.arange(k)
    offset = pos_b - pos_a
    axes, usable = _box_axes(rot_a, rot_b)
    separation = (
        np.abs(_dot(offset[:, None, :], axes))
        - _projected_radius(rot_a, size_a, axes)
        - _projected_radius(rot_b, size_b, axes)
    )
    separation = np.where(usable, separation, -np.inf)
    touching = (separation <= margin).all(axis=1)
    best = _choose_axis(separation, size_a, size_b)
    normal = _orient(axes[rows, best], offset)
    # Separation along the oriented normal: equals separation[rows, best] except where
    # d · L is within TIE_TOL of 0 and ``_orient`` kept the axis as it was.
    along_normal = separation[rows, best] - np.abs(_dot(offset, axes[rows, best]))
    along_normal += _dot(offset, normal)

    point = np.zeros((k, MAX_MANIFOLD_POINTS, 3))
    depth = np.zeros((k, MAX_MANIFOLD_POINTS))
    valid = np.zeros((k, MAX_MANIFOLD_POINTS), dtype=bool)

    on_face = np.flatnonzero(touching & (best < 6))
    if on_face.size:
        ref_is_b = best[on_face] >= 3

        def pick(b_value: np.ndarray, a_value: np.ndarray) -> np.ndarray:
            return _select(ref_is_b, b_value, a_value)

        face_point, face_depth, face_valid = _face_contacts(
            pick(pos_b[on_face], pos_a[on_face]),
            pick(rot_b[on_face], rot_a[on_face]),
            pick(size_b[on_face], size_a[on_face]),
            best[on_face] % 3,
            pick(-normal[on_face], normal[on_face]),
            pick(pos_a[on_face], pos_b[on_face]),
            pick(rot_a[on_face], rot_b[on_face]),
            pick(size_a[on_face], size_b[on_face]),
            margin,
        )
        point[on_face], depth[on_face], valid[on_face] = face_point, face_depth, face_valid

    on_edge = np.flatnonzero(touching & (best >= 6))
    if on_edge.size:
        point[on_edge, 0] = _edge_contacts(
            pos_a[on_edge],
            rot_a[on_edge],
            size_a[on_edge],
            pos_b[on_edge],
            rot_b[on_edge],
            size_b[on_edge],
            best[on_edge] - 6,
            normal[on_edge],
        )
        depth[on_edge, 0] = -along_normal[on_edge]
        valid[on_edge, 0] = True

    return _emit(valid, point, normal, depth)


NARROW_PHASE: dict[tuple[ShapeType, ShapeType], Callable[..., PairContacts]] = {
    (ShapeType.PLANE, ShapeType.SPHERE): collide_plane_sphere,
    (ShapeType.PLANE, ShapeType.CAPSULE): collide_plane_capsule,
    (ShapeType.PLANE, ShapeType.BOX): collide_plane_box,
    (ShapeType.SPHERE, ShapeType.SPHERE): collide_sphere_sphere,
    (ShapeType.SPHERE, ShapeType.CAPSULE): collide_sphere_capsule,
    (ShapeType.SPHERE, ShapeType.BOX): collide_sphere_box,
    (ShapeType.CAPSULE, ShapeType.CAPSULE): collide_capsule_capsule,
    (ShapeType.CAPSULE, ShapeType.BOX): collide_capsule_box,
    (ShapeType.BOX, ShapeType.BOX): collide_box_box,
}
"""Narrow-phase function per shape pair ``(A, B)`` with ``A <= B`` (``ShapeType`` order)."""
