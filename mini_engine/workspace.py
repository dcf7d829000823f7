"""Per-model step workspace: what ``step`` can know about a ``Model`` before the first step.

A ``Model`` never changes during a run, so the index sets, flags and constant arrays the
phases derive from it are computed once, on the first ``step`` of that model, and kept
here (``workspace(model)``, kept per model object by ``model.per_model``). Nothing in it
depends on the state; every entry is exactly what the phase computed every step before
(same values, same order), so the physics is unchanged bit for bit.

Index sets that cover every body are stored as ``slice(None)`` instead of an index array:
``x[slice(None)]`` is a view, so the hot path neither gathers nor scatters copies.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from mini_engine.forces import constant_loads, linear_acceleration
from mini_engine.integrate import BodyInertia, body_inertia
from mini_engine.model import Model, per_model

BodySelection = slice | np.ndarray
"""Either ``slice(None)`` (every body) or an ``(k,)`` int array of body indices."""


def _selection(indices: np.ndarray, n: int) -> BodySelection:
    """``slice(None)`` when ``indices`` are all ``n`` bodies in order, else ``indices``."""
    return slice(None) if indices.size == n and n > 0 else indices


@dataclass(frozen=True, eq=False)
class Workspace:
    """Constant per-model data of ``step`` and its phases (n bodies).

    Attributes:
        moving_selection: (n,) bool, the dynamic bodies (``model.body_dynamic``), or
            ``slice(None)`` when every body moves.
        gyroscopic_selection: ``model.gyroscopic_bodies`` or ``slice(None)`` when all are.
        gyroscopic_inertia: the body-frame inertia of those bodies (``integrate.BodyInertia``).
        has_springs: the model has springs (else the spring phase is skipped).
        constant_lin_acc: (n, 3) m/s², world frame, ``g + F_const / m`` (0 for fixed bodies)
            when there are no springs; None otherwise (then it depends on the state).
        constant_torque: (n, 3) N·m, world frame, ``body_torque`` when there are no springs.
        any_torque: ``constant_torque`` has a non-zero entry (False with springs: unknown).
        body_row: (n,) int, the solver's twist row of each body (n for every fixed body).
        colour_cache: the last contact colouring (its rows, order and colour slices), reused while
            the contact graph is unchanged (see ``solver.colour_contacts``).
        rotation_cache: the last step's orientations, their rotation matrices and world
            inverse inertias, reused while the orientations are unchanged (``step._rotations``,
            ``step._world_inverse_inertia``).
        contact_cache: the last step's start-of-step positions, rotations and contacts, reused
            while the poses are unchanged bit for bit (``step._contacts``).
        solver_rows: the contact solver's last rows per constraint direction and what they
            were built from, reused while that is unchanged (``solver._kept_rows``).
    """

    moving_selection: slice | np.ndarray
    gyroscopic_selection: BodySelection
    gyroscopic_inertia: BodyInertia
    has_springs: bool
    constant_lin_acc: np.ndarray | None
    constant_torque: np.ndarray | None
    any_torque: bool
    body_row: np.ndarray
    colour_cache: dict = field(default_factory=dict)
    rotation_cache: dict = field(default_factory=dict)
    contact_cache: dict = field(default_factory=dict)
    solver_rows: dict = field(default_factory=dict)


@per_model
def workspace(model: Model) -> Workspace:
    """The workspace of ``model``, built on its first step and kept per model."""
    n = model.n_bodies
    every_body_moves = n > 0 and bool(model.body_dynamic.all())
    has_springs = model.n_springs > 0
    if has_springs:
        lin_acc, torque, any_torque = None, None, False
    else:
        force, torque = constant_loads(model)  # what applied_loads returns without springs
        lin_acc = linear_acceleration(model, force)
        any_torque = bool(np.any(torque != 0.0))
        for array in (lin_acc, torque):
            array.flags.writeable = False
    body_row = np.where(model.body_fixed, n, np.arange(n))
    gyroscopic = _selection(model.gyroscopic_bodies, n)

    return Workspace(
        moving_selection=slice(None) if every_body_moves else model.body_dynamic,
        gyroscopic_selection=gyroscopic,
        gyroscopic_inertia=body_inertia(model.body_inertia, model.body_inv_inertia, gyroscopic),
        has_springs=has_springs,
        constant_lin_acc=lin_acc,
        constant_torque=torque,
        any_torque=any_torque,
        body_row=body_row,
    )
