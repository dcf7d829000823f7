"""A reference motion independent of every engine: the Newton–Euler equations integrated by
SciPy's DOP853 (8th order, adaptive) at a tight tolerance.

For scenes where nothing can touch, the motion of each body is

    dx/dt = v,   dv/dt = g + F/m,   dq/dt = ½ (0, ω) ⊗ q,   dL/dt = τ,   ω = R I⁻¹ Rᵀ L

(world frame: ``L`` is the body's angular momentum about its centre of mass, so the
gyroscopic term is exact, not an option), with ``F`` and ``τ`` the scene's springs and
constant applied loads. Every law and formula is the reference side's own
(``validation.reference.loads``, ``validation.reference.rotation``, the inertias the scene
compiled from ``validation.reference.mass_properties``), evaluated on the continuous state;
nothing of mini_engine, the engine under test, and no step of any engine is involved. The
error control keeps the reference many orders of magnitude below the first-order errors it
measures.
"""

from __future__ import annotations

from collections import OrderedDict
from typing import Protocol

import numpy as np
from scipy.integrate import OdeSolution, solve_ivp

from validation.reference.articulated import (
    JointTree,
    Loads,
    body_states,
    initial_velocities,
    joint_space_solution,
)
from validation.reference.loads import Springs, applied_loads
from validation.reference.motion import Motion
from validation.reference.rotation import norm, quat_multiply, quat_to_matrix

RELATIVE_TOLERANCE = 3e-14
"""DOP853's rtol, near the smallest SciPy accepts (100 machine epsilons, 2.2e-14). Near a
separatrix the reference is only as good as this: on the Dzhanibekov box (10 s, m = 0.9999953)
rtol 1e-12 left 2.8e-7 rad of orientation error and 1e-13 left 1.7e-8 (both against this
setting), which is where RK4's sweep curves would otherwise floor; the cost is 1.7x rtol
1e-12's (2.1 s against 1.3 s for 10 s of that box)."""

ABSOLUTE_TOLERANCE = 1e-16
"""DOP853's atol in the state's SI units (m, m/s, kg·m²/s): round-off level for the library's
metre-sized scenes (rtol times a state of order 1e-2); components near zero are then controlled
relatively by their neighbours."""


DENSE_OUTPUT_MAX_BODIES = 8
"""Scenes of at most this many bodies keep DOP853's dense output, so one integration serves every
set of sample times that ends at the same time (a sweep's points and engines, its cross-check).
A step's interpolant holds 8 states of 13 n numbers: 6.7 KB at 8 bodies, 13 MB for the
library's longest such integration (2,000 steps); larger scenes are integrated per call."""

END_DIGITS = 9
"""Significant digits of a sampled end time that name its integration: engines that add up dt
end a 0.2 s scene at 0.19999999999998613 or 0.20000000000012963 s, and all of them are
sampled from one integration."""

END_MARGIN = 1e-8
"""Relative: an integration named by an end time runs this much past it, beyond every end time
that rounds to it (half a unit in the ninth digit is at most 5e-9 of it)."""

CACHED_INTEGRATIONS = 8
"""Integrations a process keeps (least recently used dropped first): a worker meets a few
scenes at a time, each with one end time per sweep."""

_integrations: OrderedDict[tuple, OdeSolution] = OrderedDict()
"""(scene fingerprint, end time) -> DOP853's dense output from 0 to the end time."""


class RigidBodyScene(Protocol):
    """What the reference reads of a scene (``validation.scenario.compiled.CompiledScene`` is
    one), all stated by the scene itself: ``count`` n bodies; ``moving (n,)`` bool;
    ``mass (n,)`` kg; ``inertia (n, 3, 3)`` kg·m², body frame; ``gravity (3,)`` m/s²;
    ``force (n, 3)`` N and ``torque (n, 3)`` N·m, world frame, constant; ``springs``; and
    ``start``, the bodies at t = 0 (one state)."""

    count: int
    moving: np.ndarray
    mass: np.ndarray
    inertia: np.ndarray
    gravity: np.ndarray
    force: np.ndarray
    torque: np.ndarray
    springs: Springs
    start: Motion


def _unpack(y: np.ndarray, n: int) -> tuple[np.ndarray, ...]:
    """``pos (..., n, 3)``, ``quat (..., n, 4)``, ``vel (..., n, 3)``, ``momentum (..., n,
    3)`` of flat integrator states ``y (..., 13 n)``."""
    pos, quat, vel, momentum = (
        y[..., : 3 * n],
        y[..., 3 * n : 7 * n],
        y[..., 7 * n : 10 * n],
        y[..., 10 * n :],
    )  # the views np.split makes, without its Python layer
    lead = y.shape[:-1]
    return (
        pos.reshape(*lead, n, 3),
        quat.reshape(*lead, n, 4),
        vel.reshape(*lead, n, 3),
        momentum.reshape(*lead, n, 3),
    )


def _unit(quat: np.ndarray) -> np.ndarray:
    """(..., 4) the quaternions ``quat (..., 4)`` scaled to unit length."""
    return quat / norm(quat, keepdims=True)


def _omega(
    moving: np.ndarray, inverse_inertia: np.ndarray, rot: np.ndarray, momentum: np.ndarray
) -> np.ndarray:
    """(..., n, 3) rad/s world frame: ω = R I⁻¹ Rᵀ L, zero for the bodies not ``moving
    (n,)``, from ``inverse_inertia (n, 3, 3)`` 1/(kg·m²) body frame, the rotations ``rot
    (..., n, 3, 3)`` and the angular momenta ``momentum (..., n, 3)`` kg·m²/s."""
    body = np.einsum("...nji,...nj->...ni", rot, momentum)
    spin = np.einsum("nij,...nj->...ni", inverse_inertia, body)
    omega = np.einsum("...nij,...nj->...ni", rot, spin)
    return np.where(moving[:, None], omega, 0.0)


def _initial_state(scene: RigidBodyScene) -> np.ndarray:
    """(13 n,) the scene's start as the integrator's flat state: positions, quaternions,
    velocities and angular momenta ``L = R I Rᵀ ω``."""
    start = scene.start
    rot = quat_to_matrix(start.quat[0])
    inertia_world = rot @ scene.inertia @ rot.transpose(0, 2, 1)
    momentum = np.einsum("nij,nj->ni", inertia_world, start.ang_vel[0])
    return np.concatenate(
        [start.pos[0].ravel(), start.quat[0].ravel(), start.vel[0].ravel(), momentum.ravel()]
    )


def reference_motion(scene: RigidBodyScene, times: np.ndarray) -> Motion:
    """The scene's bodies at ``times`` (s, ascending) by DOP853 on the Newton–Euler equations
    (module docstring). Only for scenes where nothing can touch.

    A small scene's integration is kept and sampled from its dense output (DOP853's own
    interpolant, the one SciPy samples ``t_eval`` from) for every ``times`` whose end rounds to
    the same ``END_DIGITS`` digits. It runs ``END_MARGIN`` past that end, so the numbers depend
    only on the scene and the rounded end, whichever process or order asks."""
    n = scene.count
    end = float(times[-1])
    tree = getattr(scene, "joint_tree", None)
    if tree is not None:
        return _joint_space_motion(scene, tree, np.asarray(times, dtype=float))
    if n > DENSE_OUTPUT_MAX_BODIES:
        states = _integrate(scene, end, times=times).y
    else:
        states = _dense_output(scene, end)(times)
    pos, quat, vel, momentum = _unpack(np.asarray(states).T, n)
    inverse_inertia = np.linalg.inv(scene.inertia)
    quat = _unit(quat)
    omega = _omega(scene.moving, inverse_inertia, quat_to_matrix(quat), momentum)
    return Motion(np.asarray(times, dtype=float), pos, quat, vel, omega)


def _joint_space_motion(scene: RigidBodyScene, tree: JointTree, times: np.ndarray) -> Motion:
    """A scene with joints: DOP853 in the joint tree's coordinates
    (``articulated.joint_space_solution``: the Lagrange equations of the tree, every body
    kept on its joints exactly), from the stated poses (q = 0) and the joint rates the stated
    velocities give (``articulated.initial_velocities``), sampled from its dense output like a
    free scene's."""
    start = scene.start
    loads = Loads(scene.gravity, scene.springs, scene.force, scene.torque)
    nu0, _ = initial_velocities(tree, start.vel[0], start.ang_vel[0])

    def integrate(end: float) -> OdeSolution:
        return joint_space_solution(tree, tree.zero(), nu0, loads, end).sol

    solution = _dense_output(scene, float(times[-1]), integrate, _tree_fingerprint(tree))
    return body_states(tree, times, np.asarray(solution(times)).T)


def _tree_fingerprint(tree: JointTree) -> tuple:
    """Everything of the joint tree the joint-space integration reads, as bytes."""
    placed = ("anchor", "axis", "offset", "rotation")
    return tuple(
        (
            joint.type,
            joint.parent,
            joint.child,
            joint.damping,
            *(np.ascontiguousarray(getattr(joint, name)).tobytes() for name in placed),
        )
        for joint in tree.joints
    )


def _dense_output(
    scene: RigidBodyScene, end: float, integrate=None, extra: tuple = ()
) -> OdeSolution:
    """DOP853's dense output of the scene from 0 past ``end`` s (``reference_motion``),
    integrated once per process (``integrate(end)``: the Newton-Euler equations by default,
    the joint-space ones for a tree, whose ``extra`` fingerprint joins the key)."""
    named_end = float(f"{end:.{END_DIGITS}g}")
    key = (_fingerprint(scene), *extra, named_end)
    if key in _integrations:
        _integrations.move_to_end(key)
        return _integrations[key]
    if integrate is None:
        solution = _integrate(scene, named_end * (1.0 + END_MARGIN), times=None).sol
    else:
        solution = integrate(named_end * (1.0 + END_MARGIN))
    _integrations[key] = solution
    while len(_integrations) > CACHED_INTEGRATIONS:
        _integrations.popitem(last=False)
    return solution


def _fingerprint(scene: RigidBodyScene) -> tuple:
    """Everything the integration reads of ``scene``, as bytes: equal fingerprints, equal motions."""
    springs = scene.springs
    start = scene.start
    arrays = (
        scene.moving, scene.mass, scene.inertia, scene.gravity, scene.force, scene.torque,
        springs.body_a, springs.body_b, springs.anchor_a, springs.anchor_b, springs.stiffness,
        springs.damping, springs.rest_length,
        start.pos[0], start.quat[0], start.vel[0], start.ang_vel[0],
    )  # fmt: skip
    return (scene.count, *(np.ascontiguousarray(a).tobytes() for a in arrays))


def _integrate(scene: RigidBodyScene, end: float, times: np.ndarray | None):
    """SciPy's solution of the scene from 0 to ``end`` s: sampled at ``times``, or (None) with
    its dense output."""
    n = scene.count
    moving = scene.moving[:, None]
    gravity = np.where(moving, scene.gravity, 0.0)
    mass = np.where(scene.moving, scene.mass, 1.0)[:, None]  # 1 kg for fixed: no 0/0
    inverse_inertia = np.linalg.inv(scene.inertia)

    def derivative(_t: float, y: np.ndarray) -> np.ndarray:
        pos, quat, vel, momentum = _unpack(y, n)
        rot = quat_to_matrix(_unit(quat))
        omega = _omega(scene.moving, inverse_inertia, rot, momentum)
        loads = (scene.springs, scene.moving, scene.force, scene.torque)
        force, torque = applied_loads(*loads, pos, rot, vel, omega)
        spin = np.concatenate([np.zeros((n, 1)), omega], axis=1)
        dquat = 0.5 * quat_multiply(spin, quat)
        return np.concatenate(
            [
                np.where(moving, vel, 0.0).ravel(),
                np.where(moving, dquat, 0.0).ravel(),
                (gravity + force / mass).ravel(),
                torque.ravel(),
            ]
        )

    solution = solve_ivp(
        derivative,
        (0.0, end),
        _initial_state(scene),
        method="DOP853",
        t_eval=times,
        dense_output=times is None,
        rtol=RELATIVE_TOLERANCE,
        atol=ABSOLUTE_TOLERANCE,
    )
    if not solution.success:
        raise RuntimeError(f"DOP853 failed: {solution.message}")
    return solution
