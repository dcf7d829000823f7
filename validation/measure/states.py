"""What a run's observed states imply: the invariants over its samples, and the reductions
over bodies the metrics read at each sample (``Trajectory`` is the adapters' own record,
``validation.engines.base``).

Everything here is a function of one sample at a time, so a run computes it a batch of
states at a time as they are observed (``recording``) and keeps O(samples) numbers, never
one per body and sample. The metrics of the trajectory (``validation.measure.metrics``) are
maxima over time of per-sample quantities (``EXTREMES``); the recording streams every
observed state through ``extreme_samples``, which keeps the run's first and last samples and
the sample where each quantity peaks, so a metric read from those few samples is its maximum
over every step, whatever the kept series (plots) thins.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, fields

import numpy as np

from validation.engines.base import Trajectory
from validation.reference.articulated import (
    AXIS_TYPES,
    Joint,
    joint_coordinates,
    joint_violations,
)
from validation.reference.rotation import cross
from validation.scenario.compiled import CompiledScene, kinetic_energy, rotations

__all__ = ["EXTREMES", "Series", "Trajectory", "ballistic", "extreme_samples", "invariants"]


@dataclass(frozen=True)
class Series:
    """Invariants over the samples of a trajectory (s samples), and the per-sample reductions
    over bodies that the metrics of the trajectory need.

    Attributes:
        t: (s,) s. energy: (s,) J (kinetic + gravitational + spring).
        momentum: (s, 3) kg·m/s. angular_momentum: (s, 3) kg·m²/s about the system COM.
        com: (s, 3) m, the moving bodies' centre of mass.
        motion: (s,) J, the internal kinetic energy plus the spring energy (``internal``;
            ``internal_energy`` adds the centre of mass's own change of motion).
        momentum_scale: (s,) kg·m/s, ``Σ m |v|`` over the bodies (no cancellation between
            them: ``metrics.linear_momentum_drift``'s scale).
        angular_momentum_scale: (s,) kg·m²/s, ``Σ m |(x - c) × (v - v_c)| + |I_world ω|``
            over the bodies, about the centre of mass c moving at v_c
            (``metrics.angular_momentum_drift``'s scale).
        position_offset, velocity_offset: (s, 3) m and m/s, world frame, at each sample the
            difference from the analytic ballistic motion (``ballistic``) of the body farthest
            from it (the first such body); (0, 3) when the scene has no ballistic closed form
            (``definability``: bodies can touch, or a spring acts).
        joint_violation: (s,) m, the largest of the scene's joint violations at each sample
            (``joint_violation``); zeros without joints.
        joint_coordinates: (s, c) rad or m, a scene with models: the tree's hinge and slider
            coordinates read from the poses (``tree_coordinates``, what ``joint_divergence``
            compares across engines); (s, 0) otherwise.
    """

    t: np.ndarray
    energy: np.ndarray
    momentum: np.ndarray
    angular_momentum: np.ndarray
    com: np.ndarray
    motion: np.ndarray
    momentum_scale: np.ndarray
    angular_momentum_scale: np.ndarray
    position_offset: np.ndarray
    velocity_offset: np.ndarray
    joint_violation: np.ndarray
    joint_coordinates: np.ndarray

    @staticmethod
    def concat(*parts: Series) -> Series:
        """One series of consecutive parts (at least one)."""
        return Series(
            *(np.concatenate([getattr(p, f.name) for p in parts]) for f in fields(Series))
        )

    def take(self, index) -> Series:
        """The samples ``index`` (an index array or a slice); the offsets only where the series
        has them (a scene without a ballistic closed form has none)."""
        offsets = {"position_offset", "velocity_offset"}
        return Series(
            *(
                getattr(self, f.name)
                if f.name in offsets and getattr(self, f.name).shape[0] == 0
                else getattr(self, f.name)[index]
                for f in fields(Series)
            )
        )


def ballistic(scene: CompiledScene, t: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Analytic positions and velocities (s, n, 3) of free flight at times ``t (s,)`` (a scene
    where nothing can touch and no spring acts: ``definability``)."""
    t = t[:, None, None]
    x0 = np.array([b.position for b in scene.scenario.bodies])[None]
    v0 = np.array([b.velocity for b in scene.scenario.bodies])[None]
    a = scene.acceleration[None]  # g + F/m, zero for fixed bodies
    return x0 + v0 * t + 0.5 * a * t**2, v0 + a * t


def farthest(difference: np.ndarray) -> np.ndarray:
    """(s, 3): at each sample the row of ``difference (s, n, 3)`` with the largest norm (the
    first one on ties; the first non-finite one, as ``np.argmax`` picks)."""
    body = np.argmax(np.linalg.norm(difference, axis=2), axis=1)
    return difference[np.arange(difference.shape[0]), body]


def invariants(scene: CompiledScene, trajectory: Trajectory, free: bool = False) -> Series:
    """The scene's energy and momenta at every sample of ``trajectory`` (one definition:
    ``CompiledScene``); with ``free``, the offsets from the ballistic motion too."""
    states = (trajectory.pos, trajectory.quat, trajectory.vel, trajectory.ang_vel)
    rot = None if scene.joint_tree is None else rotations(trajectory.quat)  # the joints read it
    no_offset = np.zeros((0, 3))
    with np.errstate(over="ignore", invalid="ignore"):
        momentum = scene.linear_momentum(trajectory.vel)
        motion = internal(scene, trajectory, momentum)
        if free:
            analytic = ballistic(scene, trajectory.t)
            offsets = (
                farthest(trajectory.pos - analytic[0]),
                farthest(trajectory.vel - analytic[1]),
            )
        else:
            offsets = (no_offset, no_offset)
        return Series(
            t=trajectory.t,
            energy=scene.energy(*states),
            momentum=momentum,
            angular_momentum=scene.angular_momentum(*states),
            com=scene.centre_of_mass(trajectory.pos),
            motion=motion,
            momentum_scale=np.einsum("n,sn->s", scene.mass, np.linalg.norm(trajectory.vel, axis=2)),
            angular_momentum_scale=_angular_momentum_scale(scene, trajectory, momentum),
            position_offset=offsets[0],
            velocity_offset=offsets[1],
            joint_violation=joint_violation(scene, trajectory, rot),
            joint_coordinates=tree_coordinates(scene, trajectory, rot),
        )


def joint_violation(
    scene: CompiledScene, trajectory: Trajectory, rot: np.ndarray | None = None
) -> np.ndarray:
    """(s,) m: at each sample the largest joint violation as a distance, over the joints of
    ``scene.joint_tree`` (``articulated.joint_violations``, from the bodies' poses alone): an
    anchor's separation, or a misalignment times the child's reach from the anchor (how far
    the rotation error moves its centre). Zeros without joints. ``rot``: (s, n, 3, 3) the
    bodies' rotations when the caller has them."""
    tree = scene.joint_tree
    if tree is None:
        return np.zeros(trajectory.t.shape)
    rot = rotations(trajectory.quat) if rot is None else rot
    separation, misalignment, reach = joint_violations(tree, trajectory.pos, rot)
    return np.maximum(separation, misalignment * reach).max(axis=1, initial=0.0)


def coordinate_joints(scene: CompiledScene) -> list[Joint]:
    """The joints whose coordinates a scene with models keeps (``tree_coordinates``): the
    tree's hinges and sliders, in its order; none in a scene without models."""
    tree = scene.joint_tree
    if tree is None or not scene.scenario.models:
        return []
    return [joint for joint in tree.joints if joint.type in AXIS_TYPES]


def tree_coordinates(
    scene: CompiledScene, trajectory: Trajectory, rot: np.ndarray | None = None
) -> np.ndarray:
    """(s, c) rad or m: each of ``coordinate_joints``' coordinate at every sample, read from
    the observed poses (``articulated.joint_coordinates``; a hinge's angle unwrapped within
    the block of samples only, so comparisons wrap its differences)."""
    joints = coordinate_joints(scene)
    if not joints:
        return np.zeros((trajectory.t.size, 0))
    rot = rotations(trajectory.quat) if rot is None else rot
    found = joint_coordinates(scene.joint_tree, trajectory.pos, rot)
    return np.stack([found[joint.name] for joint in joints], axis=1)


def _centre_velocity(scene: CompiledScene, momentum: np.ndarray) -> np.ndarray:
    """(s, 3) m/s, the moving bodies' centre-of-mass velocity ``p / M`` (zero without mass)."""
    total = float(scene.mass.sum())
    return momentum / total if total > 0.0 else np.zeros_like(momentum)


def internal(scene: CompiledScene, trajectory: Trajectory, momentum: np.ndarray) -> np.ndarray:
    """(s,) J, the system's internal kinetic energy plus its spring energy.

    The kinetic energy splits (König) into ``½ M |v_c|²``, the centre of mass's, and the
    kinetic energy about the centre of mass, ``Σ ½ m |v - v_c|² + ½ ωᵀ I_world ω``. A free
    system (no ground, fixed body or spring to the world: ``CompiledScene.external_loads``)
    keeps the second alone, which a Galilean boost ``v -> v + u`` leaves unchanged (every
    ``v - v_c`` is); where the world holds the system, the world is its rest frame (the ground
    an infinitely heavy body at rest), and the kinetic energy is taken whole."""
    vel = trajectory.vel
    if not scene.external_loads:
        vel = vel - _centre_velocity(scene, momentum)[:, None, :]
    kinetic = kinetic_energy(
        scene.mass, scene.inertia_world(trajectory.quat), vel, trajectory.ang_vel
    )
    return kinetic + scene.spring_energy(trajectory.pos, trajectory.quat)


def _angular_momentum_scale(
    scene: CompiledScene, trajectory: Trajectory, momentum: np.ndarray
) -> np.ndarray:
    """(s,) kg·m²/s, ``Σ m |(x - c) × (v - v_c)| + |I_world ω|`` (``Series``): each body's
    orbital and spin angular momentum about the centre of mass, added without cancellation."""
    arm = trajectory.pos - scene.centre_of_mass(trajectory.pos)[:, None, :]
    relative = trajectory.vel - _centre_velocity(scene, momentum)[:, None, :]
    orbital = np.linalg.norm(cross(arm, relative), axis=2)
    spin = np.einsum("snij,snj->sni", scene.inertia_world(trajectory.quat), trajectory.ang_vel)
    moving = (scene.mass > 0).astype(float)
    return orbital @ scene.mass + np.linalg.norm(spin, axis=2) @ moving


def momentum_rates(scene: CompiledScene) -> tuple[np.ndarray, np.ndarray]:
    """((3,) N, (3,) N·m): the constant rates of change of the linear momentum, ``M g + ΣF``,
    and of the angular momentum about the centre of mass, ``Στ`` (uniform g + F/m exerts no
    torque about it), where the scene defines them (``definability``)."""
    linear = scene.mass.sum() * scene.gravity + scene.force.sum(axis=0)
    return linear, scene.torque.sum(axis=0)


def internal_energy(scene: CompiledScene, series: Series) -> np.ndarray:
    """(s,) J, ``motion`` plus, for a free system, ``½ M |v_c(t) - v_c(0)|²`` (the energy its
    loads gave the centre of mass's motion since the first sample, ``series`` starting
    there): what ``energy_drift``'s scale takes the largest of. A Galilean boost changes
    neither term; a projectile from rest reads ``½ M |g t|²``, the energy gravity traded."""
    if scene.external_loads:
        return series.motion
    change = _centre_velocity(scene, series.momentum - series.momentum[0])
    return series.motion + 0.5 * float(scene.mass.sum()) * np.einsum("si,si->s", change, change)


def impulse_residual(scene: CompiledScene, series: Series, name: str) -> np.ndarray:
    """(s, 3) ``x(t) - x(0) - rate·(t - t0)`` of the momentum ``name`` (``momentum`` or
    ``angular_momentum``) whose rate is constant (``momentum_rates``), ``series`` starting at
    the run's first sample."""
    rate = momentum_rates(scene)[name == "angular_momentum"]
    values = getattr(series, name)
    return values - values[0] - rate * (series.t - series.t[0])[:, None]


Magnitude = Callable[[CompiledScene, Series], np.ndarray]

EXTREMES: dict[str, Magnitude] = {
    "energy_change": lambda scene, s: np.abs(s.energy - s.energy[0]),
    "internal_energy": internal_energy,
    "momentum_residual": lambda scene, s: np.linalg.norm(
        impulse_residual(scene, s, "momentum"), axis=1
    ),
    "momentum_scale": lambda scene, s: s.momentum_scale,
    "angular_momentum_residual": lambda scene, s: np.linalg.norm(
        impulse_residual(scene, s, "angular_momentum"), axis=1
    ),
    "angular_momentum_scale": lambda scene, s: s.angular_momentum_scale,
    "position_offset": lambda scene, s: np.linalg.norm(s.position_offset, axis=1),
    "velocity_offset": lambda scene, s: np.linalg.norm(s.velocity_offset, axis=1),
    "joint_violation": lambda scene, s: s.joint_violation,
}
"""Per-sample magnitude (of a series that starts at the run's first sample) -> its values:
every quantity whose maximum over time a metric reads (``validation.measure.metrics``)."""


def extreme_samples(scene: CompiledScene, series: Series) -> Series:
    """The samples of ``series`` (starting at the run's first sample) that any metric reads: the
    first, the last, and the first where each of ``EXTREMES`` peaks (``np.argmax``, as the
    metrics pick). Folding a run batch by batch, ``extreme_samples(concat(kept, batch))``,
    keeps exactly what the metrics of every step would read, in a handful of samples."""
    picks = {0, series.t.size - 1}
    with np.errstate(over="ignore", invalid="ignore"):
        for magnitude in EXTREMES.values():
            values = magnitude(scene, series)
            if values.size:
                picks.add(int(np.argmax(values)))
    return series.take(np.array(sorted(picks)))
