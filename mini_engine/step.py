"""One time step of the engine, phase by phase (Box2D-Lite's ``World::Step`` order).

Phases a scene does not need are skipped: no collision work when nothing can
touch, no inverse-inertia work without torques or contacts, no gyroscopic
work for isotropic bodies, nothing at all for fixed bodies.
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np

from mini_engine.collision import detect_contacts
from mini_engine.contacts import Contacts
from mini_engine.forces import applied_loads, linear_acceleration
from mini_engine.integrate import (
    integrate_angular_velocity,
    integrate_linear_velocity,
    integrate_pose,
)
from mini_engine.joints import solve_joints
from mini_engine.model import Model, State
from mini_engine.rotation import (
    quat_multiply,
    quat_normalize,
    quat_to_matrix,
    rotation_quat,
    world_inertia,
)
from mini_engine.settings import Settings
from mini_engine.solver import ContactReport, solve_contacts
from mini_engine.workspace import workspace

DEFAULT_SETTINGS = Settings()


class StepResult(NamedTuple):
    """The state after one step and what happened at the contacts during it."""

    state: State
    contacts: ContactReport


POSE_VELOCITY = {
    "semi_implicit_euler": lambda old, new: new,
    "explicit_euler": lambda old, new: old,
}
"""Which velocities move the pose: the new ones (semi-implicit) or the old ones (explicit)."""


def step(model: Model, state: State, settings: Settings = DEFAULT_SETTINGS) -> StepResult:
    """Advance ``state`` by ``settings.dt``; returns the new state and the contact report."""
    dt = settings.dt
    work = workspace(model)  # the model's index sets and constant loads, built once
    rot = _rotations(work, state.quat)  # orientations as matrices, once per step

    # 1. collision detection at the start-of-step poses (broad phase, then narrow phase)
    contacts = (
        _contacts(work, model, state.pos, rot, settings) if model.can_touch else Contacts.empty()
    )
    # 2. applied loads at the start-of-step state: gravity, spring-dampers, constant loads
    #    (without springs they do not depend on the state: the workspace holds them)
    if work.has_springs:
        force, torque = applied_loads(model, state, rot)
        lin_acc = linear_acceleration(model, force)
        any_torque = bool(np.any(torque != 0.0))
    else:
        lin_acc, torque, any_torque = work.constant_lin_acc, work.constant_torque, work.any_torque
    # 3. world inverse inertia R I⁻¹ Rᵀ, only where a torque or an impulse will use it
    needs_inertia = contacts.count > 0 or any_torque or model.joints is not None
    inv_inertia_world = _world_inverse_inertia(work, model, rot) if needs_inertia else None
    # 4. integrate velocities: v += a dt; ω per the gyroscopic rule, then ω += I⁻¹τ dt
    vel = integrate_linear_velocity(state.vel, lin_acc, dt)
    ang_vel = integrate_angular_velocity(
        state.ang_vel,
        torque,
        inv_inertia_world,
        rot,
        work.gyroscopic_inertia,
        work.gyroscopic_selection,
        settings.gyroscopic,
        dt,
        any_torque,
    )
    # 4b. joint impulses (the documented impulse with e = 0 along each constrained direction,
    #     mini_engine.joints: a named extension), before the contacts
    if model.joints is not None:
        vel, ang_vel = solve_joints(
            model.joints, state.pos, rot, state.quat, model.body_inv_mass, inv_inertia_world,
            vel, ang_vel, dt,
        )  # fmt: skip
    # 5. contact impulses (sequential impulses with restitution; friction if any μ > 0)
    solution = solve_contacts(
        model, contacts, state.pos, inv_inertia_world, vel, ang_vel, settings, state.contact_memory
    )
    vel, ang_vel = solution.vel, solution.ang_vel
    # 6. integrate positions with the velocities the integrator names
    choose = POSE_VELOCITY[settings.integrator]
    pos, quat = integrate_pose(
        state.pos,
        state.quat,
        choose(state.vel, vel),
        choose(state.ang_vel, ang_vel),
        work.moving_selection,
        settings.orientation_update,
        dt,
    )
    # 7. split-impulse position correction (pose only, velocities untouched)
    if solution.pseudo_twist is not None:
        pos, quat = _apply_pseudo_twist(pos, quat, solution.pseudo_twist, dt)
    memory = solution.report if solution.report.contacts.count else None
    return StepResult(State(pos, quat, vel, ang_vel, state.time + dt, memory), solution.report)


def _rotations(work, quat: np.ndarray) -> np.ndarray:
    """Rotation matrices (n, 3, 3) of ``quat (n, 4)``, read-only; the last step's when the
    orientations are bit-for-bit those of the last step (their bytes compare equal: resting
    or non-spinning bodies, a body on the ground), so the same matrices are not rebuilt."""
    cache = work.rotation_cache
    quat_bits = quat.tobytes()  # bit-for-bit comparison: a byte string equality
    if cache.get("quat_shape") == quat.shape and cache.get("quat_bits") == quat_bits:
        return cache["rot"]
    rot = quat_to_matrix(quat)
    rot.flags.writeable = False
    cache.update(quat_shape=quat.shape, quat_bits=quat_bits, rot=rot)
    return rot


def _contacts(work, model: Model, pos: np.ndarray, rot: np.ndarray, settings: Settings) -> Contacts:
    """The contacts of ``detect_contacts`` at positions ``pos (n, 3)`` and the rotations ``rot``
    of ``_rotations``, read-only; the last step's when ``pos`` is bit-for-bit the last step's,
    ``rot`` the cached matrices and the margins the same (a body resting on the ground): the
    contacts depend on nothing else, so the same contacts are not detected again."""
    cache = work.contact_cache
    key = (pos.shape, pos.tobytes(), settings.contact_margin, settings.broadphase_padding)
    if cache.get("rot") is rot and cache.get("key") == key:
        return cache["contacts"]
    contacts = detect_contacts(
        model, pos, rot, settings.contact_margin, settings.broadphase_padding
    )
    for array in contacts:
        array.flags.writeable = False
    cache.update(rot=rot, key=key, contacts=contacts)
    return contacts


def _world_inverse_inertia(work, model: Model, rot: np.ndarray) -> np.ndarray:
    """World inverse inertias ``R I⁻¹ Rᵀ`` (n, 3, 3) for the rotations ``rot`` of
    ``_rotations``, read-only; the cached ones while ``rot`` is the cached matrices."""
    cache = work.rotation_cache
    if cache.get("inertia_rot") is not rot:
        inv_inertia_world = world_inertia(rot, model.body_inv_inertia)
        inv_inertia_world.flags.writeable = False
        cache.update(inertia_rot=rot, inv_inertia_world=inv_inertia_world)
    return cache["inv_inertia_world"]


def _apply_pseudo_twist(pos, quat, pseudo_twist, dt) -> tuple[np.ndarray, np.ndarray]:
    """Move poses by split-impulse pseudo-velocities ``pseudo_twist (n, 6)`` over ``dt``."""
    moved = np.flatnonzero(np.any(pseudo_twist != 0.0, axis=1))
    if moved.size == 0:
        return pos, quat
    pos = pos.copy()
    quat = quat.copy()
    pos[moved] += pseudo_twist[moved, :3] * dt
    quat[moved] = quat_normalize(
        quat_multiply(rotation_quat(pseudo_twist[moved, 3:] * dt), quat[moved])
    )
    return pos, quat
