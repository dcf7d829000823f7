"""What a run's observed states imply: the invariants over its samples, and the reductions
over bodies the metrics read at each sample (``Trajectory`` is the adapters' own record,
``validation.engines.base``).

Everything here is a function of one sample at a time, so a run computes it a batch of kept
samples at a time as they are observed (``recording``) and keeps O(samples) numbers, never
one per body and sample: the metrics of the trajectory (``validation.measure.metrics``) then
read only these series, and give the same numbers as if they had had the whole trajectory.
"""

from __future__ import annotations

from dataclasses import dataclass, fields

import numpy as np

from validation.engines.base import Trajectory
from validation.scenario.compiled import CompiledScene

__all__ = ["Series", "Trajectory", "ballistic", "invariants"]


@dataclass(frozen=True)
class Series:
    """Invariants over the samples of a trajectory (s samples), and the per-sample reductions
    over bodies that the metrics of the trajectory need.

    Attributes:
        t: (s,) s. energy: (s,) J (kinetic + gravitational + spring).
        momentum: (s, 3) kg·m/s. angular_momentum: (s, 3) kg·m²/s about the system COM.
        com: (s, 3) m, the moving bodies' centre of mass.
        motion: (s,) J, kinetic + spring energy (``metrics.energy_scale``).
        position_offset, velocity_offset: (s, 3) m and m/s, world frame, at each sample the
            difference from the analytic ballistic motion (``ballistic``) of the body farthest
            from it (the first such body); (0, 3) when the scene has no ballistic closed form
            (``definability``: bodies can touch, or a spring acts).
    """

    t: np.ndarray
    energy: np.ndarray
    momentum: np.ndarray
    angular_momentum: np.ndarray
    com: np.ndarray
    motion: np.ndarray
    position_offset: np.ndarray
    velocity_offset: np.ndarray

    @staticmethod
    def concat(*parts: Series) -> Series:
        """One series of consecutive parts (at least one)."""
        return Series(
            *(np.concatenate([getattr(p, f.name) for p in parts]) for f in fields(Series))
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
    no_offset = np.zeros((0, 3))
    with np.errstate(over="ignore", invalid="ignore"):
        motion = scene.kinetic_energy(trajectory.quat, trajectory.vel, trajectory.ang_vel)
        motion = motion + scene.spring_energy(trajectory.pos, trajectory.quat)
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
            momentum=scene.linear_momentum(trajectory.vel),
            angular_momentum=scene.angular_momentum(*states),
            com=scene.centre_of_mass(trajectory.pos),
            motion=motion,
            position_offset=offsets[0],
            velocity_offset=offsets[1],
        )
