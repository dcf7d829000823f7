"""What the scenario itself says the engines must build: the parity gate's expected values.

Computed from the compiled scenario alone, on the reference side only: the bodies as the
scene states them at t = 0, the inertias of ``validation.reference.mass_properties`` (or the
scene's own), and the invariants of ``CompiledScene`` (kinetic, gravitational, spring and
applied-force energy and both momenta, with the reference's rotations and spring law). Never
read back from an engine, and nothing of mini_engine, the engine under test, enters it.
With them, the physical magnitude each quantity's error is relative to (``magnitudes``).
"""

from __future__ import annotations

import numpy as np

from validation.engines.base import ModelReport
from validation.engines.parity import QUANTITIES, ExpectedReport, Magnitudes
from validation.reference.rotation import cross
from validation.scenario.compiled import (
    CompiledScene,
    centre_of_mass,
    kinetic_energy,
    rotations,
    world_inertia,
)


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


def magnitudes(scene: CompiledScene, pos, quat, vel, ang_vel) -> Magnitudes:
    """The ``Magnitudes`` of the scene's quantities in one state (``scene_report``'s
    arguments): every term of a total taken by its size, so none cancels another."""
    moving = dynamic_bodies(scene)
    pos, vel, ang_vel = (np.asarray(a, dtype=np.float64) for a in (pos, vel, ang_vel))
    mass, inertia = scene.mass, world_inertia(scene.inertia, rotations(np.asarray(quat)[None]))[0]
    spin = np.linalg.norm(np.einsum("nij,nj->ni", inertia, ang_vel), axis=1) @ (mass > 0)
    centre = centre_of_mass(mass, pos[None])[0]
    centre_velocity = vel.T @ mass / mass.sum() if mass.sum() > 0 else np.zeros(3)
    orbital = np.linalg.norm(cross(pos - centre, vel - centre_velocity), axis=1) @ mass
    potential = np.abs(mass * (pos @ scene.gravity)) + np.abs(
        np.einsum("ni,ni->n", scene.force, pos)
    )
    kinetic = kinetic_energy(mass, inertia[None], vel[None], ang_vel[None])[0]
    springs = scene.spring_energy(pos[None], np.asarray(quat)[None])[0]
    trace = np.trace(scene.inertia, axis1=1, axis2=2)
    reach = np.sqrt(np.divide(trace, mass, out=np.zeros_like(trace), where=mass > 0))
    return Magnitudes(
        mass=mass[moving].copy(),
        com=(np.linalg.norm(pos, axis=1) + reach)[moving],
        inertia_world=np.abs(inertia).max(axis=(1, 2), initial=0.0)[moving],
        energy=float(kinetic + potential.sum() + springs),
        linear_momentum=float(mass @ np.linalg.norm(vel, axis=1)),
        angular_momentum=float(orbital + spin),
    )


def reference_report(scene: CompiledScene) -> ExpectedReport:
    """The ``ModelReport`` every engine must match, the scene at t = 0 as it states it, with
    the magnitudes of its quantities (the parity gate's ``ExpectedReport``)."""
    start = scene.start
    state = (start.pos[0], start.quat[0], start.vel[0], start.ang_vel[0])
    report = scene_report(scene, *state)
    return ExpectedReport(
        **{f: getattr(report, f) for f in QUANTITIES}, magnitudes=magnitudes(scene, *state)
    )
