"""Collision shapes, their size convention, and exact solid-body mass properties.

Every body has one shape. Shapes are stored in the model as two arrays:

- ``body_shape (n,)`` int, a :class:`ShapeType` value;
- ``body_size (n, 3)`` float, metres, body frame, meaning by shape:

  ========  ===========================================================
  shape     ``body_size`` row
  ========  ===========================================================
  PLANE     ``(0, 0, 0)``; the plane passes through the body position,
            its normal is the body's +z axis; infinite; always static
  SPHERE    ``(radius, 0, 0)``
  CAPSULE   ``(radius, half_length, 0)``; a cylinder of length
            ``2 * half_length`` along body z, capped by two hemispheres
  BOX       ``(half_x, half_y, half_z)``, half extents along body axes
  ========  ===========================================================

The enum order is the narrow-phase table order: a pair is always looked up with
the lower shape value as body A (see ``mini_engine.narrowphase``).

Mass properties are those of a uniform solid (MuJoCo computes the same
values; PyBullet approximates the capsule by its bounding box, see
``docs/engines.md`` section 2.1).
"""

from __future__ import annotations

from dataclasses import dataclass
from enum import IntEnum

import numpy as np


class ShapeType(IntEnum):
    """Shape codes stored in ``Model.body_shape``; order fixes the narrow-phase pair order."""

    PLANE = 0
    SPHERE = 1
    CAPSULE = 2
    BOX = 3


@dataclass(frozen=True)
class Plane:
    """Infinite static plane through the body position, normal = body +z."""

    def size(self) -> np.ndarray:
        return np.zeros(3)

    def unit_inertia(self) -> np.ndarray:
        """A plane is always static; it has no meaningful inertia."""
        return np.zeros((3, 3))

    def bounding_radius(self) -> float:
        return np.inf

    type = ShapeType.PLANE


@dataclass(frozen=True)
class Sphere:
    """Solid sphere of ``radius`` metres."""

    radius: float

    type = ShapeType.SPHERE

    def size(self) -> np.ndarray:
        return np.array([self.radius, 0.0, 0.0])

    def unit_inertia(self) -> np.ndarray:
        """Inertia per kilogram about the centre, body frame, m²: ``2/5 r²`` on the diagonal."""
        return np.eye(3) * (2.0 / 5.0) * self.radius**2

    def bounding_radius(self) -> float:
        return self.radius


@dataclass(frozen=True)
class Box:
    """Solid box with ``half_extents`` (hx, hy, hz) metres along the body axes."""

    half_extents: tuple[float, float, float]

    type = ShapeType.BOX

    def size(self) -> np.ndarray:
        return np.asarray(self.half_extents, dtype=float)

    def unit_inertia(self) -> np.ndarray:
        """Inertia per kilogram, body frame, m²: ``Ixx = (hy² + hz²)/3`` and cyclic.

        This is the familiar ``m (b² + c²) / 12`` written with half extents (b = 2 hy).
        """
        hx, hy, hz = self.half_extents
        return np.diag([hy**2 + hz**2, hx**2 + hz**2, hx**2 + hy**2]) / 3.0

    def bounding_radius(self) -> float:
        return float(np.linalg.norm(self.half_extents))


@dataclass(frozen=True)
class Capsule:
    """Solid capsule: cylinder of ``2 * half_length`` along body z plus two hemispherical caps."""

    radius: float
    half_length: float

    type = ShapeType.CAPSULE

    def size(self) -> np.ndarray:
        return np.array([self.radius, self.half_length, 0.0])

    def unit_inertia(self) -> np.ndarray:
        """Exact inertia per kilogram of a uniform solid capsule, body frame, m².

        The mass splits between the cylinder and the two caps by volume. Each cap
        (mass ``m_h``) contributes ``m_h (2r²/5 + L²/4 + 3 L r / 8)`` about a
        transverse axis through the centre, where ``L = 2 * half_length``: its own
        moment about its base ``2 m_h r²/5`` moved by the parallel-axis theorem from
        its centroid (``3r/8`` above the base) to the capsule centre.
        """
        r, length = self.radius, 2.0 * self.half_length
        volume_cylinder = np.pi * r**2 * length
        volume_caps = 4.0 / 3.0 * np.pi * r**3
        total = volume_cylinder + volume_caps
        m_cylinder, m_cap = volume_cylinder / total, 0.5 * volume_caps / total
        axial = m_cylinder * r**2 / 2.0 + 2.0 * m_cap * (2.0 / 5.0) * r**2
        transverse = m_cylinder * (length**2 / 12.0 + r**2 / 4.0) + 2.0 * m_cap * (
            2.0 / 5.0 * r**2 + length**2 / 4.0 + 3.0 * length * r / 8.0
        )
        return np.diag([transverse, transverse, axial])

    def bounding_radius(self) -> float:
        return self.radius + self.half_length


Shape = Plane | Sphere | Box | Capsule


def solid_inertia(shape: Shape, mass: float) -> np.ndarray:
    """Inertia tensor (3, 3) of a uniform solid ``shape`` of ``mass`` kg about its centre, body frame, kg·m²."""
    return mass * shape.unit_inertia()
