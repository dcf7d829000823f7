"""What a float32 engine can resolve: the floor under which a row's error is the engine's
precision, not its physics, and so the row's precision band.

A float32 engine (``Capabilities.precision``) rounds every state update to a 24-bit
significand. A value it carries over ``steps`` scene steps of ``substeps`` updates each is
rounded that many times, each time by up to half an ulp: its error can reach

    floor = steps · substeps · u · max(|value|, |expected|),   u = 2⁻²⁴ (half an ulp, relative)

without any fault of the physics (a constant increment rounds the same way every time, so
the bound is reached, not merely allowed: a free body's position drifts so,
docs/engines-rapier.md section 3). A relative drift of a conserved quantity (``*_drift``)
cannot be resolved below ``FLOAT32_DRIFT_FLOOR``. Rows of other kinds (a largest error over
the run, a count, a fitted rate, an impact's restitution) get no floor: float32 is never the
whole story there.

The floor is the row's precision band (``precision_band``): an engine that declares float32
precision (``Capabilities.precision``) cannot be asked for less, so the row passes when
``error <= tolerance + band`` like the restitution band, and the band is in results.csv's
``band`` column (added to any band the metric has of its own). A row that passes only by it is
marked: its message starts with ``RESOLUTION_MARK``, and the report shows it.
"""

from __future__ import annotations

import math

FLOAT32_UNIT_ROUNDOFF = 2.0**-24
"""5.96e-8: half an ulp of a float32, relative (a 24-bit significand)."""

FLOAT32_DRIFT_FLOOR = 16 * FLOAT32_UNIT_ROUNDOFF
"""9.5e-7 (8 float32 epsilons): the smallest relative drift of a sum of a few float32 terms
(momentum or energy of a handful of bodies, each term rounded) that can be told from 0."""

RESOLUTION_MARK = "at float32 resolution"
"""How a failing row's message starts when its error is within its float32 floor."""

CARRIED_VALUE_KINDS = (
    "position_at",
    "velocity_at",
    "angular_velocity_at",
    "orientation_at",
    "energy_at",
    "velocity_after_impact",
    "angular_velocity_after_impact",
)
"""Metrics (``<kind>.<body>[.<name>]``) whose value is a state the engine carries step to step."""

DRIFT_SUFFIX = "_drift"
"""Metrics of a conserved quantity's relative drift (``energy_drift``, ...)."""


def resolution_floor(
    metric: str, value: float, expected: float, steps: int, substeps: int
) -> float | None:
    """The float32 floor of one row (see the module), or None for a row of another kind."""
    if metric.endswith(DRIFT_SUFFIX):
        return FLOAT32_DRIFT_FLOOR
    if metric.split(".", 1)[0] not in CARRIED_VALUE_KINDS:
        return None
    scale = max(abs(value), abs(expected))
    if not math.isfinite(scale):
        return None
    return steps * substeps * FLOAT32_UNIT_ROUNDOFF * scale


def precision_band(
    precision: str, metric: str, value: float, expected: float, steps: int, substeps: int
) -> float:
    """The row's precision band: its ``resolution_floor`` for an engine of ``float32``
    precision, 0 for a float64 engine or a row of another kind."""
    if precision != "float32":
        return 0.0
    floor = resolution_floor(metric, value, expected, steps, substeps)
    return 0.0 if floor is None else floor


def resolution_note(
    metric: str, value: float, expected: float, error: float, steps: int, substeps: int
) -> str:
    """``RESOLUTION_MARK`` and the numbers when ``error`` is within the row's floor, else ''."""
    floor = resolution_floor(metric, value, expected, steps, substeps)
    if floor is None or not (math.isfinite(error) and error <= floor):
        return ""
    if metric.endswith(DRIFT_SUFFIX):
        how = "the smallest relative drift float32 resolves"
    else:
        how = f"{steps} steps x {substeps} substeps x half an ulp of {max(abs(value), abs(expected)):.4g}"
    return f"{RESOLUTION_MARK}: |error| {error:.3g} <= {floor:.3g} ({how})"
