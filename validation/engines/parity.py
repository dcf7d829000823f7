"""The parity gate: an engine's model must equal the scenario before the first step.

Each quantity of the engine's ``ModelReport`` is compared with the scenario's
``reference_report`` to ``PARITY_TOLERANCE`` relative. A mismatch names the quantity,
the body and both values, and becomes a result row with status ``model_mismatch``.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from validation.engines.base import ModelReport

PARITY_TOLERANCE = 1e-9
"""Relative. Engines store masses and inertias in double precision; anything
beyond round-off is a different model (a dropped inertia, a COM offset, a damping term)."""

PRECISION_TOLERANCE: dict[str, float] = {"float64": PARITY_TOLERANCE, "float32": 1e-6}
"""Relative parity tolerance per declared precision (``engine_api.PRECISIONS``): a float32
engine holds a mass or inertia to its epsilon 1.2e-7, a world inertia or an energy summed
over a few terms to a few epsilons; 1e-6 (8 epsilons) admits that and nothing a dropped
term or an offset centre of mass would give."""

ABSOLUTE_FLOOR = 1e-12
"""Absolute floor in the quantity's SI unit, for quantities that are zero in the scene
(the momentum of a scene at rest): below it, a difference is round-off."""


@dataclass(frozen=True)
class Mismatch:
    quantity: str
    body: int | None
    engine_value: object
    expected: object
    relative_error: float
    tolerance: float = PARITY_TOLERANCE

    def __str__(self) -> str:
        where = f" of body {self.body}" if self.body is not None else ""
        return (
            f"{self.quantity}{where}: engine {self.engine_value}, scenario {self.expected} "
            f"(relative error {self.relative_error:.3g} > {self.tolerance})"
        )


def _relative(engine: np.ndarray, expected: np.ndarray, tolerance: float) -> float:
    scale = max(float(np.max(np.abs(expected), initial=0.0)), ABSOLUTE_FLOOR / tolerance)
    return float(np.max(np.abs(engine - expected), initial=0.0)) / scale


def compare(
    engine: ModelReport, expected: ModelReport, tolerance: float = PARITY_TOLERANCE
) -> list[Mismatch]:
    """Every quantity of ``engine`` that differs from ``expected`` beyond ``tolerance``
    (relative; ``PRECISION_TOLERANCE`` of the engine's declared precision)."""
    mismatches = []
    per_body = {
        "mass": (engine.mass, expected.mass),
        "com": (engine.com, expected.com),
        "inertia_world": (engine.inertia_world, expected.inertia_world),
    }
    for quantity, (got, want) in per_body.items():
        for body in range(len(want)):
            error = _relative(np.asarray(got[body]), np.asarray(want[body]), tolerance)
            if error > tolerance:
                mismatches.append(
                    Mismatch(
                        quantity,
                        body,
                        np.round(got[body], 12).tolist(),
                        np.round(want[body], 12).tolist(),
                        error,
                        tolerance,
                    )
                )
    totals = {
        "energy": (engine.energy, expected.energy),
        "linear_momentum": (engine.linear_momentum, expected.linear_momentum),
        "angular_momentum": (engine.angular_momentum, expected.angular_momentum),
    }
    for quantity, (got, want) in totals.items():
        error = _relative(np.asarray(got), np.asarray(want), tolerance)
        if error > tolerance:
            mismatches.append(
                Mismatch(
                    quantity,
                    None,
                    np.round(got, 12).tolist(),
                    np.round(want, 12).tolist(),
                    error,
                    tolerance,
                )
            )
    return mismatches
