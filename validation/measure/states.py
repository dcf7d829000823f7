"""What a run's observed states imply: the invariants over its samples (``Trajectory`` is
the adapters' own record, ``validation.engines.base``)."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from validation.engines.base import Trajectory
from validation.scenario.compiled import CompiledScene

__all__ = ["Series", "Trajectory", "invariants"]


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
