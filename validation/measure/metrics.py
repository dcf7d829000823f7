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

import numpy as np

from mini_engine.rotation import quat_to_matrix
from validation.measure.recording import Recording
from validation.scenario.compiled import CompiledScene
from validation.scenario.physics import symmetry_frame

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


class Context:
    """A compiled scene and one engine's recording of it, with the quantities metrics share."""

    def __init__(self, scene: CompiledScene, recording: Recording):
        self.scene = scene
        self.scenario = scene.scenario
        self.recording = recording
        self.trajectory = recording.trajectory
        self.series = recording.series
        self.moving = scene.moving
        self.mass = np.array([b.mass for b in scene.scenario.bodies])
        self.gravity = scene.gravity
        self.can_touch = scene.can_touch
        self.external_contacts = scene.external_loads


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
    return ctx.scene.pair_value(body_a, body_b, "restitution")


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
    deepest = ctx.recording.penetration_max
    if deepest is None:
        return None
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
    """``value`` |measured|, ``expected`` |target|, ``error`` the distance between the two
    vectors (the message gives both in full)."""
    body = _body_index(ctx, expectation.body)
    got = getattr(ctx.trajectory, field)[sample, body]
    target = np.asarray(expectation.value, dtype=float)
    error = float(np.linalg.norm(got - target))
    note = (
        f"{field} at t = {ctx.trajectory.t[sample]:.6g} s: {np.round(got, 6).tolist()}"
        f" (expected {np.round(target, 6).tolist()})"
    )
    return Measurement(
        expectation.metric,
        float(np.linalg.norm(got)),
        float(np.linalg.norm(target)),
        "analytic",
        error,
        note,
    )


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
    misses = np.abs(np.array(apexes) - np.array(expectation.value))
    worst = int(np.argmax(misses))
    return Measurement(
        expectation.metric,
        apexes[worst],
        float(expectation.value[worst]),
        "analytic",
        float(misses[worst]),
        f"apexes {np.round(apexes, 5).tolist()} m (worst: apex {worst + 1})",
    )


def _body_frame_omega(ctx, body: int) -> np.ndarray:
    rot = quat_to_matrix(ctx.trajectory.quat[:, body])
    return np.einsum("sji,sj->si", rot, ctx.trajectory.ang_vel[:, body])


def _precession_rate(ctx, expectation) -> Measurement:
    """The rate at which ω turns about the body's symmetry axis, seen in the body frame."""
    body = _body_index(ctx, expectation.body)
    axis, first, second = symmetry_frame(ctx.scene.inertia[body])  # checked at load time
    axis_name = "xyz"[axis] if axis is not None else "symmetry"
    omega = _body_frame_omega(ctx, body)
    angle = np.unwrap(np.arctan2(omega @ second, omega @ first))
    rate = float(np.polyfit(ctx.trajectory.t, angle, 1)[0])
    return Measurement(
        expectation.metric,
        rate,
        float(expectation.value),
        "analytic",
        abs(rate - expectation.value),
        f"rate {rate:.6g} rad/s about the body's {axis_name} axis",
    )


def _flips(ctx, expectation) -> Measurement:
    omega = _body_frame_omega(ctx, _body_index(ctx, expectation.body))
    component = omega[:, "xyz".index(expectation.axis)]
    flips = int(np.sum(np.diff(np.sign(component[component != 0.0])) != 0))
    return Measurement(
        expectation.metric,
        float(flips),
        float(expectation.value),
        "analytic",
        float(abs(flips - expectation.value)),
        f"{flips} flips",
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
