"""The parity gate: an engine's model must equal the scenario before the first step.

Each quantity of the engine's ``ModelReport`` is compared with the scenario's
``reference_report`` to ``PARITY_TOLERANCE`` relative. A mismatch names the quantity,
the body and both values, and becomes a result row with status ``model_mismatch``.
"""

from __future__ import annotations

from dataclasses import dataclass, fields

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
    problem: str = ""
    """Set when the engine's value cannot be compared at all (a wrong shape, a NaN): what is
    wrong with it, said instead of a relative error."""

    def __str__(self) -> str:
        where = f" of body {self.body}" if self.body is not None else ""
        if self.problem:
            return f"{self.quantity}{where}: {self.problem}"
        return (
            f"{self.quantity}{where}: engine {self.engine_value}, scenario {self.expected} "
            f"(relative error {self.relative_error:.3g} > {self.tolerance})"
        )


def _relative(engine: np.ndarray, expected: np.ndarray, tolerance: float) -> float:
    scale = max(float(np.max(np.abs(expected), initial=0.0)), ABSOLUTE_FLOOR / tolerance)
    return float(np.max(np.abs(engine - expected), initial=0.0)) / scale


QUANTITIES = tuple(f.name for f in fields(ModelReport))
"""The fields of a ``ModelReport``, in the order the gate reports them."""

PER_BODY = ("mass", "com", "inertia_world")
"""The quantities a ``ModelReport`` has one row of per dynamic body; the others are totals."""


def _as_floats(value: object) -> np.ndarray | None:
    """``value`` as a float array, or None when it is not numbers."""
    try:
        return np.asarray(value, dtype=np.float64)
    except (TypeError, ValueError):
        return None


def unusable(engine: ModelReport, expected: ModelReport) -> list[Mismatch]:
    """The contract before any comparison: each quantity of ``engine`` is numbers, of the
    shape of ``expected``'s (so a body too many or too few is found for every scene size,
    one body included, where indexing would have read past it) and finite (a NaN compares
    as neither greater nor smaller than a tolerance, so it would pass)."""
    found = []
    for quantity in QUANTITIES:
        got = _as_floats(getattr(engine, quantity, None))
        want = np.shape(getattr(expected, quantity))
        body = None
        if got is None or got.shape != want:
            shape = "not numbers" if got is None else f"shape {got.shape}"
            bodies = f" ({want[0]} dynamic bodies)" if quantity in PER_BODY else ""
            problem = f"the engine reported {shape}; expected shape {want}{bodies}"
        elif not np.isfinite(got).all():
            bad = ~np.isfinite(got)
            body = int(np.argwhere(bad)[0][0]) if quantity in PER_BODY else None
            problem = (
                f"the engine reported {int(bad.sum())} non-finite value(s) (first: "
                f"{got[bad][0]}); expected finite numbers"
            )
        else:
            continue
        found.append(Mismatch(quantity, body, None, None, float("inf"), problem=problem))
    return found


def compare(
    engine: ModelReport, expected: ModelReport, tolerance: float = PARITY_TOLERANCE
) -> list[Mismatch]:
    """Every quantity of ``engine`` that differs from ``expected`` beyond ``tolerance``
    (relative; ``PRECISION_TOLERANCE`` of the engine's declared precision); a quantity of the
    wrong shape or not finite (``unusable``) is a mismatch before any is compared."""
    mismatches = unusable(engine, expected)
    if mismatches:
        return mismatches
    for quantity in PER_BODY:
        got, want = getattr(engine, quantity), getattr(expected, quantity)
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
    for quantity in (q for q in QUANTITIES if q not in PER_BODY):
        got, want = getattr(engine, quantity), getattr(expected, quantity)
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


OBSERVED_COLUMNS = {"pos": 3, "quat": 4, "vel": 3, "ang_vel": 3}
"""The per-body width of each observed state field (``Snapshot``, ``Trajectory``)."""


class ObservationError(ValueError):
    """States an engine observed that break the adapter contract (a wrong body count or
    shape): the run's ``error`` row, its message naming the field."""


def check_observation(states, bodies: int) -> None:
    """The observation contract: ``states`` (a ``Trajectory`` of s states) holds ``t`` (s,)
    and, for every one of the scene's ``bodies``, ``pos``, ``vel``, ``ang_vel`` (s, n, 3) and
    ``quat`` (s, n, 4); else ``ObservationError`` naming the field (an engine reporting one
    body too many would otherwise be measured by broadcasting). Values are not judged here:
    a non-finite state is the stability checks' finding (``unstable``)."""
    if len(np.shape(states.t)) != 1:
        raise ObservationError(f"observed t has shape {np.shape(states.t)}; expected (states,)")
    count = np.shape(states.t)[0]
    for name, width in OBSERVED_COLUMNS.items():
        shape = np.shape(getattr(states, name))
        if shape != (count, bodies, width):
            raise ObservationError(
                f"observed {name} has shape {shape}; expected ({count}, {bodies}, {width}): "
                f"{count} states of the scene's {bodies} bodies"
            )
