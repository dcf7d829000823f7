"""Applied forces: gravity, linear spring-dampers, and constant applied loads.

Gravity is returned as an acceleration (it does not pass through ``F / m``, so
free fall is exact to the last bit); springs and each body's constant applied force
and torque (world frame, the force at the centre of mass) as forces and torques about
each body's centre of mass. All are evaluated at the state at the start of the step,
which makes them explicit in time whatever the integrator.
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np

from mini_engine.model import WORLD_ANCHOR, Model, State, per_model
from mini_engine.rotation import apply, cross, norm

MIN_SPRING_LENGTH = 1e-12
"""m. Below this anchor distance the spring axis is undefined; the spring then
exerts no force (a zero-length spring at rest length 0 is in equilibrium anyway)."""


def gravity_acceleration(model: Model) -> np.ndarray:
    """Linear acceleration (n, 3) m/s², world frame, from gravity; zero for fixed bodies."""
    return np.where(model.body_fixed[:, None], 0.0, model.gravity[None, :])


def linear_acceleration(model: Model, force: np.ndarray) -> np.ndarray:
    """Linear acceleration (n, 3) m/s², world frame, of every body under gravity and the forces
    ``force (n, 3)`` N at the centres of mass: ``g + F/m`` (fixed bodies: ``F/m`` with their
    zero inverse mass, so zero). The one place where the law of motion of a centre of mass is
    written; every phase that needs it calls this."""
    return gravity_acceleration(model) + force * model.body_inv_mass[:, None]


def constant_loads(model: Model) -> tuple[np.ndarray, np.ndarray]:
    """Each body's constant applied force (n, 3) N and torque (n, 3) N·m, world frame, as new
    arrays (zero for fixed bodies: the model stores them so)."""
    n = model.n_bodies
    return np.zeros((n, 3)) + model.body_force, np.zeros((n, 3)) + model.body_torque


class SpringEnds(NamedTuple):
    """Which bodies the ``k`` springs of a model act on, derived once per model.

    Attributes:
        to_world: (k,) bool, end B is a fixed point of the world.
        any_to_world: ``to_world.any()``.
        body_b_or_any: (k,) int, end B's body, or body 0 for a world end (masked out).
        on_body: (k,) bool, ``~to_world``; body_b_on_body: its springs' B bodies.
        distinct_a, distinct_b: no two springs share a body at end A (at end B): each
            accumulation is then a plain gather-add, the same sums as ``np.add.at``'s.
        any_fixed: the model has a fixed body (whose loads are zeroed).
    """

    to_world: np.ndarray
    any_to_world: bool
    body_b_or_any: np.ndarray
    on_body: np.ndarray
    body_b_on_body: np.ndarray
    distinct_a: bool
    distinct_b: bool
    any_fixed: bool


@per_model
def spring_ends(model: Model) -> SpringEnds:
    """The ``SpringEnds`` of ``model`` (they depend on nothing else)."""
    a, b = model.spring_body_a, model.spring_body_b
    to_world = b == WORLD_ANCHOR
    on_body = ~to_world
    return SpringEnds(
        to_world=to_world,
        any_to_world=bool(to_world.any()),
        body_b_or_any=np.where(to_world, 0, b),
        on_body=on_body,
        body_b_on_body=b[on_body],
        distinct_a=np.unique(a).size == a.size,
        distinct_b=np.unique(b[on_body]).size == int(on_body.sum()),
        any_fixed=bool(model.body_fixed.any()),
    )


def _add_at(total: np.ndarray, rows: np.ndarray, values: np.ndarray, distinct: bool) -> None:
    """``total[rows] += values`` summing repeated rows one after another (``np.add.at``);
    for ``distinct`` rows a fancy-indexed add, the same sums without add.at's slow path."""
    if distinct:
        total[rows] += values
    else:
        np.add.at(total, rows, values)


def _where_world(ends: SpringEnds, world_value, body_value: np.ndarray) -> np.ndarray:
    """(k, 3) ``world_value`` for the springs whose end B is the world, else ``body_value``."""
    if not ends.any_to_world:
        return body_value
    return np.where(ends.to_world[:, None], world_value, body_value)


def spring_forces(model: Model, state: State, rot: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Forces (n, 3) N and torques (n, 3) N·m about each centre of mass, world frame, from springs.

    For a spring from anchor A (on body a) to anchor B (on body b or fixed in the world)
    with length L and unit axis u = (B - A) / L, the tension is
    ``f = k (L - rest) + c (v_B - v_A)·u``; body a feels ``+f u`` at A, body b ``-f u`` at B.

    Args:
        rot: (n, 3, 3) body-to-world rotations of ``state.quat``.
    """
    n = model.n_bodies
    force = np.zeros((n, 3))
    torque = np.zeros((n, 3))
    if model.n_springs == 0:
        return force, torque
    ends = spring_ends(model)
    a, b_safe = model.spring_body_a, ends.body_b_or_any

    arm_a = apply(rot[a], model.spring_anchor_a)
    arm_b = _where_world(ends, 0.0, apply(rot[b_safe], model.spring_anchor_b))
    point_a = state.pos[a] + arm_a
    point_b = _where_world(ends, model.spring_anchor_b, state.pos[b_safe] + arm_b)
    vel_a = state.vel[a] + cross(state.ang_vel[a], arm_a)
    vel_b = _where_world(ends, 0.0, state.vel[b_safe] + cross(state.ang_vel[b_safe], arm_b))

    offset = point_b - point_a
    length = norm(offset)
    axis = offset / np.maximum(length, MIN_SPRING_LENGTH)[:, None]
    axis[length < MIN_SPRING_LENGTH] = 0.0
    stretch_speed = np.sum((vel_b - vel_a) * axis, axis=1)
    tension = model.spring_stiffness * (length - model.spring_rest_length)
    tension += model.spring_damping * stretch_speed
    force_on_a = tension[:, None] * axis

    _add_at(force, a, force_on_a, ends.distinct_a)
    _add_at(torque, a, cross(arm_a, force_on_a), ends.distinct_a)
    on_body, b = ends.on_body, ends.body_b_on_body
    if b.size:
        _add_at(force, b, -force_on_a[on_body], ends.distinct_b)
        _add_at(torque, b, cross(arm_b[on_body], -force_on_a[on_body]), ends.distinct_b)
    if ends.any_fixed:
        force[model.body_fixed] = 0.0
        torque[model.body_fixed] = 0.0
    return force, torque


def applied_loads(model: Model, state: State, rot: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Forces (n, 3) N and torques (n, 3) N·m about each centre of mass, world frame: the
    springs' (``spring_forces``) plus each body's constant ``body_force`` and ``body_torque``
    (zero for fixed bodies). Gravity is not among them (``gravity_acceleration``)."""
    force, torque = spring_forces(model, state, rot)
    constant_force, constant_torque = constant_loads(model)
    return force + constant_force, torque + constant_torque


def spring_energies(model: Model, pos: np.ndarray, rot: np.ndarray) -> np.ndarray:
    """Elastic energy (s,) J of each spring, ``½ k (L - rest)²``, at poses ``pos (n, 3)`` m and
    ``rot (n, 3, 3)`` (body to world)."""
    a, b = model.spring_body_a, model.spring_body_b
    to_world = b == WORLD_ANCHOR
    b_safe = np.where(to_world, 0, b)
    point_a = pos[a] + apply(rot[a], model.spring_anchor_a)
    point_b = np.where(
        to_world[:, None],
        model.spring_anchor_b,
        pos[b_safe] + apply(rot[b_safe], model.spring_anchor_b),
    )
    length = np.linalg.norm(point_b - point_a, axis=1)
    return 0.5 * model.spring_stiffness * (length - model.spring_rest_length) ** 2


def spring_energy(model: Model, state: State, rot: np.ndarray) -> float:
    """Elastic energy J stored in all springs, ``Σ ½ k (L - rest)²``."""
    if model.n_springs == 0:
        return 0.0
    return float(np.sum(spring_energies(model, state.pos, rot)))
