"""Numerical stability: what counts as a failed run.

The taxonomy (``KINDS``) is checked on every observed state of every run, in any engine,
and never aborts the harness: the run stops at the first failing state, its rows get status
``unstable``, and the message names the kind. (The largest stable step is searched in
``validation.jobs.stability_search``.)
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

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

GROWTH_WINDOW_STEPS = 8
"""The energy error's envelope is its largest value in each window of this many steps (every
step is observed, so a window holds the peaks of oscillations as fast as the step)."""

GROWTH_RATE_PER_STEP = math.log(2.0) / GROWTH_WINDOW_STEPS
"""Geometric growth of the energy error faster than doubling every 8 steps, sustained over
``GROWTH_WINDOWS_IN_A_ROW`` windows, is an instability however far the run is from a
blow-up. Defined per step, so the verdict does not depend on the scene's duration: RK4 on
ω = 1000 rad/s grows ≈ 1 + 14.6 δ per step at ω·dt = 2√2 (1 + δ), caught from δ = 0.5 %;
symplectic Euler above ω·dt = 2 grows at once by ≥ 9 % per step. A stable run's error is
bounded (symplectic Euler's oscillates, up to 200x the energy near ω·dt = 2), grows no faster
than linearly (energy added at impacts: window ratios 2, 1.5, 1.33, ...), or jumps once. Slow
geometric growth (explicit Euler at ω·dt < 0.3) is left to the blow-up check."""

GROWTH_WINDOWS_IN_A_ROW = 2
"""Consecutive window-to-window ratios that must all show that growth (two: an unstable
scene whose growth saturates, e.g. a spring folding through its anchor, may grow for only
three windows)."""

GROWTH_MIN_ERROR = 1.0
"""... and the energy error at the end of that growth must exceed the energy scale itself:
a small error that grows faster than linearly for a while (quadratic drift from zero: window
ratios 4, 2.25) is not an explosion."""

GROWTH_FLOOR = 1e-9
"""Relative to the energy scale: energy errors below this are round-off, never growth."""

KINDS = (
    "non_finite",
    "energy_blow_up",
    "energy_growth",
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
    window_error: np.ndarray = field(default_factory=lambda: np.zeros(0))
    """Largest |E - E0| / scale seen in each growth window from ``window_offset`` on: the
    windows judged already are dropped but the last ``GROWTH_WINDOWS_IN_A_ROW`` (a run of
    growth ending in a later window needs them), so the memory and the time of a check are
    bounded by the scene, not the duration (before, 2,000,000 steps kept 250,000
    windows and re-judged all of them after every batch)."""
    window_offset: int = 0
    """Absolute index of the window ``window_error[0]`` holds."""

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
            self._envelope(states.t, np.where(finite, growth, np.inf))
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

    def _envelope(self, t: np.ndarray, error: np.ndarray) -> None:
        """Fold the energy errors of states at times ``t`` into their windows' maxima."""
        length = GROWTH_WINDOW_STEPS * self.scene.scenario.dt
        window = np.maximum((t / length + 1e-9).astype(int) - self.window_offset, 0)
        if window.size and window.max() >= self.window_error.size:
            grown = np.zeros(int(window.max()) + 1)
            grown[: self.window_error.size] = self.window_error
            self.window_error = grown
        np.maximum.at(self.window_error, window, error)

    def _forget(self, judged: int) -> None:
        """Drop the first ``judged`` windows: every run of growth ending in them was judged."""
        if judged > 0:
            self.window_error = self.window_error[judged:].copy()
            self.window_offset += judged

    def growth_failure(self, time: float, complete: bool = False) -> str | None:
        """``energy_growth`` when the energy error's envelope grew geometrically, faster than
        ``GROWTH_RATE_PER_STEP``, over ``GROWTH_WINDOWS_IN_A_ROW`` consecutive windows. Only
        finished windows count (all of them when the run is ``complete``)."""
        finished = self.window_error if complete else self.window_error[:-1]
        envelope = np.maximum(finished, GROWTH_FLOOR)
        if envelope.size <= GROWTH_WINDOWS_IN_A_ROW:
            return None
        threshold = math.exp(GROWTH_RATE_PER_STEP * GROWTH_WINDOW_STEPS)
        growing = (envelope[1:] / envelope[:-1]) >= threshold
        run = np.convolve(growing, np.ones(GROWTH_WINDOWS_IN_A_ROW, dtype=int), "valid")
        ends = np.flatnonzero(run == GROWTH_WINDOWS_IN_A_ROW) + GROWTH_WINDOWS_IN_A_ROW
        ends = ends[envelope[ends] > GROWTH_MIN_ERROR]
        if ends.size == 0:
            self._forget(finished.size - GROWTH_WINDOWS_IN_A_ROW)
            return None
        first = int(ends[0]) - GROWTH_WINDOWS_IN_A_ROW
        factor = envelope[first + GROWTH_WINDOWS_IN_A_ROW] / envelope[first]
        return (
            f"energy_growth: the energy error grew {factor:.3g}x in "
            f"{GROWTH_WINDOWS_IN_A_ROW * GROWTH_WINDOW_STEPS} steps (geometrically) by t = {time:.6g} s"
        )
