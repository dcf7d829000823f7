"""The scene's angular momentum (``validation.scenario.compiled.angular_momentum``) is taken
about the system's centre of mass, never about the origin of the world."""

from __future__ import annotations

import numpy as np

from validation.scenario.compiled import angular_momentum

MASS = 2.0
"""kg, each of the two bodies."""

CENTRE, CENTRE_VELOCITY = np.array([10.0, -4.0, 3.0]), np.array([1.0, 2.0, 3.0])
"""m, m/s: the pair's centre of mass and its velocity, far from the origin and moving, so
``M c × v_c`` (what the origin would add) is large."""

HALF_SPAN, RELATIVE_VELOCITY = np.array([0.5, 0.0, 0.0]), np.array([0.0, 1.0, 0.0])
"""m, m/s: the bodies sit at ``c ± d`` and move at ``v_c ± u``."""

SPIN, INERTIA = np.array([0.0, 0.0, 4.0]), np.diag([0.1, 0.2, 0.3])
"""rad/s and kg·m²: the first body's spin and inertia (world frame): ``I ω = (0, 0, 1.2)``."""


def test_angular_momentum_is_about_the_centre_of_mass():
    """Two bodies at ``c ± d`` moving at ``v_c ± u``: about their centre of mass
    ``L = Σ m (±d) × (±u) + I ω = 2 m d × u + I ω``, whatever ``c`` and ``v_c`` are; about the
    origin it would read ``M c × v_c`` more."""
    pos = np.stack([CENTRE + HALF_SPAN, CENTRE - HALF_SPAN])[None]
    vel = np.stack([CENTRE_VELOCITY + RELATIVE_VELOCITY, CENTRE_VELOCITY - RELATIVE_VELOCITY])[None]
    ang_vel = np.stack([SPIN, np.zeros(3)])[None]
    inertia = np.stack([INERTIA, INERTIA])[None]
    found = angular_momentum(np.full(2, MASS), inertia, pos, vel, ang_vel)[0]
    expected = 2 * MASS * np.cross(HALF_SPAN, RELATIVE_VELOCITY) + INERTIA @ SPIN
    np.testing.assert_allclose(found, expected, rtol=0, atol=1e-12)
