"""When two runs' readings of one row differ: the noise rule, defined once (and in the legend).

One function, ``classify_change(before, now)``, decides the class of a change, for the baseline
(``validation.nightly.baseline``), ``physval compare`` and the history's step detection alike.
The same scene and versions give the same numbers bit for bit (serial, parallel or distributed),
so any difference between two runs on one machine is real; between machines (another CPU, BLAS
or compiler) round-off differs, and a scene amplifies it as far as its dynamics do. The floor is
measured (``benchmarks/noise_spread.py``: the library with every initial position moved by
1e-12 m), not guessed. The rule, in order:

1. the verdict's rank changed (passed -> failed, ok -> unstable): ``regressed`` / ``improved``;
2. both rows have an error (``error`` not NaN): finite -> inf ``regressed``, inf -> finite
   ``improved``, inf -> inf as nothing moved; two finite errors moved when

       |Δerror| > max(relative · max(|error_a|, |error_b|), absolute)

   (``RELATIVE_NOISE``, ``ABSOLUTE_NOISE``, or the row's or scene's own in ``NOISE_FLOORS``,
   measured where the regular floor is too tight: piles, stacks, an unstable balance): ``regressed``
   when the error grew, ``improved`` when it shrank; and ``regressed`` when its size held but
   the signed error (``validation.contract.SIGNED_COLUMNS``) moved by more than the same floor
   (its sign or direction changed: the engine's behaviour changed, nothing says for the better);
3. an error that is lost (number -> NaN: the check no longer measures anything) is
   ``regressed``; one that appears (NaN -> number) is ``changed``;
4. a row without an error in either run (a fitted convergence order, a cross-check, a metric
   without an expected value) is judged on its ``value`` by the same floor, and so are NaN and
   inf values: a move is ``changed`` (neither better nor worse, but news);
5. a verdict that changed within one rank (failed -> unstable) with numbers that did not move
   is ``changed``; otherwise ``unchanged``.

``changed`` fails a run against a baseline like ``regressed``. A ``divergence`` row measures an
engine against the scene's reference engine; when the reference moved and the row's own engine
did not, its move is the reference's: ``reference_moved`` (``attribute_divergence``), which does
not fail the run (the reference engine's own rows carry the regression).
"""

from __future__ import annotations

import math
from collections.abc import Iterable
from dataclasses import dataclass

import numpy as np

RELATIVE_NOISE = 1e-5
"""A row moved when its number changed by more than this fraction of its size. Measured
(``benchmarks/noise_spread.py``: the library in mini, every initial position moved by 1e-12 m in
two seeded directions): the largest relative spread of a row above 1e-9 outside ``NOISE_FLOORS``
was 5.2e-7 (box_incline_oblique, position_at.speeding: 7.7e-11 m of 1.5e-4 m); the median of
all rows 6.8e-11. Ten times the largest, rounded up to a power of ten; still 3,000 times below
a 3 % change of a rebound, and it makes a 19x move news whatever the tolerance."""

ABSOLUTE_NOISE = 3e-9
"""In the metric's SI unit: a change below this is round-off of a quantity that is 0 up to
round-off. Measured (as above): the largest spread of a row whose number is below 1e-9 was
2.2e-10 (box_incline_oblique, penetration_max), and of any row outside ``NOISE_FLOORS`` 2.3e-9
(stiff_spring_chain, velocity_at.outer: of 0.146 m/s, so within ``RELATIVE_NOISE``); ten times
the first, rounded up to 1 or 3 times a power of ten. The rotation scenes, run again with the
angular velocities perturbed by 1e-12 rad/s too (a position alone leaves a free body's
rotation untouched): largest relative spread 1.2e-9 (constant_torque_spin_up) outside the
Dzhanibekov sweep, which has its own floors."""

FLOOR_MARGIN = 10.0
"""Each floor is this many times the spread measured: two perturbed directions sample the
spread of one machine's round-off, another machine may land further out."""

CHAOTIC_RELATIVE = 0.9
"""The largest relative floor (a tenfold change of the error is always news): for the scenes
whose measured relative spread times ``FLOOR_MARGIN`` reaches it."""


@dataclass(frozen=True)
class Floor:
    """The noise floor of a row: ``max(relative · max(|a|, |b|), absolute)``."""

    relative: float = RELATIVE_NOISE
    absolute: float = ABSOLUTE_NOISE
    why: str = "regular: the measured spread of the library's rows"


REGULAR = Floor()
"""The floor of every row that ``NOISE_FLOORS`` does not name."""

NOISE_FLOORS: dict[str, Floor] = {
    "box_stack": Floor(
        CHAOTIC_RELATIVE,
        why="a stack of five boxes: contact order amplifies round-off; measured relative spread "
        "0.69 (velocity_at.box5, 9.1e-8 m/s), 0.49 (penetration_max), 0.33 (energy_drift)",
    ),
    "deep_initial_penetration": Floor(
        CHAOTIC_RELATIVE,
        why="two boxes resolved out of a 4 cm overlap: measured relative spread 0.33 "
        "(energy_drift, 1.4e-7), 0.17 (velocity_at.upper)",
    ),
    "simbenchmark_666_pile": Floor(
        1e-4,
        why="a pile of 666 spheres: measured relative spread 6.3e-6 (energy_drift), 1.9e-6 "
        "(restitution_error)",
    ),
    "millimetre_spheres/position_at.upper": Floor(
        absolute=1e-5,
        why="a sphere balanced on another (an unstable equilibrium): its position error grew "
        "from 1.9e-10 m to 1.3e-6 m under the perturbation; the scene's other rows are regular",
    ),
    "dzhanibekov_flip_times": Floor(
        absolute=3e-8,
        why="the tumble's sweep is judged against a DOP853 reference accurate to about 1e-9 rad: "
        "measured (angular velocities perturbed by 1e-12 rad/s too) spread 3.3e-9 of the "
        "cross-check with MuJoCo RK4, 8.5e-10 of RK4's orientation errors (5.5e-9 at dt 1e-3)",
    ),
    "dzhanibekov_flip_times/sweep_order.orientation_error": Floor(
        3e-2,
        3e-8,
        why="RK4's fitted order (3.99) rests on errors near the reference's accuracy: measured "
        "spread 0.011 (and one perturbed run could not fit it: NaN); mini's orders spread 1e-10",
    ),
    "head_on_ratio_1/angular_momentum_drift": Floor(
        absolute=10.0,
        why="a relative drift of an angular momentum that is 0 (a head-on impact): round-off "
        "over round-off, measured spread 0.034; judged on its verdict and inf/NaN only",
    ),
    "head_on_ratio_1e6/angular_momentum_drift": Floor(
        absolute=10.0,
        why="as head_on_ratio_1: measured spread 1.0 (5.8e-11 became 1.0)",
    ),
}
"""The rows whose measured spread exceeds the regular floors, by scene (``scene``) or by row
(``scene/metric``), each with the floor derived from its measurement (``FLOOR_MARGIN`` times
the spread; ``CHAOTIC_RELATIVE`` at most). Only these get a looser floor; a new scene is
regular until measured (``benchmarks/noise_spread.py`` prints every scene's spread)."""


def floor_for(scene: object = None, metric: object = None) -> Floor:
    """The floor of a row of ``scene`` (``NOISE_FLOORS``: the row's own, else its scene's)."""
    return NOISE_FLOORS.get(f"{scene}/{metric}") or NOISE_FLOORS.get(str(scene)) or REGULAR


LARGE_IMPROVEMENT = 2.0
"""An ``improved`` row whose error shrank at least this many times (or from inf to finite) is
listed in the news with the regressions: as much as halving the step of a first-order
integrator gives, which no refactor gives by accident, so it asks for an explanation (a fixed
bug, a changed expectation) before the baseline is saved again."""

DIVERGENCE = "divergence"
"""The metric measured against the scene's reference engine (its ``expected_kind`` is
``engine:<label>``)."""

REFERENCE_MOVED = "reference_moved"
"""A divergence row that moved because its reference engine moved."""

MOVES = ("regressed", "changed", "improved")
"""The classes of a row that moved (``reference_moved`` rows moved too, attributed)."""

FAILS_A_RUN = ("regressed", "changed")
"""The classes that fail a run against a baseline."""

NOISE_RULE = (
    "a row moved when its verdict's rank changed, or its error changed by more than "
    f"max({RELATIVE_NOISE:g}·max(|error|), {ABSOLUTE_NOISE:g}) (floors measured under a 1e-12 m "
    "perturbation of the initial state; larger measured floors for "
    + ", ".join(sorted(NOISE_FLOORS))
    + "); "
    "regressed if the error grew, became inf or was lost (NaN), or its size held while the "
    "signed error moved by more than the floor; improved if it shrank or inf became finite "
    "(listed in the news when it shrank "
    f"{LARGE_IMPROVEMENT:g}x or more); a row without an error is judged on its value: changed "
    "(fails the run like a regression); a divergence row reads reference_moved when only its "
    "reference engine moved (not a failure: the reference's own rows carry it)"
)
"""The rule in one line, for the legends and the README."""


@dataclass(frozen=True)
class Reading:
    """One run's row as the noise rule reads it."""

    error: float = math.nan
    """The error's size (NaN: the row has none; inf: it never converged, never happened)."""
    value: float = math.nan
    signed: np.ndarray | None = None
    """The signed error: (1,) a scalar's, (3,) a vector's, None when the run lacks it."""
    rank: int | None = None
    """How good the verdict is (higher is better, ``nightly.baseline.VERDICT_RANK``); None for
    a number without a verdict (a level of the history)."""
    verdict: str = ""


def noise_floor(a: float, b: float, floor: Floor = REGULAR) -> float:
    """The largest change between two finite numbers of a row that is not news."""
    scale = max(abs(a), abs(b))
    return max(floor.relative * scale if math.isfinite(scale) else 0.0, floor.absolute)


def moved(a: float, b: float, floor: Floor = REGULAR) -> int:
    """+1 when the number grew beyond noise from ``a`` to ``b``, -1 when it shrank, else 0.
    NaN is no number: NaN -> NaN 0, NaN <-> a number +1 (a move of no direction); inf is a
    number beyond any: finite -> +inf +1, +inf -> finite -1, equal infinities 0."""
    if math.isnan(a) or math.isnan(b):
        return 0 if math.isnan(a) and math.isnan(b) else 1
    if math.isinf(a) or math.isinf(b):
        return 0 if a == b else (1 if b > a else -1)
    change = b - a
    if abs(change) <= noise_floor(a, b, floor):
        return 0
    return 1 if change > 0 else -1


def _signed_moved(before: Reading, now: Reading, floor: Floor) -> bool:
    """The error's size held: did its sign or direction move beyond the floor?"""
    a, b = before.signed, now.signed
    if a is None or b is None or a.shape != b.shape:
        return False
    shift = float(np.linalg.norm(b - a))
    return shift > noise_floor(before.error, now.error, floor)


def _error_change(before: Reading, now: Reading, floor: Floor) -> str:
    """Rule 2 and 3: the class of a row that has an error in at least one run."""
    lost, appeared = math.isnan(now.error), math.isnan(before.error)
    if lost or appeared:
        return "regressed" if lost else "changed"
    direction = moved(before.error, now.error, floor)
    if direction:
        return "regressed" if direction > 0 else "improved"
    finite = math.isfinite(before.error) and math.isfinite(now.error)
    return "regressed" if finite and _signed_moved(before, now, floor) else "unchanged"


def classify_change(before: Reading, now: Reading, floor: Floor = REGULAR) -> str:
    """The class of one row from ``before`` to ``now`` (the module's rule): ``regressed``,
    ``improved``, ``changed`` or ``unchanged``; ``floor`` the row's (``floor_for``)."""
    if before.rank is not None and now.rank is not None and before.rank != now.rank:
        return "regressed" if now.rank < before.rank else "improved"
    if not (math.isnan(before.error) and math.isnan(now.error)):
        change = _error_change(before, now, floor)
    else:
        change = "changed" if moved(before.value, now.value, floor) else "unchanged"
    if change == "unchanged" and before.verdict != now.verdict:
        return "changed"
    return change


def divergence_reference(metric: str, expected_kind: object) -> str | None:
    """The reference engine of a ``divergence`` row (its ``expected_kind``: ``engine:LABEL``),
    '' when the row does not say; None for every other metric."""
    if metric != DIVERGENCE:
        return None
    kind = expected_kind if isinstance(expected_kind, str) else ""
    return kind.removeprefix("engine:") if kind.startswith("engine:") else ""


def attribute_divergence(rows: Iterable[dict], key: str) -> list[str]:
    """Each row's class (``rows[i][key]``), a moved divergence row's turned ``reference_moved``
    when its scene's reference engine moved and its own engine did not. ``rows``: dicts with
    scenario, engine, metric, the class under ``key``, and optionally ``expected_kind`` and
    ``version_moved`` (the engine's version differs between the runs). An engine *moved* in a
    scene when one of its own rows there (not a divergence row) moved (``MOVES``) or its version
    changed. The reference is the one named by the row, else the scene's one engine without a
    divergence row (``compare_scene``: the first engine that ran)."""
    rows = list(rows)
    moved_engines = {
        (r["scenario"], r["engine"])
        for r in rows
        if r["metric"] != DIVERGENCE and (r[key] in MOVES or r.get("version_moved"))
    }
    engines: dict[str, set[str]] = {}
    measured_against: dict[str, set[str]] = {}
    for r in rows:
        engines.setdefault(r["scenario"], set()).add(r["engine"])
        if r["metric"] == DIVERGENCE:
            measured_against.setdefault(r["scenario"], set()).add(r["engine"])
    classes = []
    for r in rows:
        named = divergence_reference(r["metric"], r.get("expected_kind"))
        if named is None or r[key] not in MOVES:
            classes.append(r[key])
            continue
        scene = r["scenario"]
        candidates = engines[scene] - measured_against.get(scene, set())
        reference = named or (next(iter(candidates)) if len(candidates) == 1 else "")
        blame = (scene, reference) in moved_engines and (scene, r["engine"]) not in moved_engines
        classes.append(REFERENCE_MOVED if blame else r[key])
    return classes


def large_improvement(error_before: float, error_now: float) -> bool:
    """Whether an improvement is large enough to be news (``LARGE_IMPROVEMENT``)."""
    if math.isnan(error_before) or math.isnan(error_now):
        return False
    if math.isinf(error_before):
        return math.isfinite(error_now)
    return abs(error_now) * LARGE_IMPROVEMENT <= abs(error_before) and error_before != error_now
