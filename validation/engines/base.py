"""The engine interface every adapter implements, and the records it produces.

An adapter turns a ``Scenario`` into one engine's model, advances it by whole steps,
and reads the state back in the scene's conventions: bodies in scenario order (the
ground plane is never a body of the snapshot), centre of mass, quaternions w x y z,
linear and angular velocity in the world frame. Every unit, frame and quaternion-order
conversion happens inside the adapter, at its boundary, and nowhere else.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Protocol

import numpy as np

from validation.scenario.compiled import CompiledScene
from validation.scenario.engine_spec import EngineSpec


@dataclass(frozen=True)
class Snapshot:
    """The scene's bodies at one instant (n bodies, scenario order).

    Attributes:
        time: s since the start.
        pos: (n, 3) m, world frame, centres of mass.
        quat: (n, 4) unit quaternions w x y z, body (scenario) frame to world.
        vel: (n, 3) m/s, world frame, centre-of-mass velocities.
        ang_vel: (n, 3) rad/s, world frame.
    """

    time: float
    pos: np.ndarray
    quat: np.ndarray
    vel: np.ndarray
    ang_vel: np.ndarray


@dataclass(frozen=True)
class ModelReport:
    """What an engine built, read back from the engine itself after loading (parity gate).

    Attributes:
        mass: (n,) kg.
        com: (n, 3) m, world frame.
        inertia_world: (n, 3, 3) kg·m², world frame, about each centre of mass.
        energy: J, kinetic + gravitational potential + spring energy at t = 0.
        linear_momentum: (3,) kg·m/s.
        angular_momentum: (3,) kg·m²/s, about the system's centre of mass.
    """

    mass: np.ndarray
    com: np.ndarray
    inertia_world: np.ndarray
    energy: float
    linear_momentum: np.ndarray
    angular_momentum: np.ndarray


@dataclass
class Provenance:
    """Enough to reproduce a run: the engine's version and its full effective settings."""

    engine: str
    version: str
    settings: dict[str, object] = field(default_factory=dict)
    notes: list[str] = field(default_factory=list)


class EngineAdapter(Protocol):
    """One engine behind one small interface (Solver2D's pattern: one file per engine)."""

    spec: EngineSpec

    def load(self, scene: CompiledScene) -> None:
        """Build the engine's model of the compiled scene at its scenario's dt."""

    def model_report(self) -> ModelReport:
        """Masses, centres of mass, world inertias and invariants as the engine holds them."""

    def advance(self, steps: int) -> None:
        """Advance ``steps`` fixed steps."""

    def observe(self) -> Snapshot:
        """The current state, in the scene's conventions."""

    def provenance(self) -> Provenance:
        """Version and effective settings."""

    def close(self) -> None:
        """Release the engine (PyBullet clients, for example)."""
