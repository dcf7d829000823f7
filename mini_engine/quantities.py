"""Conserved quantities of a state (formulas.md section 5), per world.

Every function returns one value per world (``model.n_worlds`` rows) so that
replicated scenes are measured copy by copy; fixed bodies contribute nothing.
"""

from __future__ import annotations

import numpy as np

from mini_engine.model import Model, State
from mini_engine.rotation import apply, quat_to_matrix, world_inertia


def _per_world(model: Model, values: np.ndarray) -> np.ndarray:
    """Sum body rows ``values (n, ...)`` into world rows ``(w, ...)``, skipping fixed bodies."""
    moving = model.body_dynamic & (model.body_world >= 0)
    out = np.zeros((model.n_worlds, *values.shape[1:]))
    np.add.at(out, model.body_world[moving], values[moving])
    return out


def linear_momentum(model: Model, state: State) -> np.ndarray:
    """(w, 3) kg·m/s, world frame: ``p = Σ m v``."""
    return _per_world(model, model.body_mass[:, None] * state.vel)


def angular_momentum(model: Model, state: State, about: np.ndarray | None = None) -> np.ndarray:
    """(w, 3) kg·m²/s, world frame: ``L = Σ (x - c) × m v + I_world ω`` about ``about (w, 3)``.

    Default: about the origin, as in formulas.md section 5.
    """
    rot = quat_to_matrix(state.quat)
    spin = apply(world_inertia(rot, model.body_inertia), state.ang_vel)
    centre = np.zeros((model.n_worlds, 3)) if about is None else about
    arm = state.pos - centre[np.maximum(model.body_world, 0)]
    orbital = np.cross(arm, model.body_mass[:, None] * state.vel)
    return _per_world(model, orbital + spin)


def centre_of_mass(model: Model, state: State) -> np.ndarray:
    """(w, 3) m, world frame, of the moving bodies."""
    mass = _per_world(model, model.body_mass)
    return _per_world(model, model.body_mass[:, None] * state.pos) / mass[:, None]


def kinetic_energy(model: Model, state: State) -> np.ndarray:
    """(w,) J: ``Σ ½ m |v|² + ½ ωᵀ I_world ω``."""
    rot = quat_to_matrix(state.quat)
    spin = apply(world_inertia(rot, model.body_inertia), state.ang_vel)
    body = 0.5 * model.body_mass * np.sum(state.vel**2, axis=1)
    body += 0.5 * np.sum(state.ang_vel * spin, axis=1)
    return _per_world(model, body)


def potential_energy(model: Model, state: State) -> np.ndarray:
    """(w,) J, gravitational: ``Σ -m g·x`` (zero at the origin)."""
    return _per_world(model, -model.body_mass * (state.pos @ model.gravity))
