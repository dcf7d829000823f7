"""Inertia tensors of uniform solids about their centre of mass, body frame, kg·m².

Each shape is the scene's (``validation.scenario.schema``): a sphere of ``radius``; a box of
``half_extents`` along the body axes; a capsule, a cylinder of length ``2 · half_length``
along body z capped by two hemispheres of its ``radius``; a cylinder, the same without the
caps (flat ends). The formulas are derived here from
the solids (a capsule from its cylinder and caps, moved by the parallel-axis theorem) and
checked against a numerical integration over the solid in ``tests/test_reference_side.py``
(the cylinder in ``tests/test_cylinder_reference.py``).
"""

from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np

BALL_MOMENT = 2.0 / 5.0
"""I / (m r²) of a solid ball about a diameter; a solid hemisphere has the same ratio about
any diameter of its flat face (it is half the ball, with half the mass and half the moment)."""

HEMISPHERE_CENTROID = 3.0 / 8.0
"""Distance / r from a solid hemisphere's flat face to its centroid, along its axis."""

CYLINDER_AXIAL = 1.0 / 2.0
"""I / (m r²) of a solid cylinder about its axis."""

CYLINDER_TRANSVERSE_RADIAL = 1.0 / 4.0
CYLINDER_TRANSVERSE_LENGTH = 1.0 / 12.0
"""A solid cylinder of radius r and length ℓ about a diameter through its centre:
I = m (r²/4 + ℓ²/12)."""

BOX_MOMENT = 1.0 / 12.0
"""I / (m (b² + c²)) of a solid box with edges a, b, c about its axis along a."""


def sphere_inertia(mass: float, radius: float) -> np.ndarray:
    """(3, 3) kg·m²: ``2/5 m r²`` on the diagonal, for ``mass`` kg and ``radius`` m."""
    return np.eye(3) * (BALL_MOMENT * mass * radius**2)


def box_inertia(mass: float, half_extents: Sequence[float]) -> np.ndarray:
    """(3, 3) kg·m², principal along the body axes: ``m (b² + c²) / 12`` and cyclic, with
    the edges ``a, b, c`` twice the ``half_extents (3,)`` m."""
    a, b, c = (2.0 * h for h in half_extents)
    return np.diag([b * b + c * c, a * a + c * c, a * a + b * b]) * (BOX_MOMENT * mass)


def capsule_inertia(mass: float, radius: float, half_length: float) -> np.ndarray:
    """(3, 3) kg·m², body z the axis, for ``mass`` kg, ``radius`` m, ``half_length`` m.

    The mass is shared by volume between the cylinder (length ``ℓ = 2 · half_length``) and
    the two hemispherical caps. Axial: the cylinder's ``m_c r²/2`` plus each cap's
    ``2/5 m_h r²``. Transverse, about a diameter through the capsule's centre: the
    cylinder's ``m_c (r²/4 + ℓ²/12)`` plus, per cap, its moment about its own centroid,
    ``(2/5 - (3/8)²) m_h r²`` (its moment about its flat face less ``m_h (3r/8)²``), moved to
    the centre by the parallel-axis term ``m_h d²`` with ``d = ℓ/2 + 3r/8``, the centroid's
    distance from the centre.
    """
    length = 2.0 * half_length
    cylinder_volume = math.pi * radius**2 * length
    caps_volume = 4.0 / 3.0 * math.pi * radius**3  # the two hemispheres make one ball
    density = mass / (cylinder_volume + caps_volume)
    cylinder_mass = density * cylinder_volume
    cap_mass = 0.5 * density * caps_volume
    cylinder = np.diag(cylinder_inertia(cylinder_mass, radius, half_length))
    axial = cylinder[2] + 2.0 * BALL_MOMENT * cap_mass * radius**2
    cap_about_centroid = (BALL_MOMENT - HEMISPHERE_CENTROID**2) * cap_mass * radius**2
    centroid_distance = half_length + HEMISPHERE_CENTROID * radius
    transverse = cylinder[0] + 2.0 * (cap_about_centroid + cap_mass * centroid_distance**2)
    return np.diag([transverse, transverse, axial])


def cylinder_inertia(mass: float, radius: float, half_length: float) -> np.ndarray:
    """(3, 3) kg·m², body z the axis, of a solid cylinder with flat ends: ``mass`` kg,
    ``radius`` m, length ``ℓ = 2 · half_length`` m. Axial ``m r²/2``; transverse, about a
    diameter through the centre, ``m (r²/4 + ℓ²/12) = m (3r² + ℓ²)/12``."""
    length = 2.0 * half_length
    axial = CYLINDER_AXIAL * mass * radius**2
    transverse = mass * (
        CYLINDER_TRANSVERSE_RADIAL * radius**2 + CYLINDER_TRANSVERSE_LENGTH * length**2
    )
    return np.diag([transverse, transverse, axial])
