"""Numerical stability: what counts as a failed run.

The taxonomy (``KINDS``) is checked on every observed state of every run, in any engine,
and never aborts the harness: the run stops at the first failing state, its rows get status
``unstable``, and the message names the kind. (The largest stable step is searched in
``validation.jobs.stability_search``.)
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from validation.measure.states import Trajectory
from validation.scenario.compiled import CompiledScene

ENERGY_BLOW_UP_FACTOR = 1e6
"""A run whose energy departs from its start by more than this multiple of the scene's
energy scale has exploded. A million, because a stable symplectic Euler oscillator at
ω·dt = 1.98 still swings its true energy by (1 + h/2)/(1 - h/2) ≈ 200x; an unstable one
grows geometrically and passes any bound within a few hundred steps."""

QUATERNION_NORM_DRIFT = 1e-6
"""Largest |‖q‖ - 1| of a body orientation; engines renormalise every step, so drift
beyond round-off means the orientation update has broken down."""

PENETRATION_FRACTION = 1.0
"""Overlap, as a fraction of the smaller body's bounding radius, beyond which one body
has passed into or through another (tunnelling)."""

SPEED_FACTOR = 100.0
"""Speeds beyond this multiple of the scene's speed scale (initial speeds, free fall over
the run, initial spin times size) cannot come from its physics: energy was created."""

KINDS = (
    "non_finite",
    "energy_blow_up",
    "quaternion_drift",
    "deep_penetration",
    "speed_limit",
    "engine_warning",
)
"""Every way a run can fail; a message starts with its kind."""


@dataclass
class StabilityChecks:
    """The taxonomy applied to the observed states of one run, batch by batch.

    The first observed state fixes the energy reference; ``first_failure`` returns the first
    state of a batch that fails a check, with its message, so the run can stop there.
    """

    scene: CompiledScene
    energy0: float | None = None
    energy_scale: float = 1.0

    @property
    def speed_limit(self) -> float:
        """m/s, beyond which a speed cannot come from the scene's physics."""
        return SPEED_FACTOR * self.scene.speed_scale

    def first_failure(
        self,
        states: Trajectory,
        deepest: np.ndarray | None = None,
        radius: np.ndarray | None = None,
    ) -> tuple[int, str] | None:
        """(index in ``states``, ``kind: detail at t``) of the first failing state, or None.

        ``deepest (s,)`` m and ``radius (s,)`` m: each state's deepest overlap and the smaller
        bounding radius of that pair (``deep_penetration``), when the scene can touch. At one
        state the kinds are judged in the order non-finite, energy, quaternion, speed, overlap.
        """
        finite = np.ones(len(states), dtype=bool)
        for array in (states.pos, states.quat, states.vel, states.ang_vel):
            finite &= np.isfinite(array).reshape(len(states), -1).all(axis=1)
        with np.errstate(over="ignore", invalid="ignore"):
            energy = self.scene.energy(states.pos, states.quat, states.vel, states.ang_vel)
        if self.energy0 is None and finite[0]:
            self.energy0 = float(energy[0])
            self.energy_scale = max(abs(self.energy0), self.scene.energy_floor)
        reference = self.energy0 if self.energy0 is not None else 0.0
        with np.errstate(over="ignore", invalid="ignore"):
            growth = np.abs(energy - reference) / self.energy_scale
            norm_drift = np.abs(np.linalg.norm(states.quat, axis=2) - 1.0).max(axis=1)
            speed = np.linalg.norm(states.vel, axis=2).max(axis=1)
        failed = {
            "non_finite": ~finite,
            "energy_blow_up": finite & (growth > ENERGY_BLOW_UP_FACTOR),
            "quaternion_drift": finite & (norm_drift > QUATERNION_NORM_DRIFT),
            "speed_limit": finite & (speed > self.speed_limit),
        }
        if deepest is not None:
            failed["deep_penetration"] = finite & (deepest > PENETRATION_FRACTION * radius)
        any_failed = np.logical_or.reduce(list(failed.values()))
        if not any_failed.any():
            return None
        index = int(np.argmax(any_failed))
        kind = next(kind for kind, mask in failed.items() if mask[index])
        details = {
            "non_finite": lambda: "state",
            "energy_blow_up": lambda: f"energy moved {growth[index]:.3g}x its scale",
            "quaternion_drift": lambda: "an orientation is no longer a unit quaternion",
            "speed_limit": lambda: (
                f"speed {speed[index]:.3g} m/s beyond {self.speed_limit:.3g} m/s"
            ),
            "deep_penetration": lambda: (
                f"overlap {deepest[index]:.3g} m exceeds the body size {radius[index]:.3g} m"
            ),
        }
        return index, f"{kind}: {details[kind]()} at t = {states.t[index]:.6g} s"
