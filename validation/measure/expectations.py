"""The scene's own expectations, evaluated online at full time resolution.

Every expectation kind has a tracker in ``TRACKERS``. The recording feeds each tracker every
observed state of the run (a batch at a time, in order) and every impact event as it closes;
the tracker keeps only what its answer needs (a bracketing pair of states, running sums, a
sign), so memory does not grow with the run, and the answer does not depend on how many
samples the trajectory keeps for plotting: a 6 s run and a 2.9 s run measure the same first
bounce alike.

Every answer is a ``Measurement`` whose ``value`` is the measured quantity, ``expected``
the target and ``error`` their difference (for vectors: the norms and the distance).
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np

from mini_engine.rotation import quat_to_matrix
from validation.engines.base import Trajectory
from validation.measure.measurement import Measurement
from validation.reference.rotation import rotation_angle
from validation.scenario.compiled import (
    CompiledScene,
    gravitational_energy,
    kinetic_energy,
    rotations,
)
from validation.scenario.physics import symmetry_frame

TIME_MATCH = 1e-9
"""Relative. An observed time within this of a requested time is that time: engines add dt
to their clock every step (MuJoCo, mini), so after 10^4 steps of 1e-3 s the clock reads
9.999999999998 for 10 s (round-off about 1e-13 relative, far below a step)."""

NOT_MEASURED = math.inf
"""Error of an expectation the run never reached (it stopped early, or had no impact)."""


def _missing(expectation, message: str) -> Measurement:
    return Measurement(expectation.metric, math.nan, None, "analytic", NOT_MEASURED, message)


def _vector(expectation, got: np.ndarray, where: str) -> Measurement:
    """``value`` |measured|, ``expected`` |target|, ``error`` the distance between the two."""
    target = np.asarray(expectation.value, dtype=float)
    return Measurement(
        expectation.metric,
        float(np.linalg.norm(got)),
        float(np.linalg.norm(target)),
        "analytic",
        float(np.linalg.norm(got - target)),
        f"{where}: {np.round(got, 6).tolist()} (expected {np.round(target, 6).tolist()})",
    )


@dataclass
class _Tracker:
    """One expectation of one body; ``update`` is fed every counted state and closed event."""

    scene: CompiledScene
    expectation: object
    body: int = field(init=False)

    def __post_init__(self) -> None:
        self.body = next(
            i for i, b in enumerate(self.scene.scenario.bodies) if b.name == self.expectation.body
        )

    def mine(self, events) -> list:
        return [e for e in events if self.expectation.body in (e.body_a, e.body_b)]


@dataclass
class StateAt(_Tracker):
    """Position or velocity of the body at ``time``: the observed state there, or the linear
    interpolation between the two observed states around it."""

    quantity: str = "pos"
    before: tuple[float, np.ndarray] | None = None
    after: tuple[float, np.ndarray] | None = None

    def update(self, states: Trajectory, events) -> None:
        if self.after is not None or len(states) == 0:
            return
        self._bracket(states.t, getattr(states, self.quantity)[:, self.body])

    def _bracket(self, t: np.ndarray, values: np.ndarray) -> None:
        """Keep the observed values just before and at (or after) the expected time."""
        reached = np.flatnonzero(t >= self.expectation.time - self._slack())
        if reached.size:
            k = int(reached[0])
            self.after = (float(t[k]), values[k].copy())
            if k > 0:
                self.before = (float(t[k - 1]), values[k - 1].copy())
        else:
            self.before = (float(t[-1]), values[-1].copy())

    def _slack(self) -> float:
        return TIME_MATCH * max(self.expectation.time, self.scene.scenario.dt)

    def value_at(self) -> tuple[np.ndarray, str] | None:
        """The value at the expected time (interpolated between the two observed states
        around it) and where it was read; None when the run ended before."""
        if self.after is None:
            return None
        t1, v1 = self.after
        if self.before is None or abs(t1 - self.expectation.time) <= self._slack():
            return v1, f"{self.quantity} at t = {t1:.6g} s"
        t0, v0 = self.before
        weight = (self.expectation.time - t0) / (t1 - t0)
        where = f"{self.quantity} at t = {self.expectation.time:.6g} s (between observations)"
        return v0 + weight * (v1 - v0), where

    def result(self) -> Measurement:
        found = self.value_at()
        if found is None:
            return _missing(self.expectation, f"the run ended before t = {self.expectation.time} s")
        return _vector(self.expectation, *found)


@dataclass
class VelocityAfterImpact(_Tracker):
    """Velocity of the body after its first impact, read once the contact has ended (the
    first observed state apart: soft contacts last several steps) and carried back to the
    impulse centroid with the body's free-flight acceleration (as ``ImpactEvent`` carries the
    relative velocities), so a one-step impulse reads exactly the velocity it left behind."""

    found: Measurement | None = None

    def update(self, states: Trajectory, events) -> None:
        if self.found is not None:
            return
        first = self.mine(events)
        if not first:
            return
        event = first[0]
        at = np.flatnonzero(states.t == event.time_end)
        acceleration = self.scene.acceleration[self.body]  # g + F/m: free flight
        velocity = states.vel[int(at[0]), self.body] - acceleration * (
            event.time_end - event.time_impulse
        )
        where = f"velocity after the impact at t = {event.time_impulse:.6g} s"
        self.found = _vector(self.expectation, velocity, where)

    def result(self) -> Measurement:
        return self.found or _missing(self.expectation, "no impact")


@dataclass
class BounceHeights(_Tracker):
    """Apex height of the centre of mass after each of the body's first impacts: the higher of
    the two states around the first one after the impact that is no longer rising."""

    pending: list[float] = field(default_factory=list)
    seen: int = 0
    apexes: list[float] = field(default_factory=list)
    last_z: float | None = None

    def update(self, states: Trajectory, events) -> None:
        wanted = len(self.expectation.value)
        for event in self.mine(events):
            if self.seen < wanted:
                self.pending.append(event.time_end)
                self.seen += 1
        if len(states) == 0:
            return
        z, vz = states.pos[:, self.body, 2], states.vel[:, self.body, 2]
        previous = np.concatenate([[self.last_z if self.last_z is not None else z[0]], z[:-1]])
        while self.pending:
            falling = np.flatnonzero((states.t >= self.pending[0]) & (vz <= 0.0))
            if not falling.size:
                break
            k = int(falling[0])
            self.apexes.append(float(max(previous[k], z[k])))
            self.pending.pop(0)
        self.last_z = float(z[-1])

    def result(self) -> Measurement:
        wanted = np.asarray(self.expectation.value, dtype=float)
        if len(self.apexes) < wanted.size:
            message = f"{len(self.apexes)} apexes seen, {wanted.size} expected"
            return _missing(self.expectation, message)
        misses = np.abs(np.array(self.apexes) - wanted)
        worst = int(np.argmax(misses))
        return Measurement(
            self.expectation.metric,
            self.apexes[worst],
            float(wanted[worst]),
            "analytic",
            float(misses[worst]),
            f"apexes {np.round(self.apexes, 5).tolist()} m (worst: apex {worst + 1})",
        )


def _body_frame(states: Trajectory, body: int) -> np.ndarray:
    """(s, 3) rad/s, the body's angular velocity in its own frame."""
    rot = quat_to_matrix(states.quat[:, body])
    return np.einsum("sji,sj->si", rot, states.ang_vel[:, body])


@dataclass
class PrecessionRate(_Tracker):
    """Rate at which ω turns about the body's symmetry axis in the body frame: the least-squares
    slope of the unwrapped angle over every observed state (running sums)."""

    sums: np.ndarray = field(default_factory=lambda: np.zeros(5))
    """n, Σt, Σθ, Σt², Σtθ with t from the first state."""
    start: float | None = None
    last_angle: float | None = None

    def __post_init__(self) -> None:
        super().__post_init__()
        axis, self.first, self.second = symmetry_frame(self.scene.inertia[self.body])
        self.axis_name = "xyz"[axis] if axis is not None else "symmetry"

    def update(self, states: Trajectory, events) -> None:
        if len(states) == 0:
            return
        omega = _body_frame(states, self.body)
        raw = np.arctan2(omega @ self.second, omega @ self.first)
        if self.last_angle is None:
            self.start, angle = float(states.t[0]), np.unwrap(raw)
        else:
            angle = np.unwrap(np.concatenate([[self.last_angle], raw]))[1:]
        t = states.t - self.start
        self.sums += [t.size, t.sum(), angle.sum(), (t * t).sum(), (t * angle).sum()]
        self.last_angle = float(angle[-1])

    def result(self) -> Measurement:
        n, st, sa, stt, sta = self.sums
        if n < 2 or n * stt - st * st <= 0.0:
            return _missing(self.expectation, "fewer than two observed states")
        rate = float((n * sta - st * sa) / (n * stt - st * st))
        return Measurement(
            self.expectation.metric,
            rate,
            float(self.expectation.value),
            "analytic",
            abs(rate - self.expectation.value),
            f"rate {rate:.6g} rad/s about the body's {self.axis_name} axis",
        )


@dataclass
class Flips(_Tracker):
    """Sign changes of one body-frame component of ω over every observed state (exact zeros
    are skipped)."""

    count: int = 0
    sign: float = 0.0

    def update(self, states: Trajectory, events) -> None:
        if len(states) == 0:
            return
        component = _body_frame(states, self.body)[:, "xyz".index(self.expectation.axis)]
        signs = np.sign(component[component != 0.0])
        if signs.size == 0:
            return
        if self.sign != 0.0:
            signs = np.concatenate([[self.sign], signs])
        self.count += int(np.sum(np.diff(signs) != 0))
        self.sign = float(signs[-1])

    def result(self) -> Measurement:
        return Measurement(
            self.expectation.metric,
            float(self.count),
            float(self.expectation.value),
            "analytic",
            float(abs(self.count - self.expectation.value)),
            f"{self.count} flips",
        )


@dataclass
class AngularVelocityAfterImpact(_Tracker):
    """Angular velocity of the body at the first state apart after its first impact, carried
    back to the impulse by the applied torque's ``R I⁻¹ Rᵀ τ`` (gravity and forces at the centre
    of mass exert none; without a torque nothing is carried)."""

    found: Measurement | None = None

    def update(self, states: Trajectory, events) -> None:
        if self.found is not None:
            return
        first = self.mine(events)
        if first:
            event = first[0]
            at = int(np.flatnonzero(states.t == event.time_end)[0])
            ang_vel = states.ang_vel[at, self.body]
            torque = self.scene.torque[self.body]
            if np.any(torque):
                rot = rotations(states.quat[at, self.body])
                inverse = rot @ np.linalg.inv(self.scene.inertia[self.body]) @ rot.T
                ang_vel = ang_vel - inverse @ torque * (event.time_end - event.time_impulse)
            where = f"angular velocity after the impact at t = {event.time_impulse:.6g} s"
            self.found = _vector(self.expectation, ang_vel, where)

    def result(self) -> Measurement:
        return self.found or _missing(self.expectation, "no impact")


@dataclass
class OrientationAt(StateAt):
    """Orientation of the body at ``time`` (the observed state there, or the nearer of the two
    around it): ``value`` and ``expected`` the rotation angles from the identity, ``error`` the
    angle between the two orientations."""

    quantity: str = "quat"

    def result(self) -> Measurement:
        if self.after is None:
            return _missing(self.expectation, f"the run ended before t = {self.expectation.time} s")
        time = self.expectation.time
        t1, q1 = self.after
        if self.before is not None and abs(self.before[0] - time) < abs(t1 - time):
            t1, q1 = self.before
        target = np.asarray(self.expectation.value, dtype=float)
        identity = np.array([1.0, 0.0, 0.0, 0.0])
        return Measurement(
            self.expectation.metric,
            float(rotation_angle(q1, identity)),
            float(rotation_angle(target, identity)),
            "analytic",
            float(rotation_angle(q1, target)),
            f"orientation at t = {t1:.6g} s: {np.round(q1, 6).tolist()} (expected {np.round(target, 6).tolist()})",
        )


@dataclass
class EnergyAt(StateAt):
    """The body's own energy at ``time``: ½ m v² + ½ ωᵀ I_world ω - m g·x (J), from the
    observed state there or interpolated between the two around it."""

    quantity: str = "energy"

    def update(self, states: Trajectory, events) -> None:
        if self.after is not None or len(states) == 0:
            return
        b = slice(self.body, self.body + 1)
        one = Trajectory(
            states.t, states.pos[:, b], states.quat[:, b], states.vel[:, b], states.ang_vel[:, b]
        )
        mass = self.scene.mass[b]
        rot = rotations(one.quat)
        inertia = rot @ self.scene.inertia[b][None] @ rot.swapaxes(-1, -2)
        energy = kinetic_energy(mass, inertia, one.vel, one.ang_vel)
        energy += gravitational_energy(mass, one.pos, self.scene.gravity)
        self._bracket(states.t, energy[:, None])

    def result(self) -> Measurement:
        found = self.value_at()
        if found is None:
            return _missing(self.expectation, f"the run ended before t = {self.expectation.time} s")
        energy, where = float(found[0][0]), found[1]
        target = float(self.expectation.value)
        return Measurement(
            self.expectation.metric,
            energy,
            target,
            "analytic",
            abs(energy - target),
            f"{where}: {energy:.6g} J",
        )


@dataclass
class _TimesOf(_Tracker):
    """Compares a list of event times with the expected list: ``value`` the worst event's
    measured time, ``expected`` its target, ``error`` the largest |Δt| (s)."""

    times: list[float] = field(default_factory=list)

    def result(self) -> Measurement:
        wanted = np.asarray(self.expectation.value, dtype=float)
        if len(self.times) < wanted.size:
            message = f"{len(self.times)} seen, {wanted.size} expected: {np.round(self.times, 5).tolist()} s"
            return _missing(self.expectation, message)
        got = np.array(self.times[: wanted.size])
        misses = np.abs(got - wanted)
        worst = int(np.argmax(misses))
        return Measurement(
            self.expectation.metric,
            float(got[worst]),
            float(wanted[worst]),
            "analytic",
            float(misses[worst]),
            f"times {np.round(got, 5).tolist()} s",
        )


@dataclass
class FlipTimes(_TimesOf):
    """Times at which a body-frame component of ω changes sign, each found by linear
    interpolation between the two observed states around the crossing."""

    last: tuple[float, float] | None = None

    def update(self, states: Trajectory, events) -> None:
        if len(states) == 0:
            return
        component = _body_frame(states, self.body)[:, "xyz".index(self.expectation.axis)]
        t = states.t
        if self.last is not None:
            t = np.concatenate([[self.last[0]], t])
            component = np.concatenate([[self.last[1]], component])
        crossing = np.flatnonzero(np.sign(component[1:]) * np.sign(component[:-1]) < 0)
        for k in crossing:
            fraction = component[k] / (component[k] - component[k + 1])
            self.times.append(float(t[k] + fraction * (t[k + 1] - t[k])))
        self.last = (float(t[-1]), float(component[-1]))


@dataclass
class ImpactTimes(_TimesOf):
    """Times of the body's impacts: each event's impulse centroid."""

    def update(self, states: Trajectory, events) -> None:
        self.times += [e.time_impulse for e in self.mine(events)]


TRACKERS: dict[str, Callable[[CompiledScene, object], _Tracker]] = {
    "position_at": lambda scene, e: StateAt(scene, e, "pos"),
    "velocity_at": lambda scene, e: StateAt(scene, e, "vel"),
    "velocity_after_impact": VelocityAfterImpact,
    "bounce_heights": BounceHeights,
    "precession_rate": PrecessionRate,
    "flips": Flips,
    "angular_velocity_at": lambda scene, e: StateAt(scene, e, "ang_vel"),
    "angular_velocity_after_impact": AngularVelocityAfterImpact,
    "orientation_at": OrientationAt,
    "flip_times": FlipTimes,
    "impact_times": ImpactTimes,
    "energy_at": EnergyAt,
}
"""Expectation kind -> its tracker (metric ``<kind>.<body>``, or the expectation's ``name``)."""


def trackers(scene: CompiledScene) -> list[_Tracker]:
    """A tracker for each of the scene's expectations, in the scene's order."""
    return [TRACKERS[e.kind](scene, e) for e in scene.scenario.expect]
