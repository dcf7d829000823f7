"""The parity gate: an engine's model must equal the scenario before the first step.

Each quantity of the engine's ``ModelReport`` is compared with the scenario's
``reference_report`` to a relative tolerance, the engine's precision's
(``PRECISION_TOLERANCE``), of the quantity's physical magnitude (``Magnitudes``): a body's
mass, its distance from the origin plus its reach, its largest inertia entry; for the totals
the sum of their terms' sizes, which do not cancel (``Σ m |v|`` for a linear momentum of
bodies moving apart, whose total is zero). A mismatch names the quantity, the body and both
values, and becomes a result row with status ``model_mismatch``.
"""

from __future__ import annotations

from dataclasses import dataclass, field, fields

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
"""Absolute floor in the quantity's SI unit, for quantities whose magnitude is zero in the
scene (the momentum of a scene at rest, a body at the origin): below it, a difference is
round-off."""


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
    item: str | None = None
    """The scene joint a joint field's mismatch is of (``joint_parity``); None otherwise (a
    body's row is ``body``)."""

    def __str__(self) -> str:
        where = f" of body {self.body}" if self.body is not None else ""
        if self.problem:
            return f"{self.quantity}{where}: {self.problem}"
        return (
            f"{self.quantity}{where}: engine {self.engine_value}, scenario {self.expected} "
            f"(relative error {self.relative_error:.3g} > {self.tolerance})"
        )


def _relative(
    engine: np.ndarray, expected: np.ndarray, magnitude: float, tolerance: float
) -> float:
    """The largest difference of ``engine`` from ``expected`` relative to the quantity's
    physical ``magnitude`` (``ABSOLUTE_FLOOR`` below it is round-off whatever the magnitude)."""
    scale = max(float(magnitude), ABSOLUTE_FLOOR / tolerance)
    return float(np.max(np.abs(engine - expected), initial=0.0)) / scale


QUANTITIES = tuple(f.name for f in fields(ModelReport))
"""The fields of a ``ModelReport``, in the order the gate reports them."""

PER_BODY = ("mass", "com", "inertia_world")
"""The quantities a ``ModelReport`` has one row of per dynamic body; the others are totals."""


@dataclass(frozen=True)
class Magnitudes:
    """The physical size of each quantity of a ``ModelReport`` (its fields, in its order),
    what its error is relative to (``reference.magnitudes``): the size of every term the
    quantity adds, none cancelling, so a total that is zero in the scene (two bodies moving
    apart) is judged against what its terms round off, not against zero.

    Attributes:
        mass: (d,) kg, each body's mass.
        com: (d,) m, each body's distance from the origin plus its radius of gyration (how
            far its mass reaches: the size a shape's centre is computed to).
        inertia_world: (d,) kg·m², each body's largest inertia entry.
        energy: J, ``Σ ½ m |v|² + ½ ωᵀ I ω + |m g·x| + |F·x|`` plus the spring energy.
        linear_momentum: kg·m/s, ``Σ m |v|``.
        angular_momentum: kg·m²/s, ``Σ m |(x - c) × (v - v_c)| + |I ω|`` about the centre of
            mass c moving at v_c (``metrics.angular_momentum_drift``'s scale).
    """

    mass: np.ndarray
    com: np.ndarray
    inertia_world: np.ndarray
    energy: float
    linear_momentum: float
    angular_momentum: float


@dataclass(frozen=True)
class ExpectedReport(ModelReport):
    """What the gate expects (``reference.reference_report``): the scene's ``ModelReport``
    and the ``Magnitudes`` its errors are relative to."""

    magnitudes: Magnitudes = field(compare=False)


def own_magnitudes(report: ModelReport) -> Magnitudes:
    """Magnitudes read off a report's own values, each body's largest entry and each total's
    largest component: for an expected report that carries no scene (not an
    ``ExpectedReport``); a total that cancels reads zero here, the floor alone."""

    def largest(quantity: str) -> np.ndarray:
        values = np.abs(np.asarray(getattr(report, quantity), dtype=np.float64))
        first = 1 if quantity in PER_BODY else 0
        return values.max(axis=tuple(range(first, values.ndim)), initial=0.0)

    return Magnitudes(*(largest(q) for q in QUANTITIES))


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


def magnitudes_of(expected: ModelReport) -> Magnitudes:
    """The magnitudes the errors against ``expected`` are relative to: the scene's
    (``ExpectedReport``), else the report's own values (``own_magnitudes``)."""
    if isinstance(expected, ExpectedReport):
        return expected.magnitudes
    return own_magnitudes(expected)


def _mismatch(quantity: str, body: int | None, got, want, magnitude, tolerance) -> Mismatch | None:
    """The mismatch of one quantity (one body's row of it), None within ``tolerance``."""
    error = _relative(np.asarray(got), np.asarray(want), magnitude, tolerance)
    if error <= tolerance:
        return None
    shown = (np.round(got, 12).tolist(), np.round(want, 12).tolist())
    return Mismatch(quantity, body, *shown, error, tolerance)


def compare(
    engine: ModelReport, expected: ModelReport, tolerance: float = PARITY_TOLERANCE
) -> list[Mismatch]:
    """Every quantity of ``engine`` that differs from ``expected`` beyond ``tolerance``
    (``PRECISION_TOLERANCE`` of the engine's declared precision) relative to the quantity's
    magnitude (``magnitudes_of``); a quantity of the wrong shape or not finite (``unusable``)
    is a mismatch before any is compared."""
    mismatches = unusable(engine, expected)
    if mismatches:
        return mismatches
    magnitudes = magnitudes_of(expected)
    found = [
        _mismatch(
            quantity,
            body,
            getattr(engine, quantity)[body],
            getattr(expected, quantity)[body],
            getattr(magnitudes, quantity)[body],
            tolerance,
        )
        for quantity in PER_BODY
        for body in range(len(getattr(expected, quantity)))
    ]
    found += [
        _mismatch(
            quantity,
            None,
            getattr(engine, quantity),
            getattr(expected, quantity),
            getattr(magnitudes, quantity),
            tolerance,
        )
        for quantity in QUANTITIES
        if quantity not in PER_BODY
    ]
    return [mismatch for mismatch in found if mismatch is not None]


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
