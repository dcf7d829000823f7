"""What every metric and expectation returns: one measured number and its comparison."""

from __future__ import annotations

from dataclasses import dataclass


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
    band: float = 0.0
    """Allowance the physics leaves at O(dt) (derived, never guessed): the row passes when
    ``error <= tolerance + band`` (restitution: ``validation.measure.restitution``)."""
    signed: tuple[float, ...] = ()
    """The error with its sign, ``measured - expected``: one number for a scalar quantity
    (a time, a count, a rate, a drift's worst excursion), three world-frame components for a
    vector (a position, a velocity, a momentum; an orientation's rotation vector); empty when
    the quantity has no sign. ``error`` is its magnitude (the norm of a vector)."""
