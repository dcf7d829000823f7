"""Recording a run: a sampled ``Trajectory`` and the impact events, the same way for every engine.

Impacts are found from the observed states alone, never from an engine's own contact
reports, so that restitution is measured identically in mini_engine, MuJoCo and
PyBullet: after every step the scene's shapes are placed at the observed poses and
mini_engine's collision detection says which pairs touch. A pair that starts touching
opens an event; its relative normal velocity *before* is taken from the last observed
state before the touch, its velocity *after* from the first observed state after the
shapes separate again. Pairs still touching at the end (resting contacts) give no event.

Gravity keeps acting while the shapes touch (for a body-ground pair it changes the
relative normal velocity by g·dt each step: 5 % of a 0.4 m/s impact per ms). So the
velocities before and after are both carried to the same instant, the *impulse
centroid* t*: the mean of the step end times weighted by each step's change of the
relative normal velocity beyond the approach acceleration ``a``. Then
``before = v_pre + a (t* - t_pre)`` and ``after = v_post - a (t_post - t*)``. ``a`` is
measured from the two observations before contact (so a ball landing on a ball that
rests on the ground is carried by g, not by the free fall of both). For an engine that
resolves an impact within one semi-implicit step (mini_engine, MuJoCo Euler with the
one-step damper, PyBullet) this recovers exactly the velocities its solver saw; for soft
contacts lasting several steps it is the natural average. Arms and normal are frozen at
first contact, so every observation is measured along the impulse's own direction.
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field

import numpy as np

from mini_engine.collision import detect_contacts
from mini_engine.rotation import quat_to_matrix
from validation.engines.base import EngineAdapter, Snapshot
from validation.measure.stability import StabilityMonitor
from validation.scenario import Scenario
from validation.scenario.physics import GROUND, build_mini_model

DETECTION_GAP = 1e-6
"""m. Shapes closer than this count as touching (mini_engine's contact margin), so a body
resting on another does not flicker in and out of contact on round-off."""

IMPACT_MIN_SPEED = 1e-3
"""m/s. A touch approaching slower than this is a resting contact settling, not an impact:
no event. The library's slowest deliberate bounce approaches at about 0.05 m/s. A rebound
must also be faster than gravity's change of velocity in one step (|a|·dt), or the body
cannot leave the ground before it is pulled back: that too is settling."""


PLASTIC_OBSERVATIONS = 3
"""Consecutive observations in contact with |relative normal velocity| below
``IMPACT_MIN_SPEED`` that close an impact as plastic (e = 0) while the shapes still touch.
Three, so that a soft contact passing through zero relative speed mid-bounce is not cut."""


@dataclass(frozen=True)
class Trajectory:
    """Sampled states of the scene's bodies (s samples, n bodies, scenario order).

    Attributes:
        t: (s,) s. pos: (s, n, 3) m, world, centres of mass. quat: (s, n, 4) w x y z.
        vel: (s, n, 3) m/s, world. ang_vel: (s, n, 3) rad/s, world.
    """

    t: np.ndarray
    pos: np.ndarray
    quat: np.ndarray
    vel: np.ndarray
    ang_vel: np.ndarray

    @staticmethod
    def from_snapshots(snapshots: list[Snapshot]) -> Trajectory:
        return Trajectory(
            t=np.array([s.time for s in snapshots]),
            pos=np.stack([s.pos for s in snapshots]),
            quat=np.stack([s.quat for s in snapshots]),
            vel=np.stack([s.vel for s in snapshots]),
            ang_vel=np.stack([s.ang_vel for s in snapshots]),
        )


@dataclass(frozen=True)
class ImpactEvent:
    """One impact of two bodies (or a body and the ground).

    Attributes:
        body_a, body_b: names (``ground`` for the plane); the normal points from A to B.
        time_start: s, the first observation in contact. time_end: s, the first one apart
            (for a plastic impact, e = 0: the observation that closed it while still touching).
        normal: (3,) unit, world frame, at first contact.
        normal_velocity_before: m/s, ``(v_PB - v_PA)·n`` just before the impulse (< 0).
        normal_velocity_after: m/s, the same just after (both carried to the impulse centroid).
        time_impulse: s, the impulse centroid (for a one-step impulse: the end of that step).
    """

    body_a: str
    body_b: str
    time_start: float
    time_end: float
    time_impulse: float
    normal: tuple[float, float, float]
    normal_velocity_before: float
    normal_velocity_after: float

    @property
    def restitution(self) -> float:
        """Measured e = -(v_rel'·n)/(v_rel·n) (formulas.md section 5)."""
        return -self.normal_velocity_after / self.normal_velocity_before


@dataclass
class _OpenImpact:
    start: float
    normal: np.ndarray
    arm_a: np.ndarray
    """(3,) m, world frame: contact point minus A's centre at first contact."""
    arm_b: np.ndarray
    history: list[tuple[float, float]]
    """(time s, relative normal velocity m/s) from the last observation before contact on."""
    accel: float = 0.0
    """m/s², relative normal acceleration before contact (what acts besides the impulse)."""


@dataclass
class ImpactDetector:
    """Finds impacts in a sequence of snapshots of one scenario (any engine)."""

    scenario: Scenario
    events: list[ImpactEvent] = field(default_factory=list)

    def __post_init__(self) -> None:
        self.model, self.state = build_mini_model(self.scenario)
        self.count = len(self.scenario.bodies)
        self.can_touch = self.model.can_touch
        self.body_gravity = np.where(self.model.body_fixed[:, None], 0.0, self.model.gravity)
        self.open: dict[tuple[int, int], _OpenImpact] = {}
        self.previous: Snapshot | None = None
        self.before_previous: Snapshot | None = None
        self.deepest: tuple[float, float] = (0.0, float("inf"))
        self.previous_touching: dict = {}

    def _full(self, snap: Snapshot, name: str) -> np.ndarray:
        """Snapshot array for every model body (the ground keeps its initial value)."""
        full = getattr(self.state, name).copy()
        full[: self.count] = getattr(snap, name)
        if name in ("vel", "ang_vel"):
            full[self.count :] = 0.0
        return full

    def _touching(
        self, snap: Snapshot
    ) -> dict[tuple[int, int], tuple[np.ndarray, np.ndarray, float]]:
        """Pairs in contact: (a, b) -> (deepest point, normal A→B, depth)."""
        pos, quat = self._full(snap, "pos"), self._full(snap, "quat")
        contacts = detect_contacts(self.model, pos, quat_to_matrix(quat), DETECTION_GAP)
        found: dict[tuple[int, int], tuple[np.ndarray, np.ndarray, float]] = {}
        for a, b, point, normal, depth in zip(*contacts, strict=True):
            key = (int(a), int(b))
            if key not in found or depth > found[key][2]:
                found[key] = (point, normal, float(depth))
        return found

    def _normal_velocity(self, snap: Snapshot, key, impact: _OpenImpact) -> float:
        """(v_PB - v_PA)·n with the arms and normal frozen at first contact, so every
        observation of one impact is measured along the impulse's own direction (for
        spinning spheres the arms stay on the line of centres: ω × r adds nothing)."""
        vel, ang_vel = self._full(snap, "vel"), self._full(snap, "ang_vel")
        a, b = key
        v_a = vel[a] + np.cross(ang_vel[a], impact.arm_a)
        v_b = vel[b] + np.cross(ang_vel[b], impact.arm_b)
        return float((v_b - v_a) @ impact.normal)

    def _event(
        self, key: tuple[int, int], impact: _OpenImpact, end: float, separated: bool
    ) -> ImpactEvent | None:
        """The impact with both velocities carried to the impulse centroid (module docstring).

        ``separated``: the shapes came apart (a bounce); otherwise they stayed together
        with no relative normal motion (a plastic impact, e = 0).
        """
        times, speeds = np.array(impact.history).T
        if not separated:  # plastic: the impulse ends at the first observation at rest; the
            # resting steps after it are the support cancelling gravity, not the impact
            rest = np.flatnonzero(speeds[1:] >= -IMPACT_MIN_SPEED)
            end = rest[0] + 2 if rest.size else speeds.size
            times, speeds = times[:end], speeds[:end]
        accel = impact.accel
        pushed = np.diff(speeds) - accel * np.diff(times)  # non-gravity change per step
        if pushed.sum() <= 0.0:
            return None
        centroid = float(np.sum(pushed * times[1:]) / pushed.sum())
        after = float(speeds[-1] - accel * (times[-1] - centroid))
        too_slow = after < max(IMPACT_MIN_SPEED, abs(accel) * float(np.min(np.diff(times))))
        if separated and too_slow:
            return None  # too slow to leave within one step against gravity: settling, not a bounce
        names = self.model.body_name
        return ImpactEvent(
            body_a=names[key[0]] if key[0] < self.count else GROUND,
            body_b=names[key[1]] if key[1] < self.count else GROUND,
            time_start=impact.start,
            time_end=end,
            time_impulse=centroid,
            normal=tuple(float(x) for x in impact.normal),
            normal_velocity_before=float(speeds[0] + accel * (centroid - times[0])),
            normal_velocity_after=after,
        )

    def _deepest(self, touching) -> tuple[float, float]:
        """(deepest overlap m, smaller bounding radius m of that pair) in ``touching``."""
        if not touching:
            return 0.0, float("inf")
        (a, b), (_, _, depth) = max(touching.items(), key=lambda item: item[1][2])
        radius = min(self.model.body_bound_radius[a], self.model.body_bound_radius[b])
        return max(depth, 0.0), float(radius)

    def _approach_acceleration(self, key, impact: _OpenImpact, before: float) -> float:
        """Relative normal acceleration (m/s²) just before contact, from the two observations
        before it: whatever acts (gravity, a support under the other body, springs). Without
        two earlier observations: free fall of both bodies, (g_B - g_A)·n."""
        earlier = self.before_previous
        if earlier is not None and self.previous is not None and self.previous.time > earlier.time:
            return (before - self._normal_velocity(earlier, key, impact)) / (
                self.previous.time - earlier.time
            )
        gravity = self.body_gravity[key[1]] - self.body_gravity[key[0]]
        return float(gravity @ impact.normal)

    def _stuck(self, impact: _OpenImpact) -> bool:
        """Still touching, with no relative normal motion for ``PLASTIC_OBSERVATIONS``
        observations: the impulse is over and the bodies move together (e = 0)."""
        recent = [speed for _, speed in impact.history[-PLASTIC_OBSERVATIONS:]]
        return len(impact.history) > PLASTIC_OBSERVATIONS and all(
            abs(speed) <= IMPACT_MIN_SPEED for speed in recent
        )

    def update(self, snap: Snapshot) -> None:
        """Feed the next observed state (every step while the scene can touch)."""
        if not self.can_touch:
            return
        touching = self._touching(snap)
        self.deepest = self._deepest(touching)
        previous = self.previous
        pos = self._full(snap, "pos")
        for key, (point, normal, _) in touching.items():
            if key not in self.previous_touching and previous is not None and key not in self.open:
                impact = _OpenImpact(
                    snap.time, normal, point - pos[key[0]], point - pos[key[1]], []
                )
                before = self._normal_velocity(previous, key, impact)
                if before < -IMPACT_MIN_SPEED:
                    impact.history.append((previous.time, before))
                    impact.accel = self._approach_acceleration(key, impact, before)
                    self.open[key] = impact
        for key, impact in list(self.open.items()):
            impact.history.append((snap.time, self._normal_velocity(snap, key, impact)))
            separated = key not in touching
            if separated or self._stuck(impact):
                del self.open[key]
                event = self._event(key, impact, snap.time, separated)
                if event is not None:
                    self.events.append(event)
        self.before_previous, self.previous, self.previous_touching = self.previous, snap, touching


@dataclass
class Recording:
    """What one engine run produced."""

    trajectory: Trajectory
    impacts: list[ImpactEvent]
    stepping_seconds: float
    """Wall time spent inside the engine's ``advance`` alone (observation excluded)."""
    unstable: str | None = None
    """Why the run failed (``kind: detail``, kinds in ``stability.KINDS``), or None."""


def record(adapter: EngineAdapter, scenario: Scenario, sample_every: int = 1) -> Recording:
    """Run the loaded ``adapter`` for the scene's duration; sample every ``sample_every`` steps.

    Scenes that can touch are observed every step (for the impact detector); the others
    only at the samples, so a contact-free scene pays for nothing it does not need. Every
    observation goes through the stability taxonomy; the first failure ends the run
    (``Recording.unstable`` names its kind).
    """
    detector = ImpactDetector(scenario)
    monitor = StabilityMonitor(scenario)
    every_step = detector.can_touch
    first = adapter.observe()
    detector.update(first)
    samples = [first]
    stepping = 0.0
    done = 0
    failure = monitor.check(first)
    while done < scenario.steps and failure is None:
        chunk = 1 if every_step else min(sample_every, scenario.steps - done)
        start = time.perf_counter()
        adapter.advance(chunk)
        stepping += time.perf_counter() - start
        done += chunk
        if every_step or done % sample_every == 0 or done == scenario.steps:
            snap = adapter.observe()
            failure = monitor.check(snap)
            if failure is None:
                detector.update(snap)
                failure = monitor.check_overlap(*detector.deepest, snap.time)
            finite = not failure or not failure.startswith("non_finite")
            if finite and (
                failure is not None or done % sample_every == 0 or done == scenario.steps
            ):
                samples.append(snap)  # a non-finite state is named in the message, not kept
    warnings = getattr(adapter, "instability_warnings", list)()
    if failure is None and warnings:
        failure = "engine_warning: " + "; ".join(warnings)
    return Recording(Trajectory.from_snapshots(samples), detector.events, stepping, failure)
