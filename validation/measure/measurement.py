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
