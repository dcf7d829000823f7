"""Frame helpers shared by the adapters: a rotation matrix as a quaternion, and a body's
principal axes (engines that take a diagonal inertia in a rotated inertial frame: PyBullet,
Rapier)."""

from __future__ import annotations

import math

import numpy as np


def matrix_to_quat(rot: np.ndarray) -> np.ndarray:
    """(4,) unit quaternion w x y z of the rotation matrix ``rot (3, 3)`` (Shepperd's method)."""
    trace = np.trace(rot)
    diagonal = np.diag(rot)
    k = int(np.argmax([trace, *diagonal]))
    if k == 0:
        s = 2.0 * math.sqrt(1.0 + trace)
        quat = [0.25 * s, (rot[2, 1] - rot[1, 2]) / s, (rot[0, 2] - rot[2, 0]) / s]
        quat.append((rot[1, 0] - rot[0, 1]) / s)
    else:
        i = k - 1
        j, m = (i + 1) % 3, (i + 2) % 3
        s = 2.0 * math.sqrt(1.0 + rot[i, i] - rot[j, j] - rot[m, m])
        vector = np.zeros(3)
        vector[i] = 0.25 * s
        vector[j] = (rot[j, i] + rot[i, j]) / s
        vector[m] = (rot[m, i] + rot[i, m]) / s
        quat = [(rot[m, j] - rot[j, m]) / s, *vector]
    quat = np.asarray(quat)
    return quat / np.linalg.norm(quat)


def principal_axes(inertia: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Principal moments (3,) kg·m² and the principal-axes rotation q_P (4,) w x y z.

    ``inertia = P diag(moments) Pᵀ`` with ``P = R(q_P)`` a proper rotation (body frame).
    A diagonal tensor keeps its order and q_P = identity, so the common case passes
    the scene's numbers to PyBullet untouched.
    """
    if not np.any(inertia - np.diag(np.diag(inertia))):
        return np.diag(inertia).copy(), np.array([1.0, 0.0, 0.0, 0.0])
    moments, axes = np.linalg.eigh(inertia)
    if np.linalg.det(axes) < 0:
        axes[:, 2] = -axes[:, 2]
    return moments, matrix_to_quat(axes)
