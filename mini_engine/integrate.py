"""Time integration: velocities from forces and torques, positions and orientations from velocities.

The documented update (formulas.md section 2), batched over bodies:

    v ← v + a dt                    a = g + F / m
    ω ← ω + α dt                    α = I_world⁻¹ τ,   I_world⁻¹ = R I_body⁻¹ Rᵀ

and then, for ``semi_implicit_euler``, ``x ← x + v_new dt``; for
``explicit_euler``, ``x ← x + v_old dt``. The orientation follows the rule named
by ``Settings.orientation_update``; the gyroscopic term the rule named by
``Settings.gyroscopic``. Each rule is a function in a registry.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import NamedTuple

import numpy as np

from mini_engine.rotation import (
    apply,
    apply_transpose,
    cross,
    quat_multiply,
    quat_normalize,
    rotation_quat,
)


def integrate_linear_velocity(vel: np.ndarray, lin_acc: np.ndarray, dt: float) -> np.ndarray:
    """New velocities (n, 3) m/s, world frame: ``v + a dt`` for accelerations ``lin_acc (n, 3)`` m/s²."""
    return vel + lin_acc * dt


# --- angular velocity: the gyroscopic rules ---------------------------------------------

BodySelection = slice | np.ndarray
"""Bodies a phase acts on: ``(k,)`` int indices, or ``slice(None)`` for every body (a view,
no gather/scatter copies; ``workspace.Workspace`` picks it when the set is complete)."""


class BodyInertia(NamedTuple):
    """Body-frame inertia of the bodies a gyroscopic rule acts on (g bodies), gathered once
    per model (``workspace.Workspace.gyroscopic_inertia``).

    Attributes:
        tensor, inv_tensor: (g, 3, 3) kg·m² and 1/(kg·m²), body frame.
        diagonal, inv_diagonal: (g, 3) the tensors' diagonals when every off-diagonal entry
            is exactly 0 (body axes are principal axes, as for every solid shape), else None.
            Then ``I ω`` is ``diagonal * ω``: the tensor product's terms without its exact
            zeros, so the same value for finite ω (a zero result may differ in sign).
    """

    tensor: np.ndarray
    inv_tensor: np.ndarray
    diagonal: np.ndarray | None
    inv_diagonal: np.ndarray | None


def body_inertia(
    inertia_body: np.ndarray, inv_inertia_body: np.ndarray, bodies: BodySelection
) -> BodyInertia:
    """The ``BodyInertia`` of ``bodies`` from ``(n, 3, 3)`` body-frame tensors and inverses."""
    tensor, inv_tensor = inertia_body[bodies], inv_inertia_body[bodies]
    off_diagonal = ~np.eye(3, dtype=bool)
    if tensor[:, off_diagonal].any() or inv_tensor[:, off_diagonal].any():
        return BodyInertia(tensor, inv_tensor, None, None)
    diagonal = np.diagonal(tensor, axis1=1, axis2=2).copy()
    return BodyInertia(
        tensor, inv_tensor, diagonal, np.diagonal(inv_tensor, axis1=1, axis2=2).copy()
    )


GyroscopicRule = Callable[[np.ndarray, np.ndarray, BodyInertia, BodySelection, float], None]
"""``rule(ang_vel, rot, inertia, bodies, dt)`` updates ``ang_vel[bodies]`` in place for the
torque-free motion ω̇ = -I⁻¹(ω × Iω) over one step; ``inertia`` is that of ``bodies``."""


def _is_empty(bodies: BodySelection) -> bool:
    return isinstance(bodies, np.ndarray) and bodies.size == 0


def _gyroscopic_none(ang_vel, rot, inertia, bodies, dt) -> None:
    """The documented law α = I⁻¹τ drops ω × Iω: torque-free bodies keep ω (not L)."""


def _gyroscopic_explicit(ang_vel, rot, inertia: BodyInertia, bodies, dt) -> None:
    """Explicit Euler on the gyroscopic term, in the body frame:
    ``ω_b ← ω_b - dt I⁻¹ (ω_b × I ω_b)``. Gains energy by O(dt) (MuJoCo Euler, Bullet multibody)."""
    if _is_empty(bodies):
        return
    R = rot[bodies]
    omega_body = apply_transpose(R, ang_vel[bodies])
    if inertia.diagonal is None:
        momentum_body = apply(inertia.tensor, omega_body)
        omega_body -= dt * apply(inertia.inv_tensor, cross(omega_body, momentum_body))
    else:  # principal body axes: (g, 3) products instead of (g, 3, 3) ones
        momentum_body = inertia.diagonal * omega_body
        omega_body -= dt * (inertia.inv_diagonal * cross(omega_body, momentum_body))
    ang_vel[bodies] = apply(R, omega_body)


def _gyroscopic_implicit(ang_vel, rot, inertia: BodyInertia, bodies, dt) -> None:
    """One Newton step on ``f(ω') = I (ω' - ω) + dt ω' × I ω' = 0`` in the body frame.

    Starting from ω' = ω, the step is ``ω' = ω - J⁻¹ f(ω)`` with
    ``J = I + dt (skew(ω) I - skew(I ω))`` (Bullet's ``computeGyroscopicImpulseImplicit_Body``,
    Catto GDC 2015). Dissipates energy by O(dt²) per step (MuJoCo implicit, Bullet rigid body).
    """
    if _is_empty(bodies):
        return
    R = rot[bodies]
    tensor = inertia.tensor
    omega_body = apply_transpose(R, ang_vel[bodies])
    momentum_body = apply(tensor, omega_body)
    residual = dt * cross(omega_body, momentum_body)
    jacobian = tensor + dt * (skew(omega_body) @ tensor - skew(momentum_body))
    omega_body -= np.linalg.solve(jacobian, residual[:, :, None])[:, :, 0]
    ang_vel[bodies] = apply(R, omega_body)


GYROSCOPIC_RULES: dict[str, GyroscopicRule] = {
    "none": _gyroscopic_none,
    "explicit": _gyroscopic_explicit,
    "implicit": _gyroscopic_implicit,
}


def skew(v: np.ndarray) -> np.ndarray:
    """Cross-product matrices (n, 3, 3) with ``skew(v) @ u = v × u`` for ``v (n, 3)``."""
    out = np.zeros((v.shape[0], 3, 3))
    out[:, 0, 1], out[:, 0, 2] = -v[:, 2], v[:, 1]
    out[:, 1, 0], out[:, 1, 2] = v[:, 2], -v[:, 0]
    out[:, 2, 0], out[:, 2, 1] = -v[:, 1], v[:, 0]
    return out


def integrate_angular_velocity(
    ang_vel: np.ndarray,
    torque: np.ndarray,
    inv_inertia_world: np.ndarray,
    rot: np.ndarray,
    gyroscopic_inertia: BodyInertia,
    gyroscopic_bodies: BodySelection,
    gyroscopic: str,
    dt: float,
    any_torque: bool = True,
) -> np.ndarray:
    """New angular velocities (n, 3) rad/s, world frame.

    The gyroscopic rule acts first on the bodies that have one (anisotropic, dynamic);
    then the documented ``ω ← ω + I_world⁻¹ τ dt`` for torques ``torque (n, 3)`` N·m.

    Args:
        inv_inertia_world: (n, 3, 3) ``R I⁻¹ Rᵀ`` at the start of the step.
        rot: (n, 3, 3) body-to-world rotations at the start of the step.
        gyroscopic_inertia: the body-frame inertia of ``gyroscopic_bodies``.
        gyroscopic_bodies: (g,) int or ``slice(None)``, the bodies whose ω × Iω can be non-zero.
        any_torque: False when ``torque`` is known to be all zero (the torque update is skipped).
    """
    new = ang_vel.copy()
    GYROSCOPIC_RULES[gyroscopic](new, rot, gyroscopic_inertia, gyroscopic_bodies, dt)
    if not any_torque:
        return new
    torqued = np.flatnonzero(np.any(torque != 0.0, axis=1))
    if torqued.size:
        new[torqued] += apply(inv_inertia_world[torqued], torque[torqued]) * dt
    return new


# --- orientation: the update rules --------------------------------------------------------


def _orientation_exponential_map(quat: np.ndarray, ang_vel: np.ndarray, dt: float) -> np.ndarray:
    """``q ← exp(½ dt ω) ⊗ q``: the exact rotation by ω dt for constant world-frame ω."""
    return quat_normalize(quat_multiply(rotation_quat(ang_vel * dt), quat))


def _orientation_linearized(quat: np.ndarray, ang_vel: np.ndarray, dt: float) -> np.ndarray:
    """``q ← normalize(q + ½ dt [0, ω] ⊗ q)``: first order (qu3e, Baraff's notes)."""
    omega_quat = np.concatenate([np.zeros((ang_vel.shape[0], 1)), ang_vel], axis=1)
    return quat_normalize(quat + 0.5 * dt * quat_multiply(omega_quat, quat))


ORIENTATION_RULES: dict[str, Callable[[np.ndarray, np.ndarray, float], np.ndarray]] = {
    "exponential_map": _orientation_exponential_map,
    "linearized": _orientation_linearized,
}


def integrate_pose(
    pos: np.ndarray,
    quat: np.ndarray,
    vel: np.ndarray,
    ang_vel: np.ndarray,
    moving: slice | np.ndarray,
    orientation_update: str,
    dt: float,
) -> tuple[np.ndarray, np.ndarray]:
    """New positions (n, 3) m and orientations (n, 4) w x y z from velocities held over ``dt``.

    ``vel``/``ang_vel`` are the velocities the integrator uses for the position update
    (the new ones for semi-implicit Euler, the old ones for explicit Euler).
    ``moving`` (``(n,) bool``, or ``slice(None)`` when every body moves) marks the bodies
    that can move; the others keep their pose exactly.
    """
    rule = ORIENTATION_RULES[orientation_update]
    if isinstance(moving, slice):  # every body moves: whole-array updates
        new_pos = pos + vel * dt
    else:
        new_pos = np.add(pos, vel * dt, out=pos.copy(), where=moving[:, None])
    if not np.count_nonzero(ang_vel):  # nothing turns (bodies at rest or sliding)
        return new_pos, quat.copy()
    nonzero = ang_vel != 0.0
    turning = nonzero[:, 0] | nonzero[:, 1] | nonzero[:, 2]  # .any(axis=1), 3 whole-array ops
    if not isinstance(moving, slice):
        turning &= moving
    spinning = turning.nonzero()[0]
    if spinning.size == turning.size:  # every body turns: no gathers
        return new_pos, rule(quat, ang_vel, dt)
    new_quat = quat.copy()
    if spinning.size:
        new_quat[spinning] = rule(quat.take(spinning, axis=0), ang_vel.take(spinning, axis=0), dt)
    return new_pos, new_quat
