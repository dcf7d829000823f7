"""The mini adapter: ``mini_engine`` with its ``Settings`` taken from the engine spec."""

from __future__ import annotations

import importlib.metadata

import numpy as np

from mini_engine import Settings, step
from mini_engine.forces import spring_energy
from mini_engine.quantities import (
    angular_momentum,
    centre_of_mass,
    kinetic_energy,
    linear_momentum,
    potential_energy,
)
from mini_engine.rotation import quat_to_matrix, world_inertia
from validation.engines.base import ModelReport, Provenance, Snapshot
from validation.engines.reference import dynamic_bodies
from validation.scenario import Scenario
from validation.scenario.engine_spec import EngineSpec
from validation.scenario.physics import build_mini_model


class MiniAdapter:
    """mini_engine as an ``EngineAdapter``; the scene's bodies come first in its model."""

    def __init__(self, spec: EngineSpec):
        self.spec = spec

    def load(self, scenario: Scenario) -> None:
        self.settings = Settings(dt=scenario.dt, **self.spec.as_dict())
        self.model, self.state = build_mini_model(scenario)
        self.count = len(scenario.bodies)
        self.moving = dynamic_bodies(scenario)

    def model_report(self) -> ModelReport:
        model, state = self.model, self.state
        rot = quat_to_matrix(state.quat)
        energy = kinetic_energy(model, state)[0] + potential_energy(model, state)[0]
        return ModelReport(
            mass=model.body_mass[self.moving].copy(),
            com=state.pos[self.moving].copy(),
            inertia_world=world_inertia(rot, model.body_inertia)[self.moving],
            energy=float(energy + spring_energy(model, state, rot)),
            linear_momentum=linear_momentum(model, state)[0],
            angular_momentum=angular_momentum(model, state, about=centre_of_mass(model, state))[0],
        )

    def advance(self, steps: int) -> None:
        state = self.state
        for _ in range(steps):
            state, _ = step(self.model, state, self.settings)
        self.state = state

    def observe(self) -> Snapshot:
        s, n = self.state, self.count
        return Snapshot(
            s.time, s.pos[:n].copy(), s.quat[:n].copy(), s.vel[:n].copy(), s.ang_vel[:n].copy()
        )

    def provenance(self) -> Provenance:
        return Provenance(
            engine="mini_engine",
            version=importlib.metadata.version("physval"),
            settings=self.settings.as_dict(),
            notes=["numpy " + np.__version__],
        )

    def close(self) -> None:
        """Nothing to release."""
