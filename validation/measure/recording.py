"""Recording a run: a sampled ``Trajectory`` and the impact events, the same way for every engine.

Impacts are found from the observed states alone, never from an engine's own contact
reports, so that restitution is measured identically in every engine: the scene's shapes are
placed at the observed poses and the reference side's contact finder
(``validation.reference.contacts``, sharing no code with any engine) says which pairs touch
and how deep. A pair that starts touching opens an event; its relative normal velocity
*before* is taken from the last observed state before the touch, its
velocity *after* from the first observed state after the shapes separate again. Pairs still
touching at the end (resting contacts) give no event.

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

Measuring once, batched: observed states are collected in batches; the contacts of a whole
batch come from one call of the finder (``CompiledScene.contacts``) and serve impact
detection, the overlap check and ``penetration_max`` alike. The stability checks judge each
batch as it completes, and the run stops at its first failing state, as if it had been
checked state by state.

The detector keeps only the impacts still open; each closed one goes to the run's
``ImpactLog`` (``validation.measure.impact_log``), which counts every impact and keeps a
bounded set of records (all of them up to ``MAX_SAMPLED_IMPACTS``), and to the expectations.
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field

import numpy as np

from validation.engines.base import EngineAdapter, Snapshot, StoppedEarlyError
from validation.engines.parity import check_observation
from validation.measure.definitions import MAX_KEPT_POSITIONS
from validation.measure.expectations import trackers
from validation.measure.impact_log import ImpactEvent, ImpactLog
from validation.measure.measurement import Measurement
from validation.measure.stability import StabilityChecks
from validation.measure.states import Series, Trajectory, extreme_samples, invariants
from validation.reference.contacts import Found
from validation.reference.rotation import cross
from validation.scenario.compiled import CompiledScene
from validation.scenario.definability import scene_traits, why_undefined
from validation.scenario.physics import GROUND

DETECTION_GAP = 1e-6
"""m. Shapes closer than this count as touching (the contact margin), so a body
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

BATCH_OBSERVATIONS = 256
"""Observed states measured together. Large enough that the per-batch NumPy calls cost far
less than the states' own observation; small enough that a run that explodes mid-batch is
stopped within a few hundred steps of its first failing state."""

BATCH_BODY_STATES = BATCH_OBSERVATIONS * 1024
"""Body states (one body at one observed state) measured together at most: a batch holds
``BATCH_OBSERVATIONS`` states of scenes up to 1,024 bodies (every scene of the library) and
fewer of larger ones, so that a batch's arrays (13 numbers per body state, and the few copies
the impact detector makes) stay near 30 MB whatever the scene: 25 states of 10,000 bodies."""

CONTEXT_OBSERVATIONS = 2
"""States of the previous batch kept for the next one: the state before a touch (the velocity
before) and the one before that (the approach acceleration)."""


@dataclass
class _OpenImpact:
    key: tuple[int, int]
    order: int
    """Opening sequence number: events closing at one observation keep the order they opened in."""
    start: float
    normal: np.ndarray
    arm_a: np.ndarray
    """(3,) m, world frame: contact point minus A's centre at first contact."""
    arm_b: np.ndarray
    times: list[float]
    speeds: list[float]
    """(time s, relative normal velocity m/s) from the last observation before contact on."""
    accel: float = 0.0
    """m/s², relative normal acceleration before contact (what acts besides the impulse)."""
    body_accelerations: tuple | None = None
    """Each body's observed (linear, angular) acceleration before contact, (3,) each, world
    frame: ``(a_A, a_B, α_A, α_B)``; None when not observed (``ImpactEvent``)."""


@dataclass(frozen=True)
class _Touching:
    """The deepest contact of each touching (state, pair) of a batch, sorted by (state, pair).

    Attributes:
        observation: (r,) int. key: (r,) int pair code ``a * N + b``. point, normal: (r, 3).
        depth: (r,) m.

    Orders that decide ties (events closing at one state, the deepest pair of a state) go by
    pair code, never by detection order, so they do not depend on how states are batched.
    """

    observation: np.ndarray
    key: np.ndarray
    point: np.ndarray
    normal: np.ndarray
    depth: np.ndarray


def _touching(contacts: Found, bodies: int) -> _Touching:
    """A batch's contacts by pair code: the finder gives the deepest contact of each touching
    (state, pair), already in (state, pair) order."""
    return _Touching(
        contacts.observation,
        contacts.body_a * bodies + contacts.body_b,
        contacts.point,
        contacts.normal,
        contacts.depth,
    )


@dataclass
class ImpactDetector:
    """Finds impacts in batches of observed states of one scene (any engine)."""

    scene: CompiledScene
    new_events: list[ImpactEvent] = field(default_factory=list)
    """The impacts the last ``update`` closed, in closing order (the run's ``ImpactLog``
    keeps what it needs of them: the detector keeps none)."""

    def __post_init__(self) -> None:
        self.bodies = self.scene.shape_count
        # each shape's free acceleration g + F/m (zero for fixed bodies and the ground)
        self.body_acceleration = np.zeros((self.bodies, 3))
        self.body_acceleration[: self.scene.count] = self.scene.acceleration
        self.open: dict[tuple[int, int], _OpenImpact] = {}
        self.opened = 0
        self.context: Trajectory | None = None
        self.context_touching: np.ndarray = np.zeros(0, dtype=np.int64)
        self.closed: list[tuple[float, int, ImpactEvent]] = []

    def update(self, states: Trajectory, touching: _Touching, last: int | None = None) -> None:
        """Feed a batch of consecutive observed states (every step while the scene can touch)
        and its touching pairs; only states up to ``last`` (inclusive) count when given."""
        if last is not None:
            states = states.take(slice(0, last + 1))
            keep = touching.observation <= last
            touching = _Touching(
                *(getattr(touching, f)[keep] for f in _Touching.__dataclass_fields__)
            )
        offset = 0 if self.context is None else len(self.context)
        ext = states if self.context is None else Trajectory.concat(self.context, states)
        codes_all = np.concatenate(
            [
                self.context_touching - self.bodies**2,
                touching.observation * self.bodies**2 + touching.key,
            ]
        )
        codes_all.sort()
        per_state = self.bodies * self.bodies

        def touching_at(obs: np.ndarray, key) -> np.ndarray:
            return _member(obs * per_state + key, codes_all)

        new = ~touching_at(touching.observation - 1, touching.key)
        new &= (touching.observation + offset) >= 1  # a state before the touch was observed
        kinematics = self._with_ground(ext)
        opens = self._approaching(kinematics, offset, touching, np.flatnonzero(new))
        count = len(states)
        for impact in list(self.open.values()):
            self._follow(kinematics, offset, impact, 0, count, touching_at)
        for obs, impact in opens:
            if impact.key in self.open:
                continue  # still in contact from an impact that has not closed: no new touch
            self.open[impact.key] = impact
            self._follow(kinematics, offset, impact, obs, count, touching_at)
        self.closed.sort(key=lambda item: (item[0], item[1]))
        self.new_events = [event for _, _, event in self.closed]
        self.closed = []
        self.context = ext.take(slice(len(ext) - min(CONTEXT_OBSERVATIONS, len(ext)), None))
        last_keys = touching.key[touching.observation == count - 1]
        self.context_touching = np.unique(last_keys)

    def _approaching(
        self, ext: Trajectory, offset: int, touching: _Touching, rows: np.ndarray
    ) -> list[tuple[int, _OpenImpact]]:
        """The impacts the new touches ``rows`` open: those approaching faster than
        ``IMPACT_MIN_SPEED`` at the state before (all rows judged at once), in (state, pair)
        order, each with the batch state it opens at."""
        obs = touching.observation[rows] + offset
        a, b = np.divmod(touching.key[rows], self.bodies)
        point, normal = touching.point[rows], touching.normal[rows]
        arm_a, arm_b = point - ext.pos[obs, a], point - ext.pos[obs, b]
        before = self._relative_normal_velocity(ext, obs - 1, a, b, normal, arm_a, arm_b)
        approaching = np.flatnonzero(before < -IMPACT_MIN_SPEED)
        earlier = np.maximum(obs - 2, 0)
        gap = ext.t[obs - 1] - ext.t[earlier]
        measured = (obs >= 2) & (gap > 0)
        previous = self._relative_normal_velocity(ext, earlier, a, b, normal, arm_a, arm_b)
        free = np.einsum("ci,ci->c", self.body_acceleration[b] - self.body_acceleration[a], normal)
        with np.errstate(divide="ignore", invalid="ignore"):
            # without two earlier observations: free flight of both bodies, (a_B - a_A)·n
            accel = np.where(measured, (before - previous) / np.where(measured, gap, 1.0), free)
        bodies = self._observed_accelerations(ext, obs, earlier, gap, a, b)
        opens = []
        for k in approaching:
            self.opened += 1
            impact = _OpenImpact(
                (int(a[k]), int(b[k])),
                self.opened,
                float(ext.t[obs[k]]),
                normal[k],
                arm_a[k],
                arm_b[k],
                [float(ext.t[obs[k] - 1])],
                [float(before[k])],
                float(accel[k]),
                tuple(tuple(float(x) for x in v[k]) for v in bodies) if measured[k] else None,
            )
            opens.append((int(obs[k]) - offset, impact))
        return opens

    @staticmethod
    def _observed_accelerations(ext, obs, earlier, gap, a, b) -> tuple[np.ndarray, ...]:
        """``(a_A, a_B, α_A, α_B)``, each (c, 3) world frame: the bodies' linear (m/s²) and
        angular (rad/s²) accelerations over the observed step before contact ``c`` (from
        ``earlier[c]`` to ``obs[c] - 1``; rows without that step are garbage, masked by the
        caller)."""
        step = np.where(gap > 0, gap, 1.0)[:, None]
        return tuple(
            (values[obs - 1, body] - values[earlier, body]) / step
            for values in (ext.vel, ext.ang_vel)
            for body in (a, b)
        )

    def _with_ground(self, states: Trajectory) -> Trajectory:
        """``states`` with the ground appended as a body (its pose, at rest), so shape
        indices index every array."""
        extra = self.bodies - self.scene.count
        samples = len(states)

        def padded(values: np.ndarray, rest: np.ndarray) -> np.ndarray:
            ground = np.broadcast_to(rest, (samples, *rest.shape))
            return np.concatenate([values, ground], axis=1)

        count = self.scene.count
        at_rest = np.zeros((extra, 3))
        return Trajectory(
            states.t,
            padded(states.pos, self.scene.rest_pos[count:]),
            padded(states.quat, self.scene.rest_quat[count:]),
            padded(states.vel, at_rest),
            padded(states.ang_vel, at_rest),
        )

    def _relative_normal_velocity(self, ext, obs, a, b, normal, arm_a, arm_b) -> np.ndarray:
        """(c,) m/s, ``(v_PB - v_PA)·n`` of contact ``c`` at state ``obs[c]`` (the ground at
        rest), arms and normal frozen at first contact: every observation of one impact is
        measured along the impulse's own direction (for spinning spheres the arms stay on the
        line of centres: ω × r adds nothing)."""
        v_a = ext.vel[obs, a] + cross(ext.ang_vel[obs, a], arm_a)
        v_b = ext.vel[obs, b] + cross(ext.ang_vel[obs, b], arm_b)
        return np.einsum("ci,ci->c", v_b - v_a, normal)

    def _follow(
        self, ext, offset, impact: _OpenImpact, first: int, count: int, touching_at
    ) -> None:
        """Extend ``impact`` over batch states ``first..count-1``; close it where the shapes
        separate or stay together at rest (plastic)."""
        if first >= count:
            return
        obs = np.arange(first, count)
        code = impact.key[0] * self.bodies + impact.key[1]
        a, b = (np.full(obs.size, body) for body in impact.key)
        frozen = (
            np.broadcast_to(v, (obs.size, 3)) for v in (impact.normal, impact.arm_a, impact.arm_b)
        )
        speeds = self._relative_normal_velocity(ext, obs + offset, a, b, *frozen)
        separated = ~touching_at(obs, code)
        history = np.concatenate([impact.speeds, speeds])
        slow = np.abs(history) <= IMPACT_MIN_SPEED
        position = np.arange(len(impact.speeds), history.size)  # history index of each state
        stuck = np.zeros(obs.size, dtype=bool)
        window = position >= PLASTIC_OBSERVATIONS  # more than three entries in the history
        if window.any():
            p = position[window]
            stuck[window] = slow[p] & slow[p - 1] & slow[p - 2]
        ends = np.flatnonzero(separated | stuck)
        if ends.size == 0:
            impact.times += ext.t[obs + offset].tolist()
            impact.speeds += speeds.tolist()
            return
        end = int(ends[0])
        impact.times += ext.t[obs[: end + 1] + offset].tolist()
        impact.speeds += speeds[: end + 1].tolist()
        del self.open[impact.key]
        close_time = float(ext.t[obs[end] + offset])
        event = self._event(impact, close_time, bool(separated[end]))
        if event is not None:
            self.closed.append((close_time, impact.order, event))

    def _event(self, impact: _OpenImpact, end: float, separated: bool) -> ImpactEvent | None:
        """The impact with both velocities carried to the impulse centroid (module docstring).

        ``separated``: the shapes came apart (a bounce); otherwise they stayed together
        with no relative normal motion (a plastic impact, e = 0).
        """
        times, speeds = np.array(impact.times), np.array(impact.speeds)
        if not separated:  # plastic: the impulse ends at the first observation at rest; the
            # resting steps after it are the support cancelling gravity, not the impact
            rest = np.flatnonzero(speeds[1:] >= -IMPACT_MIN_SPEED)
            stop = rest[0] + 2 if rest.size else speeds.size
            times, speeds = times[:stop], speeds[:stop]
        accel = impact.accel
        pushed = np.diff(speeds) - accel * np.diff(times)  # non-gravity change per step
        if pushed.sum() <= 0.0:
            return None
        centroid = float(np.sum(pushed * times[1:]) / pushed.sum())
        after = float(speeds[-1] - accel * (times[-1] - centroid))
        too_slow = after < max(IMPACT_MIN_SPEED, abs(accel) * float(np.min(np.diff(times))))
        if separated and too_slow:
            return None  # too slow to leave within one step against gravity: settling, not a bounce
        names = self.scene.body_name
        a, b = impact.key
        return ImpactEvent(
            body_a=names[a] if a < self.scene.count else GROUND,
            body_b=names[b] if b < self.scene.count else GROUND,
            time_start=impact.start,
            time_end=end,
            time_impulse=centroid,
            normal=tuple(float(x) for x in impact.normal),
            normal_velocity_before=float(speeds[0] + accel * (centroid - times[0])),
            normal_velocity_after=after,
            approach_acceleration=float(accel),
            step=float(np.min(np.diff(times))),
            **_body_accelerations(impact.body_accelerations),
        )


def _body_accelerations(found: tuple | None) -> dict:
    """``ImpactEvent``'s per-body acceleration fields from ``_OpenImpact.body_accelerations``."""
    names = ("acceleration_a", "acceleration_b", "angular_acceleration_a", "angular_acceleration_b")
    return dict.fromkeys(names) if found is None else dict(zip(names, found, strict=True))


def _member(values: np.ndarray, sorted_codes: np.ndarray) -> np.ndarray:
    """(k,) bool: which ``values`` occur in the sorted array ``sorted_codes``."""
    if sorted_codes.size == 0:
        return np.zeros(values.shape, dtype=bool)
    index = np.minimum(np.searchsorted(sorted_codes, values), sorted_codes.size - 1)
    return sorted_codes[index] == values


def batch_size(scene: CompiledScene) -> int:
    """Observed states measured together for ``scene`` (``BATCH_BODY_STATES``)."""
    return max(1, min(BATCH_OBSERVATIONS, BATCH_BODY_STATES // max(scene.count, 1)))


def kept_samples(steps: int, sample_every: int) -> int:
    """How many samples a complete run of ``steps`` steps keeps: every ``sample_every``-th
    state from the first, and the last."""
    return steps // sample_every + 1 + (steps % sample_every != 0)


def position_stride(scene: CompiledScene, sample_every: int) -> int:
    """Every how many kept samples a run that keeps positions only keeps one
    (``MAX_KEPT_POSITIONS``); 1 when all fit."""
    numbers = kept_samples(scene.scenario.steps, sample_every) * scene.count * 3
    return max(1, -(-numbers // MAX_KEPT_POSITIONS))


KEEP = ("states", "positions")
"""What a recording's trajectory holds: every kept sample's whole state (``states``: the
sweeps, the tests), or only the positions at every ``position_stride``-th kept sample, what
``divergence`` compares across engines (``positions``: ``physval run``)."""


@dataclass
class Recording:
    """What one engine run produced."""

    trajectory: Trajectory
    """The kept states (``KEEP``)."""
    impacts: list[ImpactEvent]
    """The kept impacts in closing order (``impact_log``: every one up to
    ``MAX_SAMPLED_IMPACTS``, beyond an evenly spaced sample and the worst)."""
    stepping_seconds: float
    """Wall time spent inside the engine's ``advance`` alone (observation excluded)."""
    series: Series
    """Energy, momenta and the metrics' per-sample reductions at every kept sample (computed
    as the run goes, for plots)."""
    expectations: list[Measurement] = field(default_factory=list)
    """The scene's expectations, evaluated online over every observed state (``expectations``)."""
    penetration_max: float | None = None
    """m, the deepest overlap over every observed state (None when nothing can touch)."""
    unstable: str | None = None
    """Why the run failed (``kind: detail``, kinds in ``stability.KINDS``), or None."""
    impact_count: int = 0
    """Every impact the run had, kept in ``impacts`` or not."""
    extremes: Series | None = None
    """The samples the metrics read, from every counted state of the run
    (``states.extreme_samples``: the first, the last and each per-sample maximum); None in a
    recording made by hand, whose metrics then read ``series``."""


@dataclass
class _Measurer:
    """Measures the observed states of one run batch by batch: stability checks, contacts,
    impacts and the deepest overlap; the series at the kept samples, and the kept states
    (``KEEP``)."""

    scene: CompiledScene
    sample_every: int
    keep: str = "states"
    checks: StabilityChecks = field(init=False)
    detector: ImpactDetector = field(init=False)
    impacts: ImpactLog = field(init=False)
    samples: list[Trajectory] = field(default_factory=list)
    series: list[Series] = field(default_factory=list)
    kept: int = 0
    """Samples kept so far (the series' length)."""
    extremes: Series | None = None
    """Every counted state so far, reduced to what the metrics read (``extreme_samples``)."""
    touching_before: np.ndarray | None = None
    """Pair codes touching at the last counted state of the previous batch (None before the
    first batch): the contact changes of a batch's first step."""
    changed_before: np.ndarray | None = None
    """(n,) bool, which bodies' contacts changed at the previous batch's last counted state."""
    penetration: float = 0.0
    failure: str | None = None
    last_time: float = 0.0
    """s, the last state that counted."""

    def __post_init__(self) -> None:
        self.checks = StabilityChecks(self.scene)
        self.detector = ImpactDetector(self.scene)
        self.impacts = ImpactLog(self.scene)
        self.trackers = trackers(self.scene)
        traits = scene_traits(self.scene)
        self.free = why_undefined("position_error", traits) is None
        self.states = self.keep == "states"
        self.stride = 1 if self.states else position_stride(self.scene, self.sample_every)

    def recording(self, stepping_seconds: float) -> Recording:
        """What was measured, as the run's ``Recording``."""
        return Recording(
            trajectory=Trajectory.concat(*self.samples),
            impacts=self.impacts.events(),
            stepping_seconds=stepping_seconds,
            series=Series.concat(*self.series),
            expectations=[tracker.result() for tracker in self.trackers],
            penetration_max=self.penetration if self.scene.can_touch else None,
            unstable=self.failure,
            impact_count=self.impacts.count,
            extremes=self.extremes,
        )

    def measure(self, states: Trajectory, steps, final: int) -> bool:
        """Judge and measure a batch of consecutive states observed after ``steps`` steps;
        False once a state has failed (the run must stop; later states are not kept)."""
        check_observation(states, self.scene.count)
        step_index = np.asarray(steps)
        deepest = radius = touching = None
        if self.scene.can_touch:
            finite = np.isfinite(states.pos).reshape(len(states), -1).all(axis=1)
            finite &= np.isfinite(states.quat).reshape(len(states), -1).all(axis=1)
            usable = len(states) if finite.all() else int(np.argmin(finite))
            contacts = self.scene.contacts(states.pos[:usable], states.quat[:usable], DETECTION_GAP)
            touching = _touching(contacts, self.scene.shape_count)
            deepest, radius = _deepest_per_state(self.scene, touching, len(states))
        found = self.checks.first_failure(states, deepest, radius)
        if found is None:  # geometric growth, judged on the windows finished so far
            growth = self.checks.growth_failure(float(states.t[-1]))
            found = None if growth is None else (len(states) - 1, growth)
        last = len(states) - 1 if found is None else found[0]
        # the states that count: up to the failing one (included when only the overlap failed:
        # its pose was measured before the check)
        counted = last if found is None or found[1].startswith("deep_penetration") else last - 1
        new_events: list[ImpactEvent] = []
        if touching is not None and counted >= 0:
            self.detector.update(states, touching, counted)
            self.penetration = max(self.penetration, float(deepest[: counted + 1].max(initial=0.0)))
            new_events = self.detector.new_events
        self.impacts.add(new_events)
        judged = states.take(slice(0, counted + 1))
        changes = self._contact_steps(touching, counted + 1)
        for tracker in self.trackers:
            tracker.contact_steps(judged.t, changes[:, tracker.watched].any(axis=1))
            tracker.update(judged, new_events)
        keep = (step_index % self.sample_every == 0) | (step_index == final)
        if found is not None:
            self.failure = found[1]
            keep[last + 1 :] = False
            keep[last] = not self.failure.startswith(
                "non_finite"
            )  # a non-finite state is named, not kept
        series = invariants(self.scene, states.take(slice(0, last + 1)), self.free)
        # the metrics read what the series keeps of the run: every counted state, and the
        # failing state where it is kept (a finite one that failed a check)
        self._fold(series.take(slice(0, last + 1 if keep[last] else counted + 1)))
        self._keep(
            states.take(np.flatnonzero(keep)),
            series.take(np.flatnonzero(keep)),
            step_index[keep] == final,
        )
        if counted >= 0:
            self.last_time = float(states.t[counted])
        return found is None

    def _fold(self, counted: Series) -> None:
        """Reduce every counted state to the samples the metrics read (``extreme_samples``):
        the metrics are maxima over every step, whatever the kept series thins."""
        if counted.t.size == 0:
            return
        whole = counted if self.extremes is None else Series.concat(self.extremes, counted)
        self.extremes = extreme_samples(self.scene, whole)

    def _contact_steps(self, touching: _Touching | None, count: int) -> np.ndarray:
        """(count, n) bool: for each of the scene's bodies, whether the observed step that ends
        at each of the batch's first ``count`` states begins or ends at a state where the
        body's contacts changed (it started or stopped touching a body or the ground): the
        steps an impulse can act in, which no interpolant may span (``expectations.StateAt``).
        Both sides of the change, because engines differ in where the impulse falls: one that
        keeps shapes apart (speculative contacts) acts over the step into the first touching
        state, one that resolves an overlap (mini, MuJoCo) over the step out of it; contacts
        that stay unchanged over a step (resting, a soft contact's inside) are smooth enough."""
        changed = self._contact_changes(touching, count)
        before = self.changed_before
        if before is None or count == 0:
            before = np.zeros(changed.shape[1], dtype=bool)
        steps = changed | np.concatenate([before[None], changed[:-1]])
        if count:
            self.changed_before = changed[-1]
        return steps

    def _contact_changes(self, touching: _Touching | None, count: int) -> np.ndarray:
        """(count, n) bool: which of the scene's bodies touch a different set of bodies (the
        ground one of them) at each of the batch's first ``count`` states than at the state
        before; none at the run's first state (no state before it)."""
        changed = np.zeros((count, self.scene.shape_count), dtype=bool)
        if touching is None or count == 0:
            return changed[:, : self.scene.count]
        per_state = self.scene.shape_count**2
        rows = touching.observation < count
        obs, key = touching.observation[rows], touching.key[rows]
        before = (
            np.zeros(0, dtype=np.int64) if self.touching_before is None else self.touching_before
        )
        codes = np.sort(np.concatenate([before - per_state, obs * per_state + key]))
        started = ~_member((obs - 1) * per_state + key, codes) & (
            (obs > 0) | (self.touching_before is not None)
        )
        ended_obs = np.concatenate([np.full(before.size, -1), obs])
        ended_key = np.concatenate([before, key])
        ended = ~_member((ended_obs + 1) * per_state + ended_key, codes) & (ended_obs + 1 < count)
        for at, pair in ((obs[started], key[started]), (ended_obs[ended] + 1, ended_key[ended])):
            a, b = np.divmod(pair, self.scene.shape_count)
            changed[at, a] = True
            changed[at, b] = True
        self.touching_before = np.unique(key[obs == count - 1])
        return changed[:, : self.scene.count]

    def _keep(self, kept: Trajectory, series: Series, last: np.ndarray) -> None:
        """The series at the batch's kept samples, and the states ``KEEP`` says (``last``:
        which of them is the run's final state). One object per kept batch, not per batch (a
        2,000,000-step run keeps 5,000 samples from 7,813 batches), and at least one."""
        if len(kept) == 0 and self.series:
            return
        self.series.append(series)
        ordinal = self.kept + np.arange(len(kept))
        self.kept += len(kept)
        if self.states:
            self.samples.append(kept)
            return
        chosen = np.flatnonzero((ordinal % self.stride == 0) | last)
        if chosen.size or not self.samples:
            self.samples.append(_positions_only(kept.take(chosen)))


def _positions_only(states: Trajectory) -> Trajectory:
    """``states`` with their times and positions, orientations and velocities dropped (zero
    width): 3 of the 13 numbers per body and state, all that divergence compares."""
    return Trajectory(
        states.t, states.pos, states.quat[..., :0], states.vel[..., :0], states.ang_vel[..., :0]
    )


def _deepest_per_state(scene: CompiledScene, touching: _Touching, count: int):
    """(count,) deepest overlap m (>= 0) of each state and (count,) the smaller bounding radius
    of that pair's shapes about their own centres (``contacts.Shapes.shape_radius``: a shape
    placed off its body's centre of mass is as large as itself), inf where nothing touches;
    ties go to the lower pair code."""
    deepest = np.zeros(count)
    radius = np.full(count, np.inf)
    if touching.key.size:
        order = np.lexsort((touching.key, -touching.depth, touching.observation))
        obs = touching.observation[order]
        first = np.ones(order.size, dtype=bool)
        first[1:] = obs[1:] != obs[:-1]
        pick = order[first]
        a, b = np.divmod(touching.key[pick], scene.shape_count)
        deepest[touching.observation[pick]] = np.maximum(touching.depth[pick], 0.0)
        size = scene.shapes.shape_radius
        radius[touching.observation[pick]] = np.minimum(size[a], size[b])
    return deepest, radius


def record(
    adapter: EngineAdapter, scene: CompiledScene, sample_every: int = 1, keep: str = "states"
) -> Recording:
    """Run the loaded ``adapter`` for the scene's duration; keep every ``sample_every``-th state.

    Every state is observed and measured (impacts, stability, expectations, full time
    resolution); only the kept samples make the series (metrics and plots) and, as ``keep``
    says (``KEEP``), the trajectory. Adapters that
    observe a batch of steps at the cost of a copy (``advance_observed``: MuJoCo, PyBullet)
    do so; the others are observed after each step. The stability taxonomy judges a batch at
    a time; the first failing state ends the run (``Recording.unstable`` names its kind).
    """
    measurer = _Measurer(scene, sample_every, keep)
    steps_total = scene.scenario.steps
    if hasattr(adapter, "advance_observed"):
        stepping = _batched(adapter, measurer, steps_total)
    else:
        stepping = _stepwise(adapter, measurer, steps_total)
    if measurer.failure is None:  # the last windows of the energy error's envelope
        measurer.failure = measurer.checks.growth_failure(measurer.last_time, complete=True)
    warnings = getattr(adapter, "instability_warnings", list)()
    if measurer.failure is None and warnings:
        measurer.failure = "engine_warning: " + "; ".join(warnings)
    return measurer.recording(stepping)


def _stepwise(adapter: EngineAdapter, measurer: _Measurer, steps_total: int) -> float:
    """Advance one step at a time, observing after each; measure a batch at a time; stop at
    the first failing state. Returns the seconds spent in ``advance``."""
    batch, steps = [adapter.observe()], [0]
    size = batch_size(measurer.scene)
    stepping = 0.0
    done = 0
    running = True
    while done < steps_total and running:
        start = time.perf_counter()
        try:
            adapter.advance(1)
        except Exception:
            if not batch or measurer.measure(Trajectory.stack(batch), steps, steps_total):
                raise  # the engine failed on states that all passed the checks
            return stepping  # an earlier state had already failed: that is the finding
        stepping += time.perf_counter() - start
        done += 1
        snap = adapter.observe()
        batch.append(snap)
        steps.append(done)
        if len(batch) >= size or done == steps_total or not _finite(snap):
            running = measurer.measure(Trajectory.stack(batch), steps, steps_total)
            batch, steps = [], []
    if batch:
        measurer.measure(Trajectory.stack(batch), steps, steps_total)
    return stepping


def _batched(adapter: EngineAdapter, measurer: _Measurer, steps_total: int) -> float:
    """Every state observed by the adapter's own ``advance_observed``, a batch at a time:
    the same batches as ``_stepwise`` (the start with the first steps, then ``batch_size``
    states), so that running sums over the states (``PrecessionRate``) do not depend on the
    path. Returns the seconds spent in it (stepping and the raw copies). A batch may end
    early at the state where the engine refused to go on (non-finite: ``EngineAdapter``),
    which then fails the checks; a short batch of finite states is an engine error."""
    first = adapter.observe()
    pending = Trajectory(
        np.array([first.time]),
        *(a[None] for a in (first.pos, first.quat, first.vel, first.ang_vel)),
    )  # observed, not yet measured: the start, measured with the first batch's steps
    size = batch_size(measurer.scene)
    stepping = 0.0
    done = 0
    chunk = min(max(size - 1, 1), steps_total)
    while chunk > 0:
        start = time.perf_counter()
        try:
            states = adapter.advance_observed(chunk)
        except StoppedEarlyError as stopped:
            stepping += time.perf_counter() - start
            batch = Trajectory.concat(pending, stopped.states)
            passed = not len(batch) or measurer.measure(
                batch, _batch_steps(done, batch, pending), steps_total
            )
            if passed:
                raise stopped.__cause__ from None  # the engine failed on states that passed
            return stepping  # an earlier state had already failed: that is the finding
        stepping += time.perf_counter() - start
        batch = Trajectory.concat(pending, states) if len(pending) else states
        steps = _batch_steps(done, batch, pending)
        pending = pending.take(slice(0, 0))
        if not measurer.measure(batch, steps, steps_total):
            break
        if len(states) < chunk:  # fewer than asked, all finite: not an explosion
            raise RuntimeError(
                f"the engine stopped after {done + len(states)} steps of {steps_total}"
            )
        done += chunk
        chunk = min(size, steps_total - done)
    if steps_total == 0:  # a scene of no steps: the start alone
        measurer.measure(pending, [0], steps_total)
    return stepping


def _batch_steps(done: int, batch: Trajectory, pending: Trajectory) -> np.ndarray:
    """The step numbers of ``batch``: ``pending`` states then the steps after ``done``."""
    return np.arange(done + 1 - len(pending), done + 1 - len(pending) + len(batch))


def measure_trajectory(scene: CompiledScene, states: Trajectory) -> Recording:
    """The recording of states already observed (consecutive, every one kept), measured as
    ``record`` measures a run, batch by batch."""
    measurer = _Measurer(scene, 1)
    size = batch_size(scene)
    for first in range(0, len(states), size):
        batch = states.take(slice(first, first + size))
        if not measurer.measure(batch, np.arange(first, first + len(batch)), len(states) - 1):
            break
    return measurer.recording(0.0)


def _finite(snap: Snapshot) -> bool:
    return bool(np.isfinite(snap.pos).all() and np.isfinite(snap.vel).all())
