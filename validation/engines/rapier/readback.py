"""Reading Rapier's values back in the scene's conventions (engines-rapier.md 2): quaternions
x y z w -> w x y z, a ``Rotation3`` as a matrix, a rigid body's mass and world inertia."""

from __future__ import annotations

import numpy as np

from validation.reference.rotation import quat_to_matrix


def from_xyzw(quat: np.ndarray) -> np.ndarray:
    """Rapier's ``Rotation3.quaternion`` order x y z w -> w x y z (..., 4)."""
    return np.asarray(quat, dtype=float)[..., [3, 0, 1, 2]]


def rotation_matrix(rotation) -> np.ndarray:
    """(3, 3) the ``Rotation3``'s matrix, from its quaternion."""
    return quat_to_matrix(from_xyzw(np.array([rotation.quaternion])))[0]


def world_inertia(body) -> np.ndarray:
    """(3, 3) kg·m², a rigid body's inertia about its centre of mass in the world frame: its
    principal moments in their local frame (``mass_properties``), turned by its rotation."""
    properties = body.mass_properties
    frame = rotation_matrix(body.rotation) @ rotation_matrix(
        properties.principal_inertia_local_frame
    )
    moments = np.array(properties.principal_inertia.to_tuple(), dtype=float)
    return frame @ np.diag(moments) @ frame.T
