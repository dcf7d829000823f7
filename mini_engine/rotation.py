"""Batched rotation algebra: quaternions (w, x, y, z), rotation matrices, world inertia.

Conventions: a quaternion ``q`` rotates body-frame vectors into the world frame,
``R(q) @ v_body = v_world``; angular velocity ``ω`` is in the world frame, so
the orientation obeys ``dq/dt = ½ [0, ω] ⊗ q`` (world-frame ω multiplies from
the left). Every function is batched over a leading axis of bodies.
"""

from __future__ import annotations

import numpy as np

try:  # NumPy 2: the C kernel lives in numpy._core
    from numpy._core.multiarray import c_einsum
except ImportError:  # NumPy 1.26 (the oldest the project supports): in numpy.core
    from numpy.core.multiarray import c_einsum

einsum = c_einsum
"""``np.einsum`` without its Python layer: with ``optimize=False`` (its default) ``np.einsum``
hands its operands straight to this C function, so the results are the same bit for bit; the
dispatcher and wrapper it skips cost more than the product itself on a few contacts."""

SMALL_ANGLE = 1e-12
"""rad. Below this rotation angle the exponential map uses its first-order series
(sin(θ/2)/θ → 1/2), avoiding 0/0; far below double-precision significance."""


QUAT_PRODUCT_ROWS = 64
"""Batches of at most this many quaternions build their matrices and products from a table
of products ``a_i b_j`` (``_matrices_from_products``, ``_product_from_products``): a dozen
whole-array operations instead of twenty to thirty, which is what a step of a few bodies pays
for (one body's matrix: 4 µs against 12 µs, a product 5.6 against 9.4). From about 128 rows
on, the table's 16 products a row cost more than the formulas' own arithmetic."""

PRODUCT_FIRST = np.array([10, 6, 7, 6, 5, 11, 7, 11, 5])
"""Flat index ``4 i + j`` (``q_i q_j``, w x y z = 0 1 2 3) of each entry's first product, in
row-major entry order: yy xy xz, xy xx yz, xz yz xx."""

PRODUCT_SECOND = np.array([15, 3, 2, 3, 15, 1, 2, 1, 10])
"""The second product of each entry: zz wz wy, wz zz wx, wy wx yy."""

SIGN_FIRST = np.array([-1.0, 1.0, 1.0, 1.0, -1.0, 1.0, 1.0, 1.0, -1.0])
SIGN_SECOND = np.array([-1.0, -1.0, 1.0, 1.0, -1.0, -1.0, -1.0, 1.0, -1.0])
"""Each product's sign in its entry, ``2 (±first ± second)``."""

DIAGONAL_ENTRIES = np.eye(3, dtype=bool).ravel()
"""(9,) the diagonal entries, ``1 - 2 (...)``: only they get the 1 (adding 0 to the others would
turn a -0.0 into +0.0)."""


def quat_to_matrix(quat: np.ndarray) -> np.ndarray:
    """Rotation matrices (n, 3, 3), body to world, from unit quaternions ``quat (n, 4)`` w x y z."""
    if quat.shape[0] <= QUAT_PRODUCT_ROWS:
        return _matrices_from_products(quat)
    w, x, y, z = quat[:, 0], quat[:, 1], quat[:, 2], quat[:, 3]
    xx, yy, zz = x * x, y * y, z * z  # each product once: it appears in two entries
    xy, xz, yz = x * y, x * z, y * z
    wx, wy, wz = w * x, w * y, w * z
    rot = np.empty((quat.shape[0], 3, 3))
    rot[:, 0, 0] = 1 - 2 * (yy + zz)
    rot[:, 0, 1] = 2 * (xy - wz)
    rot[:, 0, 2] = 2 * (xz + wy)
    rot[:, 1, 0] = 2 * (xy + wz)
    rot[:, 1, 1] = 1 - 2 * (xx + zz)
    rot[:, 1, 2] = 2 * (yz - wx)
    rot[:, 2, 0] = 2 * (xz - wy)
    rot[:, 2, 1] = 2 * (yz + wx)
    rot[:, 2, 2] = 1 - 2 * (xx + yy)
    return rot


def _matrices_from_products(quat: np.ndarray) -> np.ndarray:
    """``quat_to_matrix``'s entries from the table of products ``q_i q_j`` (n, 16): each entry
    ``2 (±first ± second)``, plus 1 on the diagonal: the same operations on the same products
    (``a - b`` is ``a + (-b)`` in IEEE arithmetic, signed zeros included), so bit for bit the
    entries written out above."""
    products = (quat[:, :, None] * quat[:, None, :]).reshape(-1, 16)
    entries = products.take(PRODUCT_FIRST, axis=1) * SIGN_FIRST  # float whatever the input
    second = products.take(PRODUCT_SECOND, axis=1) * SIGN_SECOND
    entries += second
    entries *= 2.0
    np.add(entries, 1.0, out=entries, where=DIAGONAL_ENTRIES)
    return entries.reshape(-1, 3, 3)


CROSS_FIRST = np.array([11, 13, 6])
CROSS_SECOND = np.array([14, 7, 9])
"""Flat indices ``4 i + j`` of ``p_i q_j`` in the cross product ``p_v × q_v = first - second``:
(yz, zx, xy) less (zy, xz, yx)."""


def quat_multiply(p: np.ndarray, q: np.ndarray) -> np.ndarray:
    """Hamilton products ``p ⊗ q`` (n, 4) of quaternions ``p, q (n, 4)`` w x y z:
    ``(p_w q_w - p_v·q_v, p_w q_v + q_w p_v + p_v × q_v)``."""
    if p.shape[0] <= QUAT_PRODUCT_ROWS:
        return _product_from_products(p, q)
    pw, pv = p[:, :1], p[:, 1:]
    qw, qv = q[:, :1], q[:, 1:]
    product = np.empty((p.shape[0], 4))  # filled in place: cheaper than np.concatenate
    np.subtract(pw * qw, last_axis_sum(pv * qv)[:, None], out=product[:, :1])
    np.add(pw * qv + qw * pv, cross(pv, qv), out=product[:, 1:])
    return product


def _product_from_products(p: np.ndarray, q: np.ndarray) -> np.ndarray:
    """``quat_multiply`` from the table of products ``p_i q_j`` (n, 16) (as
    ``_matrices_from_products``): the same sums of the same products in the same order, so
    bit for bit the same quaternions."""
    products = (p[:, :, None] * q[:, None, :]).reshape(-1, 16)
    product = np.empty((p.shape[0], 4))
    dot = 0.0 + products[:, 5]  # last_axis_sum's order: 0 + xx + yy + zz
    dot += products[:, 10]
    dot += products[:, 15]
    np.subtract(products[:, 0], dot, out=product[:, 0])
    spin = products.take(CROSS_FIRST, axis=1)
    spin -= products.take(CROSS_SECOND, axis=1)
    np.add(products[:, 1:4] + products[:, 4::4], spin, out=product[:, 1:])  # p_w q_v + q_w p_v
    return product


def quat_normalize(quat: np.ndarray) -> np.ndarray:
    """Unit quaternions (n, 4) with the same direction as ``quat (n, 4)``."""
    return quat / norm(quat, keepdims=True)


def rotation_quat(rotation_vector: np.ndarray) -> np.ndarray:
    """Unit quaternions (n, 4) of the rotations ``θ = |r|`` about ``r / |r|``, from ``r (n, 3)`` rad.

    ``[cos(θ/2), sin(θ/2) r/|r|]``, exact; below ``SMALL_ANGLE`` the series limit.
    """
    angle = norm(rotation_vector)
    half = 0.5 * angle
    finite_angle = angle > SMALL_ANGLE
    safe_angle = np.where(finite_angle, angle, 1.0)
    scale = np.where(finite_angle, np.sin(half) / safe_angle, 0.5)
    rotation = np.empty((rotation_vector.shape[0], 4))  # filled in place, as quat_multiply
    np.cos(half, out=rotation[:, 0])
    np.multiply(scale[:, None], rotation_vector, out=rotation[:, 1:])
    return rotation


def norm(vector: np.ndarray, keepdims: bool = False) -> np.ndarray:
    """Euclidean lengths over the last axis of ``vector (..., k)``: ``np.linalg.norm(vector,
    axis=-1)``'s own operations (square, sum, root) without its dispatch and conj copy."""
    length = np.sqrt(last_axis_sum(vector * vector))
    return length[..., None] if keepdims else length


REDUCTION_ENTRIES = 120
"""Arrays of at most this many entries (40 rows of three) are summed by the reduction itself,
one call (0.6 µs on one row, where the additions below take 1.8 µs); it loses to them from
about 64 rows of three on."""


def last_axis_sum(values: np.ndarray) -> np.ndarray:
    """Sums (...) over the short last axis of ``values (..., k)``, bit for bit as
    ``values.sum(axis=-1)`` computes them (from +0, left to right: ``0 + v0 + v1 + ...``),
    but, past ``REDUCTION_ENTRIES``, as k whole-array additions: several times cheaper than
    the reduction from k = 3 components and a few hundred rows on (a reduction over a 3-long
    axis loops per row)."""
    if values.size <= REDUCTION_ENTRIES:
        return np.add.reduce(values, axis=-1)  # the reduction itself: one call on a few rows
    total = 0.0 + values[..., 0]
    for component in range(1, values.shape[-1]):
        total += values[..., component]
    return total


def world_inertia(rot: np.ndarray, inertia_body: np.ndarray) -> np.ndarray:
    """World-frame tensors ``R I Rᵀ`` (n, 3, 3) from ``rot (n, 3, 3)`` and body-frame ``inertia_body (n, 3, 3)``.

    The same function gives the world inverse inertia ``R I⁻¹ Rᵀ`` from the body-frame
    inverse (formulas.md section 2): for a rotation ``Rᵀ = R⁻¹``.
    """
    return rot @ inertia_body @ rot.transpose(0, 2, 1)  # 3x faster than a 3-operand einsum


def apply(matrix: np.ndarray, vector: np.ndarray) -> np.ndarray:
    """Batched matrix-vector products (n, 3) of ``matrix (n, 3, 3)`` and ``vector (n, 3)``."""
    return einsum("nij,nj->ni", matrix, vector)


def apply_transpose(matrix: np.ndarray, vector: np.ndarray) -> np.ndarray:
    """Batched ``matrixᵀ @ vector`` (n, 3): world to body frame when ``matrix`` is R."""
    return einsum("nji,nj->ni", matrix, vector)


CROSS_TABLE_ROWS = 32
"""Batches of at most this many rows take their cross products from the table of products
``a_i b_j`` (``_cross_from_products``: 1.8 µs a call on one row against 3.5); the tables
lose to the written-out components from about 64 rows on."""

CROSS_TABLE_FIRST = np.array([5, 6, 1])
CROSS_TABLE_SECOND = np.array([7, 2, 3])
"""Flat indices ``3 i + j`` of ``a_i b_j`` in ``a × b = first - second``: (yz, zx, xy) less
(zy, xz, yx)."""


def cross(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Row-wise cross products (n, 3) of ``a, b (n, 3)``, right-handed (formulas.md section 1).

    Written out component by component: for small batches this is several times
    faster than ``np.cross``, and it sits in the solver's inner loop.
    """
    if a.shape[0] <= CROSS_TABLE_ROWS:
        return _cross_from_products(a, b)
    ax, ay, az = a[:, 0], a[:, 1], a[:, 2]
    bx, by, bz = b[:, 0], b[:, 1], b[:, 2]
    out = np.empty((a.shape[0], 3))  # filled column by column: cheaper than np.stack
    out[:, 0] = ay * bz - az * by
    out[:, 1] = az * bx - ax * bz
    out[:, 2] = ax * by - ay * bx
    return out


def _cross_from_products(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """``cross`` from the table of products ``a_i b_j`` (n, 9): the same products, the same
    subtractions, so bit for bit the components written out in ``cross``."""
    products = (a[:, :, None] * b[:, None, :]).reshape(-1, 9)
    first = products.take(CROSS_TABLE_FIRST, axis=1)
    return np.subtract(first, products.take(CROSS_TABLE_SECOND, axis=1), dtype=float)
