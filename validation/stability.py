"""Numerical stability: what counts as a failed run, and the largest stable step.

The taxonomy (``KINDS``) is checked on every observed state of every run, in any engine,
and never aborts the harness: the run stops, its rows get status ``unstable``, and the
message names the kind. ``largest_stable_dt`` bisects the step of one scene in one
engine between a stable and an unstable value.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from validation.engines.base import Snapshot
from validation.scenario import Scenario
from validation.scene_physics import SHAPE_BUILDERS, SceneEnergy

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


BISECTION_RATIO = 1.02
"""The bisection stops when the unstable and stable steps are within 2 % of each other."""

MAX_BISECTIONS = 40


@dataclass(frozen=True)
class StabilityLimit:
    """The largest stable step of one scene in one engine (``None`` bounds: not bracketed)."""

    scenario: str
    engine: str
    stable_dt: float | None
    unstable_dt: float | None
    reason: str

    def sentence(self) -> str:
        """The finding in plain words, as the report prints it."""
        if self.stable_dt is None and self.unstable_dt is None:
            return f"{self.engine} was not run on {self.scenario}: {self.reason}"
        if self.stable_dt is None:
            return f"{self.engine} is unstable at every dt tried on {self.scenario} (down to {self.unstable_dt:.3g} s): {self.reason}"
        if self.unstable_dt is None:
            return f"{self.engine} is stable on {self.scenario} up to the largest dt tried ({self.stable_dt:.3g} s)"
        return (
            f"{self.engine} is unstable above dt = {self.unstable_dt:.3g} s on {self.scenario} "
            f"(stable at {self.stable_dt:.3g} s): {self.reason}"
        )


def largest_stable_dt(
    is_stable: Callable[[float], tuple[bool, str]], start: float, lowest: float, highest: float
) -> tuple[float | None, float | None, str]:
    """Bracket and bisect (geometric) the step where ``is_stable(dt)`` turns false.

    Returns (largest stable dt, smallest unstable dt, the unstable run's reason); a bound is
    None when no dt in [lowest, highest] was stable (or unstable).
    """
    stable, unstable, reason = None, None, ""
    dt = start
    ok, why = is_stable(dt)
    while True:  # bracket by factors of 2
        if ok:
            stable = dt
            if dt >= highest:
                return stable, None, ""
            dt = min(dt * 2.0, highest)
        else:
            unstable, reason = dt, why
            if dt <= lowest:
                return None, unstable, reason
            dt = max(dt / 2.0, lowest)
        if stable is not None and unstable is not None:
            break
        ok, why = is_stable(dt)
    for _ in range(MAX_BISECTIONS):
        if unstable / stable <= BISECTION_RATIO:
            break
        middle = math.sqrt(stable * unstable)
        ok, why = is_stable(middle)
        if ok:
            stable = middle
        else:
            unstable, reason = middle, why
    return stable, unstable, reason


def scene_at(scenario: Scenario, dt: float) -> Scenario:
    """The same scene with another step (duration unchanged)."""
    return Scenario.model_validate({**scenario.model_dump(), "dt": dt, "source": scenario.source})


SEARCH_DOWN = 16.0
"""The bisection looks for a stable step down to the scene's dt / 16. Each halving doubles
the cost of a probe, and a scheme that is unstable 16 times below the author's step is
unstable for the scene's purposes (explicit Euler on an undamped spring grows as
exp(ω² dt t): at any fixed dt it explodes given time, so "every dt tried" is the finding)."""

SEARCH_UP_FRACTION = 0.1
"""... and for an unstable one up to a tenth of the scene's duration."""

SAMPLES_PER_PROBE = 200
"""Trajectory samples kept per probe run: stability is checked at every observation anyway."""


def stability_limit(scenario: Scenario, spec, search_down: float = SEARCH_DOWN) -> StabilityLimit:
    """The largest stable dt of ``scenario`` in the engine ``spec`` (any EngineSpec), searched
    between the scene's dt / ``search_down`` and a tenth of its duration."""
    from validation.runner import run_engine
    from validation.scenario import MAX_STEPS

    def is_stable(dt: float) -> tuple[bool, str]:
        probe = scene_at(scenario, dt)
        run = run_engine(probe, spec, max(1, probe.steps // SAMPLES_PER_PROBE))
        if run.status == "model_mismatch":
            raise _NotRunError(run.message)
        return run.status == "ok", run.message

    lowest = max(scenario.dt / search_down, scenario.duration / MAX_STEPS)
    highest = max(scenario.dt, SEARCH_UP_FRACTION * scenario.duration)
    try:
        stable, unstable, reason = largest_stable_dt(is_stable, scenario.dt, lowest, highest)
    except _NotRunError as why:
        return StabilityLimit(scenario.name or "", spec.label, None, None, f"model_mismatch: {why}")
    return StabilityLimit(scenario.name or "", spec.label, stable, unstable, reason)


class _NotRunError(Exception):
    """The engine's model failed the parity gate: its stability says nothing."""
