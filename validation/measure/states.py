"""Observed states of a run, as one structure of arrays (the same for every engine)."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from validation.engines.base import Snapshot
from validation.scenario.compiled import CompiledScene


@dataclass(frozen=True)
class Trajectory:
    """Observed states of one run (s states, n scene bodies, scenario order).

    Attributes:
        t: (s,) s. pos: (s, n, 3) m, world, centres of mass. quat: (s, n, 4) w x y z.
        vel: (s, n, 3) m/s, world. ang_vel: (s, n, 3) rad/s, world.
    """

    t: np.ndarray
    pos: np.ndarray
    quat: np.ndarray
    vel: np.ndarray
    ang_vel: np.ndarray

    @staticmethod
    def stack(snapshots: list[Snapshot]) -> Trajectory:
        return Trajectory(
            t=np.array([s.time for s in snapshots]),
            pos=np.stack([s.pos for s in snapshots]),
            quat=np.stack([s.quat for s in snapshots]),
            vel=np.stack([s.vel for s in snapshots]),
            ang_vel=np.stack([s.ang_vel for s in snapshots]),
        )

    def __len__(self) -> int:
        return int(self.t.size)

    def take(self, index) -> Trajectory:
        """The states at ``index`` (an int array or a slice)."""
        return Trajectory(
            *(a[index] for a in (self.t, self.pos, self.quat, self.vel, self.ang_vel))
        )


@dataclass(frozen=True)
class Series:
    """Invariants over the samples of a trajectory (s samples).

    Attributes:
        t: (s,) s. energy: (s,) J (kinetic + gravitational + spring).
        momentum: (s, 3) kg·m/s. angular_momentum: (s, 3) kg·m²/s about the system COM.
        com: (s, 3) m, the moving bodies' centre of mass.
    """

    t: np.ndarray
    energy: np.ndarray
    momentum: np.ndarray
    angular_momentum: np.ndarray
    com: np.ndarray


def invariants(scene: CompiledScene, trajectory: Trajectory) -> Series:
    """The scene's energy and momenta at every sample of ``trajectory`` (one definition:
    ``CompiledScene``)."""
    states = (trajectory.pos, trajectory.quat, trajectory.vel, trajectory.ang_vel)
    with np.errstate(over="ignore", invalid="ignore"):
        return Series(
            t=trajectory.t,
            energy=scene.energy(*states),
            momentum=scene.linear_momentum(trajectory.vel),
            angular_momentum=scene.angular_momentum(*states),
            com=scene.centre_of_mass(trajectory.pos),
        )
