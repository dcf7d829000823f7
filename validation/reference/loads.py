"""What pushes a scene's bodies besides contacts, as the scene states it: linear
spring-dampers between anchors, and each body's constant applied force and torque.

Arrays: ``n`` scene bodies in scenario order, ``k`` springs; any leading axes ``...`` are
states (a whole recording is one call). Positions are centres of mass, world frame, m;
rotations body to world; velocities world frame. Gravity is not a load here: it is an
acceleration, added where the motion is integrated.
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import cached_property

import numpy as np

from validation.reference.rotation import cross, norm

WORLD = -1
"""``Springs.body_b`` of a spring whose second end is a fixed point of the world."""

MIN_SPRING_LENGTH = 1e-12
"""m. Below this anchor distance a spring has no axis; it then pulls on nothing (a spring
of rest length 0 whose ends meet is in equilibrium anyway)."""


@dataclass(frozen=True)
class Springs:
    """The scene's ``k`` linear spring-dampers.

    Attributes:
        body_a: (k,) int, the scene body of end A.
        body_b: (k,) int, the scene body of end B, or ``WORLD``.
        anchor_a: (k, 3) m, end A in body a's frame (from its centre of mass).
        anchor_b: (k, 3) m, end B in body b's frame, or a world point when ``body_b`` is
            ``WORLD``.
        stiffness: (k,) N/m. damping: (k,) N·s/m. rest_length: (k,) m.
    """

    body_a: np.ndarray
    body_b: np.ndarray
    anchor_a: np.ndarray
    anchor_b: np.ndarray
    stiffness: np.ndarray
    damping: np.ndarray
    rest_length: np.ndarray

    @property
    def count(self) -> int:
        return int(self.body_a.size)

    @cached_property
    def to_world(self) -> np.ndarray:
        """(k,) bool: end B is a fixed point of the world."""
        return self.body_b == WORLD

    @cached_property
    def body_b_or_any(self) -> np.ndarray:
        """(k,) int: ``body_b``, with body 0 for a world end (any body: its values are masked)."""
        return np.where(self.to_world, 0, self.body_b)

    def incidence(self, bodies: int) -> tuple[np.ndarray, np.ndarray]:
        """(k, n) each, 1 where spring k's end A (B) is on body n of ``bodies``, else 0 (a
        world end on none): built once per body count, as they depend on nothing else."""
        built = self.__dict__.setdefault("_incidence", {})  # a frozen dataclass's own cache
        if bodies not in built:
            attached = np.ones(self.count, dtype=bool)
            built[bodies] = (
                _incidence(self.body_a, bodies, attached),
                _incidence(self.body_b_or_any, bodies, ~self.to_world),
            )
        return built[bodies]


@dataclass(frozen=True)
class SpringEnds:
    """Both ends of every spring at some states (``...`` leading axes, ``k`` springs).

    Attributes:
        arm_a, arm_b: (..., k, 3) m, world frame, from each end's body centre to the end
            (0 for a world end).
        point_a, point_b: (..., k, 3) m, world frame.
    """

    arm_a: np.ndarray
    arm_b: np.ndarray
    point_a: np.ndarray
    point_b: np.ndarray


def spring_ends(springs: Springs, pos: np.ndarray, rot: np.ndarray) -> SpringEnds:
    """The springs' ends at the poses ``pos (..., n, 3)`` m and ``rot (..., n, 3, 3)``."""
    to_world, body_b = springs.to_world, springs.body_b_or_any
    arm_a = np.einsum("...kij,kj->...ki", rot[..., springs.body_a, :, :], springs.anchor_a)
    arm_b = np.einsum("...kij,kj->...ki", rot[..., body_b, :, :], springs.anchor_b)
    arm_b = np.where(to_world[:, None], 0.0, arm_b)
    point_a = pos[..., springs.body_a, :] + arm_a
    point_b = np.where(to_world[:, None], springs.anchor_b, pos[..., body_b, :] + arm_b)
    return SpringEnds(arm_a, arm_b, point_a, point_b)


def spring_energies(springs: Springs, pos: np.ndarray, rot: np.ndarray) -> np.ndarray:
    """(..., k) J, each spring's elastic energy ``½ k (L - rest)²`` at the poses ``pos
    (..., n, 3)`` and ``rot (..., n, 3, 3)``, ``L`` its anchors' distance."""
    ends = spring_ends(springs, pos, rot)
    length = norm(ends.point_b - ends.point_a)
    return 0.5 * springs.stiffness * (length - springs.rest_length) ** 2


def spring_energy(springs: Springs, pos: np.ndarray, rot: np.ndarray) -> np.ndarray:
    """(...) J, the energy stored in all springs (``spring_energies`` summed)."""
    return spring_energies(springs, pos, rot).sum(axis=-1)


def spring_loads(
    springs: Springs,
    bodies: int,
    pos: np.ndarray,
    rot: np.ndarray,
    vel: np.ndarray,
    ang_vel: np.ndarray,
) -> tuple[np.ndarray, np.ndarray]:
    """Forces (..., n, 3) N and torques (..., n, 3) N·m about each centre of mass, world
    frame, of the springs on the ``bodies`` (n) scene bodies at ``pos, vel, ang_vel (..., n,
    3)`` and ``rot (..., n, 3, 3)``.

    A spring of length ``L`` along the unit axis ``u`` from end A to end B pulls with the
    tension ``f = k (L - rest) + c (v_B - v_A)·u``, ``v`` each end's velocity; body a feels
    ``+f u`` at A, body b ``-f u`` at B, each with its torque ``arm × force``. Fixed bodies
    are not special here (the caller keeps them still).
    """
    ends = spring_ends(springs, pos, rot)
    to_world, body_b = springs.to_world, springs.body_b_or_any
    speed_a = vel[..., springs.body_a, :] + cross(ang_vel[..., springs.body_a, :], ends.arm_a)
    speed_b = vel[..., body_b, :] + cross(ang_vel[..., body_b, :], ends.arm_b)
    speed_b = np.where(to_world[:, None], 0.0, speed_b)
    offset = ends.point_b - ends.point_a
    length = norm(offset)
    has_axis = length >= MIN_SPRING_LENGTH
    axis = np.where(
        has_axis[..., None], offset / np.maximum(length, MIN_SPRING_LENGTH)[..., None], 0.0
    )
    stretch_speed = np.sum((speed_b - speed_a) * axis, axis=-1)
    tension = springs.stiffness * (length - springs.rest_length)
    tension = tension + springs.damping * stretch_speed
    pull_on_a = tension[..., None] * axis
    on_a, on_b = springs.incidence(bodies)
    force = np.einsum("kn,...ki->...ni", on_a, pull_on_a)
    force -= np.einsum("kn,...ki->...ni", on_b, pull_on_a)
    torque = np.einsum("kn,...ki->...ni", on_a, cross(ends.arm_a, pull_on_a))
    torque -= np.einsum("kn,...ki->...ni", on_b, cross(ends.arm_b, pull_on_a))
    return force, torque


def _incidence(body: np.ndarray, bodies: int, attached: np.ndarray) -> np.ndarray:
    """(k, n) 1 where spring k's end is on body n (and ``attached (k,)``), else 0."""
    incidence = np.zeros((body.size, bodies))
    incidence[np.flatnonzero(attached), body[attached]] = 1.0
    return incidence


def applied_loads(
    springs: Springs,
    moving: np.ndarray,
    force: np.ndarray,
    torque: np.ndarray,
    pos: np.ndarray,
    rot: np.ndarray,
    vel: np.ndarray,
    ang_vel: np.ndarray,
) -> tuple[np.ndarray, np.ndarray]:
    """Forces (..., n, 3) N and torques (..., n, 3) N·m about each centre of mass, world
    frame: the springs' (``spring_loads``) plus each body's constant applied ``force (n, 3)``
    N and ``torque (n, 3)`` N·m, zero on the bodies that are not ``moving (n,)``."""
    spring_force, spring_torque = spring_loads(springs, moving.size, pos, rot, vel, ang_vel)
    still = ~moving[:, None]
    return (
        np.where(still, 0.0, spring_force + force),
        np.where(still, 0.0, spring_torque + torque),
    )
