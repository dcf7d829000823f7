"""Metrics: pure functions of one engine's recording of one scene, one definition each.

Every metric is a function in ``METRICS`` (or, for a scene's own expectations,
``EXPECTATIONS``) that returns a ``Measurement`` or ``None`` when the scene cannot
define it (no restitution without an impact, no ballistic error where bodies touch).
A ``None`` is left out of the report, never written as zero. The one-line definitions
the report prints are in ``validation.measure.definitions``.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass
from functools import cached_property

import numpy as np

from mini_engine.collision import detect_contacts
from mini_engine.rotation import quat_to_matrix
from validation.measure.recording import Recording
from validation.scenario import Scenario
from validation.scenario.physics import SceneEnergy, body_inertia, build_mini_model, pair_value

ZERO_SCALE = 1e-12
"""Below this magnitude (in the quantity's SI unit) an initial energy or momentum counts as
zero, and its drift is reported as an absolute difference instead of a relative one."""


@dataclass(frozen=True)
class Measurement:
    """A metric's value and what it was compared against.

    ``error`` is the number a tolerance applies to; ``expected_kind`` is ``analytic``,
    ``conserved`` or ``engine:<spec>``.
    """

    metric: str
    value: float
    expected: float | None
    expected_kind: str
    error: float
    message: str = ""


@dataclass
class Series:
    """Invariants over the samples of a recording (s samples).

    Attributes:
        t: (s,) s. energy: (s,) J (kinetic + gravitational + spring).
        momentum: (s, 3) kg·m/s. angular_momentum: (s, 3) kg·m²/s about the system COM.
        com: (s, 3) m, the moving bodies' centre of mass.
    """

    t: np.ndarray
    energy: np.ndarray
    momentum: np.ndarray
    angular_momentum: np.ndarray
    com: np.ndarray


class Context:
    """A scene and one engine's recording of it, with the derived quantities metrics share."""

    def __init__(self, scenario: Scenario, recording: Recording):
        self.scenario = scenario
        self.recording = recording
        self.trajectory = recording.trajectory
        self.moving = np.array([not b.fixed for b in scenario.bodies])
        self.mass = np.array([b.mass for b in scenario.bodies])
        self.inertia = np.array([body_inertia(b) for b in scenario.bodies])
        self.gravity = np.asarray(scenario.gravity, dtype=float)

    @cached_property
    def model_and_state(self):
        return build_mini_model(self.scenario)

    @cached_property
    def external_contacts(self) -> bool:
        """Whether anything outside the moving bodies can push them: ground, fixed bodies,
        springs to the world. Then momentum is not conserved and its drift is undefined."""
        world_springs = any(s.b == "world" for s in self.scenario.springs)
        return self.scenario.ground is not None or not self.moving.all() or world_springs

    @cached_property
    def can_touch(self) -> bool:
        return self.model_and_state[0].can_touch

    @cached_property
    def series(self) -> Series:
        traj = self.trajectory
        m = np.where(self.moving, self.mass, 0.0)
        samples, count = traj.pos.shape[:2]
        rot = quat_to_matrix(traj.quat.reshape(-1, 4)).reshape(samples, count, 3, 3)
        inertia_world = rot @ self.inertia[None] @ rot.transpose(0, 1, 3, 2)
        spin = np.einsum("snij,snj->sni", inertia_world, traj.ang_vel)
        total_mass = m.sum()
        com = np.einsum("n,sni->si", m, traj.pos) / total_mass
        momentum = np.einsum("n,sni->si", m, traj.vel)
        arm = traj.pos - com[:, None, :]
        angular = np.einsum("n,sni->si", m, np.cross(arm, traj.vel))
        angular += np.einsum("sni,n->si", spin, self.moving.astype(float))
        energy = SceneEnergy(self.scenario)(traj.pos, traj.quat, traj.vel, traj.ang_vel)
        return Series(traj.t, energy, momentum, angular, com)


def _drift(values: np.ndarray, name: str, scale: float | None = None) -> Measurement:
    """max |x(t) - x(0)| / |x(0)| (or / ``scale``); absolute when the scale is zero."""
    start = values[0]
    change = np.linalg.norm(
        np.atleast_2d((values - start).T).T.reshape(values.shape[0], -1), axis=1
    )
    reference = float(np.linalg.norm(start)) if scale is None else scale
    relative = reference > ZERO_SCALE
    value = float(change.max() / reference) if relative else float(change.max())
    magnitude = float(np.linalg.norm(start))
    note = "" if relative else "initial value is zero: absolute drift"
    return Measurement(name, value, magnitude, "conserved", value, note)


def energy_drift(ctx: Context) -> Measurement:
    return _drift(ctx.series.energy, "energy_drift")


def angular_momentum_drift(ctx: Context) -> Measurement | None:
    if ctx.external_contacts:
        return None
    return _drift(ctx.series.angular_momentum, "angular_momentum_drift")


def linear_momentum_drift(ctx: Context) -> Measurement | None:
    if ctx.external_contacts:
        return None
    series = ctx.series
    total_mass = ctx.mass[ctx.moving].sum()
    predicted = series.momentum[0] + total_mass * ctx.gravity * series.t[:, None]
    change = np.linalg.norm(series.momentum - predicted, axis=1)
    scale = max(
        float(np.linalg.norm(series.momentum[0])),
        total_mass * np.linalg.norm(ctx.gravity) * series.t[-1],
    )
    value = float(change.max() / scale) if scale > ZERO_SCALE else float(change.max())
    return Measurement(
        "linear_momentum_drift",
        value,
        float(np.linalg.norm(series.momentum[0])),
        "conserved",
        value,
    )


def _ballistic(ctx: Context) -> tuple[np.ndarray, np.ndarray] | None:
    """Analytic positions and velocities (s, n, 3) of free flight, or None if not free."""
    if ctx.can_touch or ctx.scenario.springs:
        return None
    t = ctx.trajectory.t[:, None, None]
    x0 = np.array([b.position for b in ctx.scenario.bodies])[None]
    v0 = np.array([b.velocity for b in ctx.scenario.bodies])[None]
    g = np.where(ctx.moving[:, None], ctx.gravity, 0.0)[None]
    return x0 + v0 * t + 0.5 * g * t**2, v0 + g * t


def position_error(ctx: Context) -> Measurement | None:
    analytic = _ballistic(ctx)
    if analytic is None:
        return None
    value = float(np.linalg.norm(ctx.trajectory.pos - analytic[0], axis=2).max())
    return Measurement("position_error", value, 0.0, "analytic", value)


def velocity_error(ctx: Context) -> Measurement | None:
    analytic = _ballistic(ctx)
    if analytic is None:
        return None
    value = float(np.linalg.norm(ctx.trajectory.vel - analytic[1], axis=2).max())
    return Measurement("velocity_error", value, 0.0, "analytic", value)


def requested_restitution(ctx: Context, body_a: str, body_b: str) -> float:
    return pair_value(ctx.scenario, body_a, body_b, "restitution")


def restitution_error(ctx: Context) -> Measurement | None:
    impacts = ctx.recording.impacts
    if not impacts:
        return None
    errors = [abs(i.restitution - requested_restitution(ctx, i.body_a, i.body_b)) for i in impacts]
    worst = int(np.argmax(errors))
    event = impacts[worst]
    expected = requested_restitution(ctx, event.body_a, event.body_b)
    note = f"worst of {len(impacts)} impacts: {event.body_a}-{event.body_b} at t = {event.time_start:.4g} s"
    return Measurement(
        "restitution_error", errors[worst], expected, "analytic", errors[worst], note
    )


def penetration_max(ctx: Context) -> Measurement | None:
    if not ctx.can_touch:
        return None
    model, state = ctx.model_and_state
    count = len(ctx.scenario.bodies)
    deepest = 0.0
    for k in range(ctx.trajectory.t.size):
        pos, quat = state.pos.copy(), state.quat.copy()
        pos[:count], quat[:count] = ctx.trajectory.pos[k], ctx.trajectory.quat[k]
        depth = detect_contacts(model, pos, quat_to_matrix(quat), 0.0).depth
        if depth.size:
            deepest = max(deepest, float(depth.max()))
    return Measurement("penetration_max", deepest, 0.0, "analytic", deepest)


METRICS: dict[str, Callable[[Context], Measurement | None]] = {
    "energy_drift": energy_drift,
    "angular_momentum_drift": angular_momentum_drift,
    "linear_momentum_drift": linear_momentum_drift,
    "position_error": position_error,
    "velocity_error": velocity_error,
    "restitution_error": restitution_error,
    "penetration_max": penetration_max,
}
"""Metric name -> its function (``divergence`` needs two engines: ``divergence()``)."""


def divergence(ctx: Context, reference: Context, reference_label: str) -> Measurement | None:
    """max over common sample times of the COM distance between this engine and the reference."""
    mine, theirs = ctx.trajectory, reference.trajectory
    common = min(mine.t.size, theirs.t.size)
    if common == 0 or not np.allclose(mine.t[:common], theirs.t[:common]):
        return None
    value = float(np.linalg.norm(mine.pos[:common] - theirs.pos[:common], axis=2).max())
    return Measurement("divergence", value, 0.0, f"engine:{reference_label}", value)


# --- the scene's own expectations ---------------------------------------------------------


def _body_index(ctx: Context, name: str) -> int:
    return next(i for i, b in enumerate(ctx.scenario.bodies) if b.name == name)


def _nearest_sample(ctx: Context, time: float) -> int:
    return int(np.argmin(np.abs(ctx.trajectory.t - time)))


def _vector_expectation(ctx, expectation, field: str, sample: int) -> Measurement:
    body = _body_index(ctx, expectation.body)
    got = getattr(ctx.trajectory, field)[sample, body]
    error = float(np.linalg.norm(got - np.asarray(expectation.value)))
    note = f"{field} at t = {ctx.trajectory.t[sample]:.6g} s: {np.round(got, 6).tolist()}"
    return Measurement(expectation.metric, error, 0.0, "analytic", error, note)


def _position_at(ctx, expectation) -> Measurement:
    return _vector_expectation(ctx, expectation, "pos", _nearest_sample(ctx, expectation.time))


def _velocity_at(ctx, expectation) -> Measurement:
    return _vector_expectation(ctx, expectation, "vel", _nearest_sample(ctx, expectation.time))


def _velocity_after_impact(ctx, expectation) -> Measurement | None:
    mine = [i for i in ctx.recording.impacts if expectation.body in (i.body_a, i.body_b)]
    if not mine:
        return Measurement(
            expectation.metric, float("inf"), 0.0, "analytic", float("inf"), "no impact"
        )
    # the first sample at the end of the impulse, before gravity acts any further
    sample = int(np.searchsorted(ctx.trajectory.t, mine[0].time_impulse - 1e-12))
    sample = min(sample, ctx.trajectory.t.size - 1)
    return _vector_expectation(ctx, expectation, "vel", sample)


def _bounce_heights(ctx, expectation) -> Measurement:
    body = _body_index(ctx, expectation.body)
    z, vz = ctx.trajectory.pos[:, body, 2], ctx.trajectory.vel[:, body, 2]
    impacts = [
        i.time_end for i in ctx.recording.impacts if expectation.body in (i.body_a, i.body_b)
    ]
    apexes = []
    for start in impacts[: len(expectation.value)]:
        after = np.flatnonzero((ctx.trajectory.t >= start) & (vz <= 0.0))
        if after.size:
            apexes.append(float(z[max(after[0] - 1, 0) : after[0] + 1].max()))
    if len(apexes) < len(expectation.value):
        message = f"{len(apexes)} apexes seen, {len(expectation.value)} expected"
        return Measurement(expectation.metric, float("inf"), 0.0, "analytic", float("inf"), message)
    error = float(np.max(np.abs(np.array(apexes) - np.array(expectation.value))))
    return Measurement(
        expectation.metric,
        error,
        0.0,
        "analytic",
        error,
        f"apexes {np.round(apexes, 5).tolist()} m",
    )


def _body_frame_omega(ctx, body: int) -> np.ndarray:
    rot = quat_to_matrix(ctx.trajectory.quat[:, body])
    return np.einsum("sji,sj->si", rot, ctx.trajectory.ang_vel[:, body])


def _precession_rate(ctx, expectation) -> Measurement:
    omega = _body_frame_omega(ctx, _body_index(ctx, expectation.body))
    angle = np.unwrap(np.arctan2(omega[:, 1], omega[:, 0]))
    rate = float(np.polyfit(ctx.trajectory.t, angle, 1)[0])
    error = abs(rate - expectation.value)
    return Measurement(
        expectation.metric, error, expectation.value, "analytic", error, f"rate {rate:.6g} rad/s"
    )


def _flips(ctx, expectation) -> Measurement:
    omega = _body_frame_omega(ctx, _body_index(ctx, expectation.body))
    component = omega[:, "xyz".index(expectation.axis)]
    flips = int(np.sum(np.diff(np.sign(component[component != 0.0])) != 0))
    error = float(abs(flips - expectation.value))
    return Measurement(
        expectation.metric, error, float(expectation.value), "analytic", error, f"{flips} flips"
    )


EXPECTATIONS: dict[str, Callable] = {
    "position_at": _position_at,
    "velocity_at": _velocity_at,
    "velocity_after_impact": _velocity_after_impact,
    "bounce_heights": _bounce_heights,
    "precession_rate": _precession_rate,
    "flips": _flips,
}
"""Expectation kind -> its metric function (named ``<kind>.<body>`` or by its ``name``)."""


def _guarded(name: str, compute: Callable[[], Measurement | None]) -> Measurement | None:
    """A metric's result, or a NaN measurement carrying the exception: one broken metric
    (on an exploded trajectory, say) must not take the other rows down with it."""
    try:
        return compute()
    except Exception as error:  # reported in the row's message
        return Measurement(
            name,
            math.nan,
            None,
            "analytic",
            math.nan,
            f"not computed: {type(error).__name__}: {error}",
        )


def measure(ctx: Context) -> list[Measurement]:
    """Every metric the scene can define for this recording (divergence excluded)."""
    found = [_guarded(name, lambda metric=metric: metric(ctx)) for name, metric in METRICS.items()]
    found += [
        _guarded(e.metric, lambda e=e: EXPECTATIONS[e.kind](ctx, e)) for e in ctx.scenario.expect
    ]
    return [result for result in found if result is not None]
