"""What the scenario itself says the engines must build: the parity gate's expected values.

Computed from the compiled scenario alone, on the reference side only: the bodies as the
scene states them at t = 0, the inertias of ``validation.reference.mass_properties`` (or the
scene's own), and the invariants of ``CompiledScene`` (kinetic, gravitational, spring and
applied-force energy and both momenta, with the reference's rotations and spring law). Never
read back from an engine, and nothing of mini_engine, the engine under test, enters it.
"""

from __future__ import annotations

import numpy as np

from validation.engines.base import ModelReport
from validation.scenario.compiled import CompiledScene, rotations, world_inertia


def dynamic_bodies(scene: CompiledScene) -> np.ndarray:
    """(d,) int, scenario indices of the bodies that move (the parity gate's rows)."""
    return np.flatnonzero(scene.moving)


def scene_report(scene: CompiledScene, pos, quat, vel, ang_vel) -> ModelReport:
    """The ``ModelReport`` of one state ``pos, quat, vel, ang_vel (n, ...)`` of the scene's
    bodies with the scene's masses and inertias: dynamic bodies, invariants of all."""
    moving = dynamic_bodies(scene)
    states = tuple(np.asarray(a)[None] for a in (pos, quat, vel, ang_vel))
    inertia = world_inertia(scene.inertia, rotations(states[1]))[0]
    return ModelReport(
        mass=scene.mass[moving].copy(),
        com=np.asarray(pos)[moving].copy(),
        inertia_world=inertia[moving],
        energy=float(scene.energy(*states)[0]),
        linear_momentum=scene.linear_momentum(states[2])[0],
        angular_momentum=scene.angular_momentum(*states)[0],
    )


def reference_report(scene: CompiledScene) -> ModelReport:
    """The ``ModelReport`` every engine must match: the scene at t = 0, as it states it."""
    start = scene.start
    return scene_report(scene, start.pos[0], start.quat[0], start.vel[0], start.ang_vel[0])
