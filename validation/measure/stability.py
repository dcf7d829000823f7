"""Numerical stability: what counts as a failed run, and the largest stable step.

The taxonomy (``KINDS``) is checked on every observed state of every run, in any engine,
and never aborts the harness: the run stops, its rows get status ``unstable``, and the
message names the kind. ``largest_stable_dt`` bisects the step of one scene in one
engine between a stable and an unstable value.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from validation.engines.base import Snapshot
from validation.scenario import Scenario
from validation.scenario.physics import SHAPE_BUILDERS, SceneEnergy

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
    "engine_error",
    "engine_warning",
)
"""Every way a run can fail; a message starts with its kind."""


@dataclass
class StabilityMonitor:
    """Checks observed states of one scene against the taxonomy."""

    scenario: Scenario

    def __post_init__(self) -> None:
        bodies = self.scenario.bodies
        self.moving = np.array([not b.fixed for b in bodies])
        self.mass = np.where(self.moving, [b.mass for b in bodies], 0.0)
        self.gravity = np.asarray(self.scenario.gravity, dtype=float)
        speed = max(np.linalg.norm(b.velocity) for b in bodies)
        spin = max(np.linalg.norm(b.angular_velocity) * _size(b) for b in bodies)
        fall = float(np.linalg.norm(self.gravity)) * self.scenario.duration
        self.energy = SceneEnergy(self.scenario)
        initial = tuple(
            np.array([[getattr(b, f) for b in bodies]]) for f in ("position", "orientation")
        )
        stored = float(self.energy.spring_energy(*initial)[0])  # what the springs can release
        release = math.sqrt(
            2.0 * stored / max(self.mass[self.moving].min(initial=math.inf), 1e-300)
        )
        self.speed_limit = SPEED_FACTOR * (1.0 + speed + spin + fall + release)
        self.energy0: float | None = None
        self.energy_scale = 1.0

    def _energy(self, snap: Snapshot) -> float:
        return float(
            self.energy(*(a[None] for a in (snap.pos, snap.quat, snap.vel, snap.ang_vel)))[0]
        )

    def check_overlap(self, deepest: float, radius: float, time: float) -> str | None:
        """``deep_penetration`` when the deepest overlap (m) of a state exceeds
        ``PENETRATION_FRACTION`` of that pair's smaller bounding radius (m)."""
        if deepest > PENETRATION_FRACTION * radius:
            return f"deep_penetration: overlap {deepest:.3g} m exceeds the body size {radius:.3g} m at t = {time:.6g} s"
        return None

    def check(self, snap: Snapshot) -> str | None:
        """The failure of this state (``kind: detail``), or None."""
        if not all(np.isfinite(a).all() for a in (snap.pos, snap.quat, snap.vel, snap.ang_vel)):
            return f"non_finite: state at t = {snap.time:.6g} s"
        energy = self._energy(snap)
        if self.energy0 is None:
            self.energy0 = energy
            self.energy_scale = max(
                abs(energy), float(self.mass.sum()) * (1.0 + np.linalg.norm(self.gravity))
            )
        growth = abs(energy - self.energy0) / self.energy_scale
        for kind, failed, detail in (
            (
                "energy_blow_up",
                growth > ENERGY_BLOW_UP_FACTOR,
                f"energy moved {growth:.3g}x its scale",
            ),
            (
                "quaternion_drift",
                np.abs(np.linalg.norm(snap.quat, axis=1) - 1.0).max() > QUATERNION_NORM_DRIFT,
                "an orientation is no longer a unit quaternion",
            ),
            (
                "speed_limit",
                np.linalg.norm(snap.vel, axis=1).max() > self.speed_limit,
                f"speed {np.linalg.norm(snap.vel, axis=1).max():.3g} m/s beyond {self.speed_limit:.3g} m/s",
            ),
        ):
            if failed:
                return f"{kind}: {detail} at t = {snap.time:.6g} s"
        return None


def _size(body) -> float:
    """m, the bounding radius of a scene body's shape (mini_engine's, one definition)."""
    return SHAPE_BUILDERS[body.shape.type](body.shape).bounding_radius()
