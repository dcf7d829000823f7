"""Metrics: pure functions of one engine's recording of one scene, one definition each.

Every metric is a function in ``METRICS`` (or, for a scene's own expectations,
``EXPECTATIONS``) that returns a ``Measurement`` or ``None`` when the scene cannot
define it. Whether a scene can define a metric (no ballistic error where bodies can touch,
no momentum drift with a ground, ...) is ``validation.scenario.definability``'s table, the
one the loader checks a scene's ``checks`` against; a metric then returns ``None`` only for
what the run decides (no restitution without an impact). A ``None`` is left out of the
report, never written as zero. The one-line definitions the report prints are in
``validation.measure.definitions``.
"""

from __future__ import annotations

import math
from collections.abc import Callable

import numpy as np

from validation.measure.impact_log import RANKINGS, restitution_error_of
from validation.measure.measurement import Measurement
from validation.measure.recording import Recording
from validation.measure.states import (
    coordinate_joints,
    farthest,
    impulse_residual,
    internal_energy,
    momentum_rates,
)
from validation.scenario.compiled import CompiledScene
from validation.scenario.definability import scene_traits, why_undefined

ZERO_SCALE = 1e-12
"""Below this magnitude (in the quantity's SI unit) an energy or momentum scale counts as
zero, and its drift is reported as an absolute difference instead of a relative one."""


class Context:
    """A compiled scene and one engine's recording of it, with the quantities metrics share."""

    def __init__(self, scene: CompiledScene, recording: Recording):
        self.scene = scene
        self.scenario = scene.scenario
        self.recording = recording
        self.trajectory = recording.trajectory
        self.series = recording.series if recording.extremes is None else recording.extremes
        """The samples the metrics read: every step's extremes (``states.extreme_samples``), or
        the kept series of a recording made without them."""
        self.moving = scene.moving
        self.mass = np.array([b.mass for b in scene.scenario.bodies])
        self.gravity = scene.gravity
        self.traits = scene_traits(scene)


def _conserved(name: str, drift: float, signed: tuple[float, ...], message: str) -> Measurement:
    """A conserved quantity's row: ``value`` the measured drift, ``expected`` its target 0,
    ``error`` the drift, ``signed`` its worst excursion with its sign (per component for a
    vector); the scale it was divided by goes in the message."""
    return Measurement(name, drift, 0.0, "conserved", drift, message, signed=signed)


def energy_scale(ctx: Context) -> tuple[float, float, float]:
    """(E_scale, motion, weight) J: the scale of ``energy_drift``, the sum of ``motion``, the
    largest internal energy over the run (``states.internal_energy``: kinetic energy about
    the centre of mass plus spring energy plus the centre of mass's own change of kinetic
    energy, for a free system; kinetic plus spring energy where a ground, fixed body or world
    spring holds it), and ``weight``, Σ m |g + F/m| r over the moving bodies (each body's
    weight, with its constant applied force, over its bounding radius r). None of them depends
    on where the origin is, where a potential is zero, or (for a free system) on a Galilean
    boost of the whole scene: the kinetic and spring energies have a physical zero, and a
    weight times a size is the energy scale of a body that rests (a resting stack has no
    motion, but sinking by its own size would release this much)."""
    pull = np.linalg.norm(ctx.scene.acceleration, axis=1)  # g + F/m, zero for fixed bodies
    radius = ctx.scene.bound_radius[: ctx.scene.count]
    weight = float(np.sum(ctx.scene.mass * pull * radius))
    largest = float(np.max(internal_energy(ctx.scene, ctx.series), initial=0.0))
    return largest + weight, largest, weight


def energy_drift(ctx: Context) -> Measurement | None:
    """max |E(t) - E(0)| / E_scale (``energy_scale``): the energy error on a scale no choice
    of origin, potential zero or boost changes; the message keeps the error in J."""
    change = ctx.series.energy - ctx.series.energy[0]
    worst = int(np.argmax(np.abs(change)))
    scale, motion, weight = energy_scale(ctx)
    relative = scale > ZERO_SCALE
    divisor = scale if relative else 1.0
    drift = float(abs(change[worst]) / divisor)
    message = f"max |ΔE| {abs(change[worst]):.6g} J at t = {ctx.series.t[worst]:.6g} s; " + (
        f"E_scale {scale:.6g} J (internal kinetic + spring {motion:.6g} J, weight x size "
        f"{weight:.6g} J)"
        if relative
        else "E_scale is zero: absolute drift (J)"
    )
    return _conserved("energy_drift", drift, (float(change[worst] / divisor),), message)


def _impulse_balance(ctx: Context, name: str, metric: str) -> Measurement:
    """max |x(t) - x(0) - rate·t| / scale of the momentum ``name`` of the series (``momentum``
    or ``angular_momentum``) whose rate of change is constant (``states.momentum_rates``), the
    scale the larger of the largest ``<name>_scale`` over the run (the bodies' momenta added
    without cancellation: ``Series``) and the loads' impulse |rate|·t_end; absolute when both
    are zero. Never |x(0)|: a total that cancels to round-off is no scale."""
    series = ctx.series
    residual = impulse_residual(ctx.scene, series, name)
    change = np.linalg.norm(residual, axis=1)
    worst = int(np.argmax(change))
    carried = float(np.max(getattr(series, f"{name}_scale"), initial=0.0))
    rate = momentum_rates(ctx.scene)[name == "angular_momentum"]
    impulse = float(np.linalg.norm(rate)) * float(series.t[-1] - series.t[0])
    scale = max(carried, impulse)
    relative = scale > ZERO_SCALE
    divisor = scale if relative else 1.0
    note = (
        f"max drift {change[worst]:.6g} at t = {series.t[worst]:.6g} s; scale {scale:.6g} "
        f"(bodies' momenta without cancellation {carried:.6g}, loads' impulse {impulse:.6g})"
        if relative
        else "scale is zero: absolute drift"
    )
    signed = tuple(float(x) for x in residual[worst] / divisor)
    return _conserved(metric, float(change[worst] / divisor), signed, note)


def angular_momentum_drift(ctx: Context) -> Measurement:
    return _impulse_balance(ctx, "angular_momentum", "angular_momentum_drift")


def linear_momentum_drift(ctx: Context) -> Measurement:
    return _impulse_balance(ctx, "momentum", "linear_momentum_drift")


def _largest_offset(name: str, offset: np.ndarray, expected_kind: str) -> Measurement:
    """The largest norm over samples of ``offset (s, 3)`` (each sample's farthest body:
    ``states.farthest``), with that offset's components as the signed error."""
    distance = np.linalg.norm(offset, axis=1)
    sample = int(np.argmax(distance))
    value = float(distance[sample])
    signed = tuple(float(x) for x in offset[sample])
    return Measurement(name, value, 0.0, expected_kind, value, signed=signed)


def position_error(ctx: Context) -> Measurement:
    """From each sample's farthest body off the ballistic positions (``Series``)."""
    return _largest_offset("position_error", ctx.series.position_offset, "analytic")


def velocity_error(ctx: Context) -> Measurement:
    """From each sample's farthest body off the ballistic velocities (``Series``)."""
    return _largest_offset("velocity_error", ctx.series.velocity_offset, "analytic")


def requested_restitution(ctx: Context, body_a: str, body_b: str) -> float:
    return ctx.scene.pair_value(body_a, body_b, "restitution")


def restitution_error(ctx: Context) -> Measurement | None:
    """The impact with the largest |Δe| beyond its discretization band (``restitution``):
    value its e_measured, expected its e, error |Δe|, band its band. The recording keeps that
    impact whatever it thins (``impact_log``: the worst by ``beyond_band`` are kept, ties to
    the earlier, as ``np.argmax`` picks); the note counts every impact."""
    impacts = ctx.recording.impacts
    if not impacts:
        return None
    pairs = {(i.body_a, i.body_b) for i in impacts}
    lookup = {pair: requested_restitution(ctx, *pair) for pair in pairs}
    requested = [lookup[i.body_a, i.body_b] for i in impacts]
    found = [restitution_error_of(i, e) for i, e in zip(impacts, requested, strict=True)]
    errors = [error for error, _ in found]
    bands = [band for _, band in found]
    worst = int(np.argmax([RANKINGS["beyond_band"](error, band) for error, band in found]))
    event = impacts[worst]
    count = max(ctx.recording.impact_count, len(impacts))  # a recording made of events alone
    note = (
        f"worst of {count} impacts: {event.body_a}-{event.body_b} at t = "
        f"{event.time_start:.4g} s, |Δe| {errors[worst]:.3g}, band {bands[worst]:.3g} at "
        f"{abs(event.normal_velocity_before):.3g} m/s"
    )
    return Measurement(
        "restitution_error",
        event.restitution,
        requested[worst],
        "analytic",
        errors[worst],
        note,
        bands[worst],
        signed=(event.restitution - requested[worst],),
    )


def penetration_max(ctx: Context) -> Measurement | None:
    """The deepest overlap the recording saw (None when it measured none)."""
    deepest = ctx.recording.penetration_max
    if deepest is None:
        return None
    return Measurement("penetration_max", deepest, 0.0, "analytic", deepest, signed=(deepest,))


def joint_violation(ctx: Context) -> Measurement:
    """The largest joint violation over every observed step (``states.joint_violation``): an
    anchor's separation, or a misalignment times the child's reach, in m."""
    worst = int(np.argmax(ctx.series.joint_violation))
    value = float(ctx.series.joint_violation[worst])
    message = f"largest at t = {ctx.series.t[worst]:.6g} s"
    return Measurement("joint_violation", value, 0.0, "analytic", value, message, signed=(value,))


Metric = Callable[[Context], Measurement | None]


def _where_defined(name: str, compute: Metric) -> Metric:
    """``compute``, or None where the scene cannot define metric ``name`` (``definability``)."""

    def metric(ctx: Context) -> Measurement | None:
        return None if why_undefined(name, ctx.traits) is not None else compute(ctx)

    metric.__doc__ = compute.__doc__
    return metric


METRICS: dict[str, Metric] = {
    name: _where_defined(name, compute)
    for name, compute in {
        "energy_drift": energy_drift,
        "angular_momentum_drift": angular_momentum_drift,
        "linear_momentum_drift": linear_momentum_drift,
        "position_error": position_error,
        "velocity_error": velocity_error,
        "restitution_error": restitution_error,
        "penetration_max": penetration_max,
        "joint_violation": joint_violation,
    }.items()
}
"""Metric name -> its function, None where the scene cannot define it (``divergence`` needs
two engines: ``divergence()``)."""


def divergence(ctx: Context, reference: Context, reference_label: str) -> Measurement | None:
    """max over common sample times of the COM distance between this engine and the reference."""
    mine, theirs = ctx.trajectory, reference.trajectory
    common = min(mine.t.size, theirs.t.size)
    if common == 0 or not np.allclose(mine.t[:common], theirs.t[:common]):
        return None
    difference = farthest(mine.pos[:common] - theirs.pos[:common])
    return _largest_offset("divergence", difference, f"engine:{reference_label}")


def _joint_differences(ctx: Context, reference: Context) -> tuple[np.ndarray, np.ndarray] | None:
    """(times (s,), differences (s, c)): this engine's tree coordinates minus the reference
    engine's at their common kept samples (``Series.joint_coordinates``), a hinge's wrapped to
    ±π; None when they share no samples or the scene keeps no coordinates."""
    mine, theirs = ctx.recording.series, reference.recording.series
    common = min(mine.t.size, theirs.t.size)
    columns = mine.joint_coordinates.shape[1]
    if common == 0 or columns == 0 or not np.allclose(mine.t[:common], theirs.t[:common]):
        return None
    difference = mine.joint_coordinates[:common] - theirs.joint_coordinates[:common]
    hinge = np.array([j.type == "hinge" for j in coordinate_joints(ctx.scene)])
    wrapped = np.where(hinge, (difference + math.pi) % (2.0 * math.pi) - math.pi, difference)
    return mine.t[:common], wrapped


JOINT_UNITS = {"hinge": "rad", "slider": "m"}
"""The unit of a joint's coordinate, by its type."""


def joint_divergence(ctx: Context, reference: Context, reference_label: str) -> Measurement | None:
    """max over the common kept samples and the tree's coordinates of |q - q_reference| (rad
    or m), the message naming the joint and the time; signed: that difference."""
    found = _joint_differences(ctx, reference)
    if found is None:
        return None
    times, difference = found
    sample, column = np.unravel_index(int(np.nanargmax(np.abs(difference))), difference.shape)
    joint = coordinate_joints(ctx.scene)[column]
    value = float(abs(difference[sample, column]))
    message = (
        f"joint {joint.name} at t = {times[sample]:.6g} s: {value:.3g} {JOINT_UNITS[joint.type]} "
        f"from {reference_label}"
    )
    return Measurement(
        "joint_divergence", value, 0.0, f"engine:{reference_label}", value, message,
        signed=(float(difference[sample, column]),),
    )  # fmt: skip


def agreement_time(
    ctx: Context, reference: Context, reference_label: str, band: float | None
) -> Measurement | None:
    """The time (s) this engine's tree coordinates stay within ``band`` (the scene's
    ``joint_divergence`` tolerance) of the reference engine's: the first common kept sample
    beyond it, or the last common sample's time when none is; expected that last time, error
    the time lost. None without a band or common samples."""
    found = None if band is None else _joint_differences(ctx, reference)
    if found is None:
        return None
    times, difference = found
    beyond = np.flatnonzero(~(np.abs(difference).max(axis=1) <= band))
    end = float(times[-1])
    if beyond.size == 0:
        return Measurement(
            "agreement_time", end, end, f"engine:{reference_label}", 0.0,
            f"within {band:g} of {reference_label} throughout",
        )  # fmt: skip
    left = float(times[beyond[0]])
    column = int(np.nanargmax(np.abs(difference[beyond[0]])))
    joint = coordinate_joints(ctx.scene)[column]
    message = (
        f"joint {joint.name} leaves the band {band:g} of {reference_label} at t = {left:.6g} s"
    )
    return Measurement(
        "agreement_time", left, end, f"engine:{reference_label}", end - left, message,
        signed=(left - end,),
    )  # fmt: skip


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
    found += ctx.recording.expectations  # evaluated online while recording (``expectations``)
    return [result for result in found if result is not None]
