"""Values between observed steps, by interpolants whose error is far below the engines'.

An expectation at a time ``t`` between two observed states ``t0 < t < t1`` (step ``h = t1 - t0``)
reads the engine's motion there through one of ``INTERPOLANTS``, chosen by quantity:

- a **position**: the cubic Hermite through the observed positions and velocities at both ends,
  ``(x0, v0)`` and ``(x1, v1)``. Exact when the acceleration is constant over the step; for a
  smooth motion its error is at most ``h⁴ max|x⁗| / 384``;
- a **velocity**, an **angular velocity**, an **energy**, a **joint coordinate**: the cubic through the four observed
  values around ``t`` (two before, two at or after; fewer at the ends of a run: the polynomial
  through those). Exact for a cubic in t; at mid-step between equal steps its error is at most
  ``9 h⁴ max|f⁗| / 384``;
- an **orientation**: the same Hermite on the rotation group, ``q(t) = exp(φ(t)) q0`` with
  ``φ`` the cubic Hermite of the world-frame rotation vector from ``q0``: ``φ(t0) = 0``,
  ``φ'(t0) = ω0``, ``φ(t1) = log(q1 q0⁻¹)``, ``φ'(t1) = J⁻¹(φ(t1)) ω1`` (``J`` the left Jacobian
  of the rotation group, so that ``φ'`` reproduces the observed ω). Exact for a constant ω; for a
  smooth rotation its error is ``O(h⁴)`` like a position's.

For scale: a linear interpolation adds ``a·τ(h - τ)/2`` of an acceleration ``a`` (``h²|a|/8`` at
mid-step: 1.2 µm for gravity at h = 1 ms), and the nearer of two steps ``|ω|·h/2`` of rotation
(2.5 mrad at 5 rad/s, h = 1 ms): errors the engine did not make, larger than a fourth-order
engine's own. The Hermite's error for the same cases is 0.
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np
from scipy.interpolate import CubicHermiteSpline
from scipy.spatial.transform import Rotation

SMALL_ANGLE = 1e-4
"""rad. Below this rotation angle the left Jacobian's coefficient ``(1 - (θ/2) cot(θ/2))/θ²``
is taken as its limit 1/12: the closed form cancels about 2·log10(1/θ) of its 16 digits near 0,
while the neglected series term, θ²/720, is below 1.4e-11 of the limit here."""


def hermite_position(time: float, t: np.ndarray, pos: np.ndarray, vel: np.ndarray) -> np.ndarray:
    """(3,) m at ``time`` from the two observed states ``t (2,)`` s, ``pos (2, 3)`` m and
    ``vel (2, 3)`` m/s around it: the cubic Hermite (module docstring)."""
    return CubicHermiteSpline(t, pos, vel, axis=0)(time)


def cubic_through(time: float, t: np.ndarray, values: np.ndarray) -> np.ndarray:
    """(...) the polynomial through the observed ``values (k, ...)`` at times ``t (k,)`` (k <= 4,
    the states around ``time``), evaluated at ``time``: the cubic of the module docstring, in
    Lagrange's form ``Σ_i values_i Π_{j≠i} (time - t_j)/(t_i - t_j)``. Written out rather than
    SciPy's ``BarycentricInterpolator``, which permutes the nodes at random for stability (a
    last-bit difference from run to run: the same scene must give the same numbers)."""
    offsets = time - t  # (k,) s: times from each state, so a 10 s clock does not cost digits
    gaps = t[:, None] - t[None, :]  # (k, k) s, t_i - t_j
    np.fill_diagonal(gaps, 1.0)
    factors = offsets[None, :] / gaps  # (time - t_j)/(t_i - t_j) for j != i
    np.fill_diagonal(factors, 1.0)
    weights = np.prod(factors, axis=1)  # (k,) the Lagrange basis at ``time``
    return np.tensordot(weights, values, axes=1)


def _skew(vector: np.ndarray) -> np.ndarray:
    """(3, 3) the matrix of ``vector × ·``."""
    x, y, z = vector
    return np.array([[0.0, -z, y], [z, 0.0, -x], [-y, x, 0.0]])


def inverse_left_jacobian(rotation_vector: np.ndarray) -> np.ndarray:
    """(3, 3) ``J⁻¹(φ)`` of the rotation group: ``d/dt φ = J⁻¹(φ) ω`` for ``R = exp(φ) R0``
    and the world-frame angular velocity ω of R (Barfoot, State Estimation for Robotics, 7.1)."""
    angle = float(np.linalg.norm(rotation_vector))
    cross = _skew(rotation_vector)
    if angle < SMALL_ANGLE:
        coefficient = 1.0 / 12.0
    else:
        half = 0.5 * angle
        coefficient = (1.0 - half / np.tan(half)) / angle**2
    return np.eye(3) - 0.5 * cross + coefficient * cross @ cross


def hermite_orientation(
    time: float, t: np.ndarray, quat: np.ndarray, ang_vel: np.ndarray
) -> np.ndarray:
    """(4,) unit quaternion w x y z at ``time`` from the two observed states ``t (2,)`` s,
    ``quat (2, 4)`` w x y z and ``ang_vel (2, 3)`` rad/s world frame around it: the Hermite on
    the rotation group (module docstring)."""
    start = Rotation.from_quat(quat[0], scalar_first=True)
    turn = rotation_vector_between(quat[0], quat[1])  # world frame, the shorter way
    rates = np.stack([ang_vel[0], inverse_left_jacobian(turn) @ ang_vel[1]])
    path = CubicHermiteSpline(t, np.stack([np.zeros(3), turn]), rates, axis=0)
    return (Rotation.from_rotvec(path(time)) * start).as_quat(scalar_first=True)


def rotation_vector_between(start: np.ndarray, end: np.ndarray) -> np.ndarray:
    """(3,) rad, world frame: the rotation vector ``log(q_end q_start⁻¹)`` of the rotation
    taking orientation ``start (4,)`` to ``end (4,)`` (w x y z), the shorter way; its norm is
    the angle between the two."""
    start_rot = Rotation.from_quat(start, scalar_first=True)
    return (Rotation.from_quat(end, scalar_first=True) * start_rot.inv()).as_rotvec()


INTERPOLANTS: dict[str, tuple[tuple[str, ...], int, Callable[..., np.ndarray]]] = {
    "pos": (("pos", "vel"), 1, hermite_position),
    "quat": (("quat", "ang_vel"), 1, hermite_orientation),
    "vel": (("vel",), 2, cubic_through),
    "ang_vel": (("ang_vel",), 2, cubic_through),
    "energy": (("energy",), 2, cubic_through),
    "coordinate": (("coordinate",), 2, cubic_through),
}
"""Quantity -> (the observed arrays its interpolant takes, how many states it uses on each side
of the time, the interpolant ``f(time, t, *arrays)``)."""
