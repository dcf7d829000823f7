"""What the scenario itself says the engines must build: the parity gate's expected values.

Computed from the scenario alone (the solid-shape formulas of ``mini_engine.shapes``,
shared by every engine's expectation), never read back from an engine.
"""

from __future__ import annotations

import numpy as np

from mini_engine.forces import spring_energy
from mini_engine.quantities import (
    angular_momentum,
    centre_of_mass,
    kinetic_energy,
    linear_momentum,
    potential_energy,
)
from mini_engine.rotation import quat_to_matrix, world_inertia
from validation.engines.base import ModelReport
from validation.scenario import Scenario
from validation.scenario.physics import build_mini_model


def dynamic_bodies(scenario: Scenario) -> np.ndarray:
    """(d,) int, scenario indices of the bodies that move (the parity gate's rows)."""
    return np.array([i for i, b in enumerate(scenario.bodies) if not b.fixed], dtype=np.int64)


def reference_report(scenario: Scenario) -> ModelReport:
    """The ``ModelReport`` every engine must match: dynamic bodies only, t = 0."""
    model, state = build_mini_model(scenario)
    moving = dynamic_bodies(scenario)
    rot = quat_to_matrix(state.quat)
    centre = centre_of_mass(model, state)
    return ModelReport(
        mass=model.body_mass[moving].copy(),
        com=state.pos[moving].copy(),
        inertia_world=world_inertia(rot, model.body_inertia)[moving],
        energy=float(
            kinetic_energy(model, state)[0]
            + potential_energy(model, state)[0]
            + spring_energy(model, state, rot)
        ),
        linear_momentum=linear_momentum(model, state)[0],
        angular_momentum=angular_momentum(model, state, about=centre)[0],
    )
