"""A reference motion independent of every engine: the Newton–Euler equations integrated by
SciPy's DOP853 (8th order, adaptive) at a tight tolerance.

For scenes where nothing can touch, the motion of each body is

    dx/dt = v,   dv/dt = g + F/m,   dq/dt = ½ (0, ω) ⊗ q,   dL/dt = τ,   ω = R I⁻¹ Rᵀ L

(world frame: ``L`` is the body's angular momentum about its centre of mass, so the
gyroscopic term is exact, not an option), with ``F`` and ``τ`` the scene's springs and constant
applied loads (the one load law, ``mini_engine.forces.applied_loads``, evaluated on the
continuous state; it is a force law, not a discretization). No step of any engine is involved; the error control
keeps the reference many orders of magnitude below the first-order errors it measures.
"""

from __future__ import annotations

import numpy as np
from scipy.integrate import solve_ivp

from mini_engine.forces import applied_loads
from mini_engine.model import State
from mini_engine.rotation import quat_multiply, quat_to_matrix
from validation.engines.base import Trajectory
from validation.scenario.compiled import CompiledScene

RELATIVE_TOLERANCE = 1e-12
"""DOP853's rtol: the issue's choice, 9+ orders below the 1e-3..1e-5 errors a sweep measures."""

ABSOLUTE_TOLERANCE = 1e-14
"""DOP853's atol in the state's SI units (m, m/s, kg·m²/s): round-off level for the library's
metre-sized scenes; components near zero are then controlled relatively by their neighbours."""


def _unpack(y: np.ndarray, n: int) -> tuple[np.ndarray, ...]:
    pos, quat, vel, momentum = np.split(y, [3 * n, 7 * n, 10 * n])
    return pos.reshape(n, 3), quat.reshape(n, 4), vel.reshape(n, 3), momentum.reshape(n, 3)


def _omega(scene: CompiledScene, quat: np.ndarray, momentum: np.ndarray) -> np.ndarray:
    """(n, 3) rad/s world frame: ω = R I⁻¹ Rᵀ L (zero for fixed bodies)."""
    rot = quat_to_matrix(quat / np.linalg.norm(quat, axis=1, keepdims=True))
    body = np.einsum("nji,nj->ni", rot, momentum)
    inverse = np.linalg.inv(scene.inertia)
    omega = np.einsum("nij,nj->ni", rot, np.einsum("nij,nj->ni", inverse, body))
    return np.where(scene.moving[:, None], omega, 0.0)


def reference_motion(scene: CompiledScene, times: np.ndarray) -> Trajectory:
    """The scene's bodies at ``times`` (s) by DOP853 on the Newton–Euler equations (module
    docstring). Only for scenes where nothing can touch."""
    n = scene.count
    initial = scene.initial
    rot0 = quat_to_matrix(initial.quat[:n])
    inertia_world = rot0 @ scene.inertia @ rot0.transpose(0, 2, 1)
    momentum0 = np.einsum("nij,nj->ni", inertia_world, initial.ang_vel[:n])
    y0 = np.concatenate(
        [
            initial.pos[:n].ravel(),
            initial.quat[:n].ravel(),
            initial.vel[:n].ravel(),
            momentum0.ravel(),
        ]
    )
    gravity = np.where(scene.moving[:, None], scene.gravity, 0.0)
    mass = np.where(scene.moving, scene.mass, 1.0)
    rest = initial

    def derivative(_t: float, y: np.ndarray) -> np.ndarray:
        pos, quat, vel, momentum = _unpack(y, n)
        omega = _omega(scene, quat, momentum)
        accel, torque = gravity + scene.force / mass[:, None], scene.torque
        if scene.model.n_springs:
            state = State(
                pos=np.concatenate([pos, rest.pos[n:]]),
                quat=np.concatenate(
                    [quat / np.linalg.norm(quat, axis=1, keepdims=True), rest.quat[n:]]
                ),
                vel=np.concatenate([vel, rest.vel[n:]]),
                ang_vel=np.concatenate([omega, rest.ang_vel[n:]]),
            )
            force, moment = applied_loads(scene.model, state, quat_to_matrix(state.quat))
            accel = gravity + np.where(scene.moving[:, None], force[:n] / mass[:, None], 0.0)
            torque = np.where(scene.moving[:, None], moment[:n], 0.0)
        spin = np.concatenate([np.zeros((n, 1)), omega], axis=1)
        dquat = 0.5 * quat_multiply(spin, quat)
        moving = scene.moving[:, None]
        return np.concatenate(
            [
                np.where(moving, vel, 0.0).ravel(),
                np.where(moving, dquat, 0.0).ravel(),
                accel.ravel(),
                torque.ravel(),
            ]
        )

    solution = solve_ivp(
        derivative,
        (0.0, float(times[-1])),
        y0,
        method="DOP853",
        t_eval=times,
        rtol=RELATIVE_TOLERANCE,
        atol=ABSOLUTE_TOLERANCE,
    )
    if not solution.success:
        raise RuntimeError(f"DOP853 failed: {solution.message}")
    states = solution.y.T
    pos = np.stack([_unpack(s, n)[0] for s in states])
    quat = np.stack([_unpack(s, n)[1] for s in states])
    quat /= np.linalg.norm(quat, axis=2, keepdims=True)
    vel = np.stack([_unpack(s, n)[2] for s in states])
    omega = np.stack(
        [_omega(scene, q, m) for q, m in ((_unpack(s, n)[1], _unpack(s, n)[3]) for s in states)]
    )
    return Trajectory(solution.t, pos, quat, vel, omega)


def rotation_angle(quat: np.ndarray, reference: np.ndarray) -> np.ndarray:
    """(...) rad, the angle of the rotation between two orientations ``(..., 4)`` w x y z,
    |log(R_refᵀ R)|, in [0, π] whatever the quaternions' signs."""
    conjugate = reference * np.array([1.0, -1.0, -1.0, -1.0])
    relative = quat_multiply(conjugate.reshape(-1, 4), quat.reshape(-1, 4)).reshape(quat.shape)
    vector = np.linalg.norm(relative[..., 1:], axis=-1)
    return 2.0 * np.arctan2(vector, np.abs(relative[..., 0]))
