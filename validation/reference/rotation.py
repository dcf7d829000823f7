"""Quaternion algebra of the reference side, written from the closed forms.

Conventions (the scene's): a unit quaternion ``q = (w, x, y, z)`` rotates body-frame
vectors into the world frame, ``R(q) v_body = v_world``; products are Hamilton's. Every
function takes any number of leading axes, so a whole recording (states x bodies) is one
call. SciPy's ``Rotation`` checks these formulas in ``tests/test_reference_side.py``.
"""

from __future__ import annotations

import numpy as np

CONJUGATE_SIGNS = np.array([1.0, -1.0, -1.0, -1.0])
"""(4,) signs that turn a quaternion w x y z into its conjugate (the inverse of a unit one)."""

TABLE_ROWS = 32
"""Calls on at most this many quaternions or vectors (the reference integration's right-hand
side: a few bodies and springs, 10^4 to 10^5 calls a scene) compute from a table of all
products ``a_i b_j`` and gather each entry's terms: a dozen whole-array operations instead of
twenty to thirty (one matrix 4.5 µs against 13). Larger arrays (whole recordings) use the
written-out entries, cheaper there. Both give the same bits: the same products, summed in
the same order (``tests/test_reference_side.py``)."""

MATRIX_FIRST = np.array([10, 6, 7, 6, 5, 11, 7, 11, 5])
MATRIX_SECOND = np.array([15, 3, 2, 3, 15, 1, 2, 1, 10])
"""Flat indices ``4 i + j`` of ``q_i q_j`` (w x y z = 0 1 2 3) in each matrix entry, row-major:
``2 (±first ± second)``, plus 1 on the diagonal (yy zz, xy wz, xz wy, ...)."""

MATRIX_SIGN_FIRST = np.array([-1.0, 1.0, 1.0, 1.0, -1.0, 1.0, 1.0, 1.0, -1.0])
MATRIX_SIGN_SECOND = np.array([-1.0, -1.0, 1.0, 1.0, -1.0, -1.0, -1.0, 1.0, -1.0])
"""The signs of ``MATRIX_FIRST`` and ``MATRIX_SECOND`` in their entries."""

MATRIX_DIAGONAL = np.eye(3, dtype=bool).ravel()
"""(9,) the entries that get the 1 (only they: adding 0 would turn -0.0 into +0.0)."""

CROSS_FIRST = np.array([5, 6, 1])
CROSS_SECOND = np.array([7, 2, 3])
"""Flat indices ``3 i + j`` of ``a_i b_j`` in ``a × b = first - second``."""

QUAT_CROSS_FIRST = np.array([11, 13, 6])
QUAT_CROSS_SECOND = np.array([14, 7, 9])
QUAT_DOT = np.array([5, 10, 15])
"""Flat indices ``4 i + j`` of ``p_i q_j``: the vector parts' cross product (first - second)
and dot product in a Hamilton product."""


def _rows(array: np.ndarray) -> int:
    """The number of vectors in ``array (..., d)``."""
    return array.size // array.shape[-1] if array.shape[-1] else 0


def _products(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """(..., d e) every product ``a_i b_j`` of ``a (..., d)`` and ``b (..., e)``, flat ``e i + j``."""
    return (a[..., :, None] * b[..., None, :]).reshape(*a.shape[:-1], a.shape[-1] * b.shape[-1])


def quat_to_matrix(quat: np.ndarray) -> np.ndarray:
    """(..., 3, 3) body-to-world rotation matrices of unit quaternions ``quat (..., 4)``
    w x y z: the entries ``1 - 2(y² + z²)``, ``2(xy - wz)``, ... of the rotation by ``q``."""
    if _rows(quat) <= TABLE_ROWS:
        products = _products(quat, quat)
        entries = products.take(MATRIX_FIRST, axis=-1) * MATRIX_SIGN_FIRST  # float, as below
        second = products.take(MATRIX_SECOND, axis=-1) * MATRIX_SIGN_SECOND
        entries += second  # a - b is a + (-b), signed zeros included
        entries *= 2.0
        np.add(entries, 1.0, out=entries, where=MATRIX_DIAGONAL)
        return entries.reshape(*quat.shape[:-1], 3, 3)
    w, x, y, z = (quat[..., k] for k in range(4))
    rot = np.empty((*quat.shape[:-1], 3, 3))
    rot[..., 0, 0] = 1.0 - 2.0 * (y * y + z * z)
    rot[..., 0, 1] = 2.0 * (x * y - w * z)
    rot[..., 0, 2] = 2.0 * (x * z + w * y)
    rot[..., 1, 0] = 2.0 * (x * y + w * z)
    rot[..., 1, 1] = 1.0 - 2.0 * (x * x + z * z)
    rot[..., 1, 2] = 2.0 * (y * z - w * x)
    rot[..., 2, 0] = 2.0 * (x * z - w * y)
    rot[..., 2, 1] = 2.0 * (y * z + w * x)
    rot[..., 2, 2] = 1.0 - 2.0 * (x * x + y * y)
    return rot


def cross(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """(..., 3) cross products ``a × b`` of ``a, b (..., 3)`` (broadcast): NumPy's ``np.cross``
    formula term for term (so bit-identical to it), without its Python-level axis handling,
    which dominated the reference integration's right-hand side on small arrays."""
    if a.shape == b.shape and _rows(a) <= TABLE_ROWS:
        products = _products(a, b)
        product = products.take(CROSS_FIRST, axis=-1)
        product -= products.take(CROSS_SECOND, axis=-1)
        return product
    a0, a1, a2 = a[..., 0], a[..., 1], a[..., 2]
    b0, b1, b2 = b[..., 0], b[..., 1], b[..., 2]
    shape = a.shape if a.shape == b.shape else np.broadcast_shapes(a.shape, b.shape)
    product = np.empty(shape, dtype=np.result_type(a, b))
    product[..., 0] = a1 * b2 - a2 * b1
    product[..., 1] = a2 * b0 - a0 * b2
    product[..., 2] = a0 * b1 - a1 * b0
    return product


def norm(vectors: np.ndarray, keepdims: bool = False) -> np.ndarray:
    """(...) Euclidean lengths of ``vectors (..., d)`` (float): ``np.linalg.norm(vectors,
    axis=-1)``'s own operations, ``sqrt(add.reduce(v * v))``, so bit-identical to it, without
    its Python-level checks (a tenth of the reference integration's right-hand side)."""
    return np.sqrt(np.add.reduce(vectors * vectors, axis=-1, keepdims=keepdims))


def quat_multiply(p: np.ndarray, q: np.ndarray) -> np.ndarray:
    """(..., 4) Hamilton products ``p ⊗ q`` of quaternions ``p, q (..., 4)`` w x y z:
    ``(p_w q_w - p_v·q_v, p_w q_v + q_w p_v + p_v × q_v)``."""
    if p.shape == q.shape and _rows(p) <= TABLE_ROWS:
        products = _products(p, q)
        dot = np.sum(products.take(QUAT_DOT, axis=-1), axis=-1, keepdims=True)
        spin = products.take(QUAT_CROSS_FIRST, axis=-1)
        spin -= products.take(QUAT_CROSS_SECOND, axis=-1)
        vector = products[..., 1:4] + products[..., 4::4] + spin  # p_w q_v + q_w p_v + ...
        return np.concatenate([products[..., :1] - dot, vector], axis=-1)
    p_scalar, p_vector = p[..., :1], p[..., 1:]
    q_scalar, q_vector = q[..., :1], q[..., 1:]
    scalar = p_scalar * q_scalar - np.sum(p_vector * q_vector, axis=-1, keepdims=True)
    vector = p_scalar * q_vector + q_scalar * p_vector + cross(p_vector, q_vector)
    return np.concatenate([scalar, vector], axis=-1)


def quat_conjugate(quat: np.ndarray) -> np.ndarray:
    """(..., 4) conjugates of ``quat (..., 4)`` w x y z: the inverse rotations of unit ones."""
    return quat * CONJUGATE_SIGNS


def rotation_angle(quat: np.ndarray, reference: np.ndarray) -> np.ndarray:
    """(...) rad, the angle of the rotation between two orientations ``(..., 4)`` w x y z,
    |log(R_refᵀ R)|, in [0, π] whatever the quaternions' signs."""
    relative = quat_multiply(quat_conjugate(reference), quat)
    vector = np.linalg.norm(relative[..., 1:], axis=-1)
    return 2.0 * np.arctan2(vector, np.abs(relative[..., 0]))
