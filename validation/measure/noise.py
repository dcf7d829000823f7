"""When two runs' values of one row differ: the noise rule, defined once (and in the legend).

The same scene and versions give the same numbers bit for bit (serial, parallel or distributed),
so any difference between two runs on one machine is real; between machines (another CPU, BLAS or
compiler) chaotic scenes (piles, tumbling boxes) amplify round-off. A row has *moved* when its
error changed by more than

    max(RELATIVE_NOISE · max(|error_a|, |error_b|), TOLERANCE_NOISE · tolerance, ABSOLUTE_NOISE)

and then it is ``regressed`` when the error grew and ``improved`` when it shrank. A change of
verdict (passed -> failed, ok -> unstable) is always a move, whatever the numbers. Where both
runs recorded the signed error (``validation.contract.SIGNED_COLUMNS``), an error whose size
held but whose sign or direction moved by more than the same floor (explicit instead of
semi-implicit Euler on a projectile: the same |error|, the opposite sign) is ``regressed``
too: the engine's behaviour changed, and nothing says it got better.
"""

from __future__ import annotations

import math

import numpy as np

RELATIVE_NOISE = 1e-3
"""A 0.1 % change of a row's error is news: 30x below issue 12's example of news (a 3 % change of a
rebound). Reruns on one machine are bit-identical (the determinism tests), so the floor matters
only across machines, where chaotic scenes (piles, tumbles) may amplify round-off; how far is
not measured yet, and a baseline is best saved on the machine that compares against it."""

TOLERANCE_NOISE = 1e-3
"""... and a change below a thousandth of the row's tolerance cannot change a verdict soon."""

ABSOLUTE_NOISE = 1e-12
"""In the metric's SI unit: changes below this are round-off of quantities that are 0 exactly."""

NOISE_RULE = (
    f"a row moved when |Δerror| > max({RELATIVE_NOISE:g}·max(|error|), "
    f"{TOLERANCE_NOISE:g}·tolerance, {ABSOLUTE_NOISE:g}); regressed if the error grew, improved "
    "if it shrank, regressed also when its size held but the signed error moved by more than "
    "that floor (its sign or direction changed); a change of verdict is always a move"
)
"""The rule in one line, for the legend and the README."""


def noise_floor(error_a: float, error_b: float, tolerance: float) -> float:
    """The largest change of a row's error that is not news."""
    scale = max(abs(error_a), abs(error_b))
    allowance = TOLERANCE_NOISE * tolerance if math.isfinite(tolerance) else 0.0
    return max(RELATIVE_NOISE * scale, allowance, ABSOLUTE_NOISE)


def moved(error_a: float, error_b: float, tolerance: float) -> int:
    """+1 when the error grew beyond noise from run a to run b, -1 when it shrank, else 0
    (NaN errors compare as unchanged when both are NaN, as a move otherwise)."""
    if math.isnan(error_a) or math.isnan(error_b):
        return 0 if math.isnan(error_a) and math.isnan(error_b) else 1
    change = error_b - error_a
    if abs(change) <= noise_floor(error_a, error_b, tolerance):
        return 0
    return 1 if change > 0 else -1


def moved_signed(
    signed_a: np.ndarray | None,
    signed_b: np.ndarray | None,
    error_a: float,
    error_b: float,
    tolerance: float,
) -> int:
    """``moved`` of the errors, and +1 when their size held but the signed errors
    ``signed_a, signed_b`` (scalars as (1,), vectors as (3,); None when a run lacks them) are
    apart by more than the noise floor."""
    direction = moved(error_a, error_b, tolerance)
    if direction != 0 or signed_a is None or signed_b is None or signed_a.shape != signed_b.shape:
        return direction
    shift = float(np.linalg.norm(signed_b - signed_a))
    return 1 if shift > noise_floor(error_a, error_b, tolerance) else 0
