"""Batched rotation algebra: quaternions (w, x, y, z), rotation matrices, world inertia.

Conventions: a quaternion ``q`` rotates body-frame vectors into the world frame,
``R(q) @ v_body = v_world``; angular velocity ``ω`` is in the world frame, so
the orientation obeys ``dq/dt = ½ [0, ω] ⊗ q`` (world-frame ω multiplies from
the left). Every function is batched over a leading axis of bodies.
"""

from __future__ import annotations

import numpy as np

SMALL_ANGLE = 1e-12
"""rad. Below this rotation angle the exponential map uses its first-order series
(sin(θ/2)/θ → 1/2), avoiding 0/0; far below double-precision significance."""


def quat_to_matrix(quat: np.ndarray) -> np.ndarray:
    """Rotation matrices (n, 3, 3), body to world, from unit quaternions ``quat (n, 4)`` w x y z."""
    w, x, y, z = quat[:, 0], quat[:, 1], quat[:, 2], quat[:, 3]
    rot = np.empty((quat.shape[0], 3, 3))
    rot[:, 0, 0] = 1 - 2 * (y * y + z * z)
    rot[:, 0, 1] = 2 * (x * y - w * z)
    rot[:, 0, 2] = 2 * (x * z + w * y)
    rot[:, 1, 0] = 2 * (x * y + w * z)
    rot[:, 1, 1] = 1 - 2 * (x * x + z * z)
    rot[:, 1, 2] = 2 * (y * z - w * x)
    rot[:, 2, 0] = 2 * (x * z - w * y)
    rot[:, 2, 1] = 2 * (y * z + w * x)
    rot[:, 2, 2] = 1 - 2 * (x * x + y * y)
    return rot


def quat_multiply(p: np.ndarray, q: np.ndarray) -> np.ndarray:
    """Hamilton products ``p ⊗ q`` (n, 4) of quaternions ``p, q (n, 4)`` w x y z."""
    pw, pv = p[:, :1], p[:, 1:]
    qw, qv = q[:, :1], q[:, 1:]
    w = pw * qw - np.sum(pv * qv, axis=1, keepdims=True)
    v = pw * qv + qw * pv + cross(pv, qv)
    return np.concatenate([w, v], axis=1)


def quat_normalize(quat: np.ndarray) -> np.ndarray:
    """Unit quaternions (n, 4) with the same direction as ``quat (n, 4)``."""
    return quat / np.linalg.norm(quat, axis=1, keepdims=True)


def rotation_quat(rotation_vector: np.ndarray) -> np.ndarray:
    """Unit quaternions (n, 4) of the rotations ``θ = |r|`` about ``r / |r|``, from ``r (n, 3)`` rad.

    ``[cos(θ/2), sin(θ/2) r/|r|]``, exact; below ``SMALL_ANGLE`` the series limit.
    """
    angle = np.linalg.norm(rotation_vector, axis=1)
    half = 0.5 * angle
    safe_angle = np.where(angle > SMALL_ANGLE, angle, 1.0)
    scale = np.where(angle > SMALL_ANGLE, np.sin(half) / safe_angle, 0.5)
    return np.concatenate([np.cos(half)[:, None], scale[:, None] * rotation_vector], axis=1)


def world_inertia(rot: np.ndarray, inertia_body: np.ndarray) -> np.ndarray:
    """World-frame tensors ``R I Rᵀ`` (n, 3, 3) from ``rot (n, 3, 3)`` and body-frame ``inertia_body (n, 3, 3)``.

    The same function gives the world inverse inertia ``R I⁻¹ Rᵀ`` from the body-frame
    inverse (formulas.md section 2): for a rotation ``Rᵀ = R⁻¹``.
    """
    return rot @ inertia_body @ rot.transpose(0, 2, 1)  # 3x faster than a 3-operand einsum


def apply(matrix: np.ndarray, vector: np.ndarray) -> np.ndarray:
    """Batched matrix-vector products (n, 3) of ``matrix (n, 3, 3)`` and ``vector (n, 3)``."""
    return np.einsum("nij,nj->ni", matrix, vector)


def apply_transpose(matrix: np.ndarray, vector: np.ndarray) -> np.ndarray:
    """Batched ``matrixᵀ @ vector`` (n, 3): world to body frame when ``matrix`` is R."""
    return np.einsum("nji,nj->ni", matrix, vector)


def cross(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Row-wise cross products (n, 3) of ``a, b (n, 3)``, right-handed (formulas.md section 1).

    Written out component by component: for small batches this is several times
    faster than ``np.cross``, and it sits in the solver's inner loop.
    """
    ax, ay, az = a[:, 0], a[:, 1], a[:, 2]
    bx, by, bz = b[:, 0], b[:, 1], b[:, 2]
    out = np.empty((a.shape[0], 3))  # filled column by column: cheaper than np.stack
    out[:, 0] = ay * bz - az * by
    out[:, 1] = az * bx - ax * bz
    out[:, 2] = ax * by - ay * bx
    return out
