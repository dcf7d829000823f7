"""The scene's own expectations, evaluated online at full time resolution.

Every expectation kind has a tracker in ``TRACKERS``. The recording feeds each tracker every
observed state of the run (a batch at a time, in order) and every impact event as it closes;
the tracker keeps only what its answer needs (a bracketing pair of states, running sums, a
sign), so memory does not grow with the run (but for ``period``, whose mean level is known
only at the end: it keeps the joint's coordinate at every state, ``GROWING_BYTES_PER_STATE``),
and the answer does not depend on how many samples the trajectory keeps for plotting: a 6 s
run and a 2.9 s run measure the same first bounce alike.

A joint's expectations (``joint_position_at``, ``period``) read its coordinate from the
observed poses of its two bodies (``validation.reference.articulated.joint_coordinates``).

Every answer is a ``Measurement`` whose ``value`` is the measured quantity, ``expected``
the target and ``error`` their difference (for vectors: the norms and the distance).
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np

from validation.engines.base import Trajectory
from validation.measure.interpolation import INTERPOLANTS, rotation_vector_between
from validation.measure.measurement import Measurement
from validation.reference.articulated import Joint, JointTree, joint_coordinates
from validation.reference.rotation import quat_to_matrix, rotation_angle
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

GROWING_BYTES_PER_STATE = {"period": 4 * 8}
"""Bytes per counted state of the trackers whose memory grows with the run, by kind:
``Period`` keeps two float64 a state (the time and the coordinate) and its answer holds two
more at once (the two concatenated, then the coordinate less its mean)."""

NOT_MEASURED = math.inf
"""Error of an expectation the run never reached (it stopped early, or had no impact)."""


def _missing(expectation, message: str) -> Measurement:
    return Measurement(expectation.metric, math.nan, None, "analytic", NOT_MEASURED, message)


def _vector(expectation, got: np.ndarray, where: str) -> Measurement:
    """``value`` |measured|, ``expected`` |target|, ``error`` the distance between the two,
    ``signed`` the difference per component."""
    target = np.asarray(expectation.value, dtype=float)
    return Measurement(
        expectation.metric,
        float(np.linalg.norm(got)),
        float(np.linalg.norm(target)),
        "analytic",
        float(np.linalg.norm(got - target)),
        f"{where}: {np.round(got, 6).tolist()} (expected {np.round(target, 6).tolist()})",
        signed=tuple(float(x) for x in got - target),
    )


def _scalar(expectation, got: float, target: float, message: str) -> Measurement:
    """``value`` the measured number, ``expected`` the target, ``error`` |difference|,
    ``signed`` the difference."""
    return Measurement(
        expectation.metric,
        float(got),
        float(target),
        "analytic",
        abs(float(got) - float(target)),
        message,
        signed=(float(got) - float(target),),
    )


@dataclass
class _Tracker:
    """One expectation of one body; ``update`` is fed every counted state and closed event."""

    scene: CompiledScene
    expectation: object
    body: int = field(init=False)
    watched: np.ndarray = field(init=False)
    """The bodies whose contact changes an interpolant may not span (``contact_steps``)."""

    def __post_init__(self) -> None:
        self._locate()

    def _locate(self) -> None:
        """Find the expectation's subject among the scene's bodies."""
        self.body = next(
            i for i, b in enumerate(self.scene.scenario.bodies) if b.name == self.expectation.body
        )
        self.watched = np.array([self.body])

    def mine(self, events) -> list:
        return [e for e in events if self.expectation.body in (e.body_a, e.body_b)]

    def contact_steps(self, t: np.ndarray, changed: np.ndarray) -> None:
        """Told before each ``update`` which of its states ``t (k,)`` end an observed step an
        impulse can act in (``changed (k,)`` bool: the step begins or ends where the contacts of
        a ``watched`` body changed, ``recording``); only the trackers that read between steps
        (``StateAt``) need it."""


@dataclass
class StateAt(_Tracker):
    """A quantity of the body at ``time``: the observed state there, or between the observed
    states around it the interpolant of ``validation.measure.interpolation`` (a cubic Hermite
    of positions and velocities, a cubic through four velocities, the Hermite on the rotation
    group). Keeps the ``side`` states before the time and the ``side`` at or after it.

    An interpolant never spans a step an impulse can act in (one that begins or ends where
    the body's contacts changed: an impact, a contact starting or ending; ``contact_steps``),
    where its motion jumps: it takes only the observed states on the time's side of that
    step, and when the step is the one the time falls in, the value is the observed state
    after it; the row's message says which."""

    quantity: str = "pos"
    before_t: np.ndarray = field(default_factory=lambda: np.zeros(0))
    after_t: np.ndarray = field(default_factory=lambda: np.zeros(0))
    before: dict[str, np.ndarray] = field(default_factory=dict)
    after: dict[str, np.ndarray] = field(default_factory=dict)
    jumps: np.ndarray = field(default_factory=lambda: np.zeros(0))
    """s, the end times of the observed steps near the time an impulse can act in (those
    after the earliest state kept)."""

    def contact_steps(self, t: np.ndarray, changed: np.ndarray) -> None:
        if self.after_t.size >= self.side:
            return
        jumps = np.concatenate([self.jumps, t[changed]])
        earliest = np.concatenate([self.before_t, t[t < self.expectation.time]])[-self.side :]
        self.jumps = jumps[jumps > earliest[0]] if earliest.size else jumps

    def __post_init__(self) -> None:
        super().__post_init__()
        self.arrays, self.side, self.interpolant = INTERPOLANTS[self.quantity]

    def update(self, states: Trajectory, events) -> None:
        if self.after_t.size >= self.side or len(states) == 0:
            return
        values = {name: getattr(states, name)[:, self.body] for name in self.arrays}
        self._bracket(states.t, values)

    def _bracket(self, t: np.ndarray, values: dict[str, np.ndarray]) -> None:
        """Keep the last ``side`` observed states before the expected time and the first
        ``side`` at (or after) it."""
        reached = t >= self.expectation.time - self._slack()
        early, late = ~reached, reached
        self.before_t = np.concatenate([self.before_t, t[early]])[-self.side :]
        self.after_t = np.concatenate([self.after_t, t[late]])[: self.side]
        for name, value in values.items():
            kept = self.before.get(name, value[:0])
            self.before[name] = np.concatenate([kept, value[early]])[-self.side :]
            kept = self.after.get(name, value[:0])
            self.after[name] = np.concatenate([kept, value[late]])[: self.side]

    def _slack(self) -> float:
        return TIME_MATCH * max(self.expectation.time, self.scene.scenario.dt)

    def value_at(self) -> tuple[np.ndarray, str] | None:
        """The value at the expected time (the interpolant between the observed states around
        it) and where it was read; None when the run ended before."""
        if self.after_t.size == 0:
            return None
        time, first = self.expectation.time, float(self.after_t[0])
        if self.before_t.size == 0 or abs(first - time) <= self._slack():
            return self.after[self.arrays[0]][0], f"{self.quantity} at t = {first:.6g} s"
        if np.any((self.jumps > self.before_t[-1]) & (self.jumps <= first)):
            where = (
                f"{self.quantity} at t = {first:.6g} s, the observed step after the contact "
                f"change around t = {time:.6g} s (no interpolation across an impact)"
            )
            return self.after[self.arrays[0]][0], where
        t = np.concatenate([self.before_t, self.after_t])  # at most ``side`` on each side
        arrays = [np.concatenate([self.before[name], self.after[name]]) for name in self.arrays]
        # a jump at the end of step (t_k-1, t_k]: t_k is after it, t_k-1 before
        after_jump = self.jumps[self.jumps <= self.before_t[-1]]
        before_jump = self.jumps[self.jumps > first]
        lowest = after_jump.max(initial=-np.inf)
        smooth = (t >= lowest) & (t < before_jump.min(initial=np.inf))
        where = f"{self.quantity} at t = {time:.6g} s (interpolated between observations"
        if not smooth.all():
            where += f" from t = {t[smooth][0]:.6g} to {t[smooth][-1]:.6g} s: not across a contact change"
        arrays = [values[smooth] for values in arrays]
        return self.interpolant(time, t[smooth], *arrays), where + ")"

    def result(self) -> Measurement:
        found = self.value_at()
        if found is None:
            return _missing(self.expectation, f"the run ended before t = {self.expectation.time} s")
        return _vector(self.expectation, *found)


@dataclass
class VelocityAfterImpact(_Tracker):
    """Velocity of the body after its first impact, read once the contact has ended (the
    first observed state apart: soft contacts last several steps) and carried back to the
    impulse centroid with the acceleration the body was observed to have over the step before
    the contact (``ImpactEvent.acceleration_of``: g + F/m in free flight, nothing for a body
    resting on a support), as ``ImpactEvent`` carries the relative velocities; a one-step
    impulse reads exactly the velocity it left behind."""

    found: Measurement | None = None

    def update(self, states: Trajectory, events) -> None:
        if self.found is not None:
            return
        first = self.mine(events)
        if not first:
            return
        event = first[0]
        at = np.flatnonzero(states.t == event.time_end)
        observed = event.acceleration_of(self.expectation.body)
        acceleration = self.scene.acceleration[self.body] if observed is None else observed
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
        message = f"apexes {np.round(self.apexes, 5).tolist()} m (worst: apex {worst + 1})"
        return _scalar(self.expectation, self.apexes[worst], wanted[worst], message)


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
        message = f"rate {rate:.6g} rad/s about the body's {self.axis_name} axis"
        return _scalar(self.expectation, rate, self.expectation.value, message)


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
        return _scalar(self.expectation, self.count, self.expectation.value, f"{self.count} flips")


@dataclass
class AngularVelocityAfterImpact(_Tracker):
    """Angular velocity of the body at the first state apart after its first impact, carried
    back to the impulse centroid with the angular acceleration the body was observed to have
    over the step before the contact (``ImpactEvent.angular_acceleration_of``: an applied
    torque's ``R I⁻¹ Rᵀ τ`` and the gyroscopic change of a tumbling body, nothing for a body at
    rest); when no step before the contact was observed, with the applied torque's alone."""

    found: Measurement | None = None

    def update(self, states: Trajectory, events) -> None:
        if self.found is not None:
            return
        first = self.mine(events)
        if first:
            event = first[0]
            at = int(np.flatnonzero(states.t == event.time_end)[0])
            observed = event.angular_acceleration_of(self.expectation.body)
            if observed is None:
                rot = rotations(states.quat[at, self.body])
                inverse = rot @ np.linalg.inv(self.scene.inertia[self.body]) @ rot.T
                observed = inverse @ self.scene.torque[self.body]
            elapsed = event.time_end - event.time_impulse
            ang_vel = states.ang_vel[at, self.body] - observed * elapsed
            where = f"angular velocity after the impact at t = {event.time_impulse:.6g} s"
            self.found = _vector(self.expectation, ang_vel, where)

    def result(self) -> Measurement:
        return self.found or _missing(self.expectation, "no impact")


@dataclass
class OrientationAt(StateAt):
    """Orientation of the body at ``time`` (the observed state there, or between the two
    around it the Hermite on the rotation group of ``validation.measure.interpolation``):
    ``value`` and ``expected`` the rotation angles from the identity, ``error`` the angle
    between the two orientations, ``signed`` the world-frame rotation vector taking the
    expected orientation to the measured one."""

    quantity: str = "quat"

    def result(self) -> Measurement:
        found = self.value_at()
        if found is None:
            return _missing(self.expectation, f"the run ended before t = {self.expectation.time} s")
        quat, where = found
        target = np.asarray(self.expectation.value, dtype=float)
        identity = np.array([1.0, 0.0, 0.0, 0.0])
        turn = rotation_vector_between(target, quat)
        return Measurement(
            self.expectation.metric,
            float(rotation_angle(quat, identity)),
            float(rotation_angle(target, identity)),
            "analytic",
            float(rotation_angle(quat, target)),
            f"{where}: {np.round(quat, 6).tolist()} (expected {np.round(target, 6).tolist()})",
            signed=tuple(float(x) for x in turn),
        )


@dataclass
class EnergyAt(StateAt):
    """The body's own energy at ``time``: ½ m v² + ½ ωᵀ I_world ω - m g·x (J), from the
    observed state there or, between the states around it, the cubic through four of them."""

    quantity: str = "energy"

    def update(self, states: Trajectory, events) -> None:
        if self.after_t.size >= self.side or len(states) == 0:
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
        self._bracket(states.t, {"energy": energy})

    def result(self) -> Measurement:
        found = self.value_at()
        if found is None:
            return _missing(self.expectation, f"the run ended before t = {self.expectation.time} s")
        energy, where = float(found[0]), found[1]
        return _scalar(self.expectation, energy, self.expectation.value, f"{where}: {energy:.6g} J")


def _articulation(tree: JointTree, joint: Joint) -> np.ndarray:
    """The bodies joined to ``joint``'s child through joints (their root's subtree): an impulse
    on any of them moves the joint."""
    child_of = {j.child: k for k, j in enumerate(tree.joints)}
    root = tree.joints.index(joint)
    while tree.joints[root].parent in child_of:
        root = child_of[tree.joints[root].parent]
    return np.flatnonzero(tree.subtree[root])


class _OfJoint:
    """A tracker whose subject is a joint (``schema.JOINT_EXPECTATION_MODELS``): it reads the
    joint's coordinate from the observed poses of its two bodies
    (``articulated.joint_coordinates``), continuous over the run (a hinge's angle unwrapped
    from batch to batch too), and watches the contacts of every body of its articulation."""

    def _locate(self) -> None:
        tree = self.scene.joint_tree
        self.joint = next(j for j in tree.joints if j.name == self.expectation.joint)
        self.body, self.watched = self.joint.child, _articulation(tree, self.joint)
        self.last_coordinate: np.ndarray | None = None

    def coordinate(self, states: Trajectory) -> np.ndarray:
        """(s,) rad or m, or (s, 3) rad for a ball: the joint's coordinate at ``states``."""
        found = joint_coordinates(self.scene.joint_tree, states.pos, quat_to_matrix(states.quat))
        values = found[self.joint.name]
        if self.joint.type == "hinge" and self.last_coordinate is not None:
            turns = np.round((self.last_coordinate - values[0]) / (2 * math.pi))
            values = values + 2 * math.pi * turns
        self.last_coordinate = values[-1]
        return values


@dataclass
class JointPositionAt(_OfJoint, StateAt):
    """The joint's coordinate at ``time`` (the observed state there, or between the states
    around it the cubic through four of them, ``validation.measure.interpolation``; never across
    a contact change of its articulation): a hinge's or slider's a number (``_scalar``), a
    ball's rotation vector (``_vector``)."""

    quantity: str = "coordinate"

    def update(self, states: Trajectory, events) -> None:
        if self.after_t.size >= self.side or len(states) == 0:
            return
        self._bracket(states.t, {"coordinate": self.coordinate(states)})

    def result(self) -> Measurement:
        found = self.value_at()
        if found is None:
            return _missing(self.expectation, f"the run ended before t = {self.expectation.time} s")
        value, where = found
        if np.ndim(value):
            return _vector(self.expectation, np.asarray(value), where)
        unit = "m" if self.joint.type == "slider" else "rad"
        message = f"{where}: {float(value):.6g} {unit}"
        return _scalar(self.expectation, float(value), self.expectation.value, message)


@dataclass
class Period(_OfJoint, _Tracker):
    """Mean time between successive upward crossings of the joint's coordinate about its mean
    over the run, each crossing placed by linear interpolation inside the step that makes it
    (``upward_crossings``). The mean is known only at the end: this tracker keeps the
    coordinate of every counted state (two float64 a state, the time and the coordinate)."""

    t: list[np.ndarray] = field(default_factory=list)
    values: list[np.ndarray] = field(default_factory=list)

    def update(self, states: Trajectory, events) -> None:
        if len(states):
            self.t.append(np.asarray(states.t, dtype=float))
            self.values.append(self.coordinate(states))

    def result(self) -> Measurement:
        t = np.concatenate(self.t) if self.t else np.zeros(0)
        values = np.concatenate(self.values) if self.values else np.zeros(0)
        self.t, self.values = [t], [values]  # the batches' arrays freed
        mean = float(values.mean()) if values.size else math.nan
        crossings = upward_crossings(t, values - mean)
        if crossings.size < 2:
            message = (
                f"{crossings.size} upward crossing(s) of the coordinate about its mean "
                f"{mean:.6g}; a period needs two"
            )
            return _missing(self.expectation, message)
        period = float(np.diff(crossings).mean())
        message = (
            f"{crossings.size} upward crossings about the mean {mean:.6g}, from t = "
            f"{crossings[0]:.6g} to {crossings[-1]:.6g} s: mean interval {period:.6g} s"
        )
        return _scalar(self.expectation, period, self.expectation.value, message)


def upward_crossings(t: np.ndarray, values: np.ndarray) -> np.ndarray:
    """(c,) s: the times at which ``values (s,)`` at times ``t (s,)`` cross 0 upwards (from
    below 0 to 0 or above), each linearly interpolated inside its step."""
    k = np.flatnonzero((values[:-1] < 0.0) & (values[1:] >= 0.0))
    fraction = values[k] / (values[k] - values[k + 1])
    return t[k] + fraction * (t[k + 1] - t[k])


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
        message = f"times {np.round(got, 5).tolist()} s"
        return _scalar(self.expectation, got[worst], wanted[worst], message)


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
    "joint_position_at": JointPositionAt,
    "period": Period,
}
"""Expectation kind -> its tracker (metric ``<kind>.<body>`` or ``<kind>.<joint>``, or the
expectation's ``name``)."""


def trackers(scene: CompiledScene) -> list[_Tracker]:
    """A tracker for each of the scene's expectations, in the scene's order."""
    return [TRACKERS[e.kind](scene, e) for e in scene.scenario.expect]
