"""Step detection: the run at which a metric moved, from its history.

The idea is asv's (airspeed velocity, ``asv/step_detect.py``: ``detect_steps`` and
``solve_potts``, after Friedrich et al., "Complexity penalized M-estimation", J. Comput. Graph.
Stat. 17, 2008): fit the series with a piecewise-constant function minimising

    F = Σ_segments Σ_i (y_i − mean_segment)²  +  γ · (number of segments)

exactly, by dynamic programming over the segment boundaries (optimal partitioning, O(n²)).
asv fits the L1 cost (medians) and chooses γ by an information criterion; here it is the L2 cost
(means), written for numpy and batched over all series of a history at once (one vectorised
update per right edge: 1,000 series of 365 runs fit in about a second), with a documented penalty:

    γ = PENALTY_PER_LOG_RUN · ln(n) · σ²

(twice the Schwarz/BIC penalty of a change point in Gaussian noise, 2 σ² ln n), where σ
is the series' noise: the robust scatter of its run-to-run differences (MAD / 0.6745 / √2,
unaffected by a few steps), but never below half the noise rule's floor
(``validation.measure.noise.noise_floor``), because physval's runs on one machine are bit-identical
and their σ would otherwise be 0. The fit proposes steps; the noise rule disposes: neighbouring
segments whose levels the rule does not call a move (``noise.classify_change`` of the two
levels is ``unchanged``: the rule of the baseline and of ``compare``) are merged.

A series' points are the runs that measured it: a run without a number (NaN: the run did not
select the scene, or its row has no value) is left out of the fit, so a step is always placed at
a run that measured the series, never at a run in between that did not. An infinite value (an
error that overflowed) is a number beyond any: the change between finite and infinite is a step
by itself, at the first run of the new class; the finite values alone are fitted as above.
"""

from __future__ import annotations

import itertools
from dataclasses import dataclass

import numpy as np

from validation.measure.noise import REGULAR, Floor, Reading, classify_change, moved, noise_floor

PENALTY_PER_LOG_RUN = 4.0
"""γ / (σ² ln n): BIC gives 2 per change point; asv's criterion counts 4 degrees of freedom per
breakpoint, and so does this. Measured on 365-run Gaussian series: 0 false steps in 1,000 pure-noise
series (3 gave 4), and a 3 σ step held for the last 10 runs found at its exact run 83 % of the
time, a 2 σ step held for 30 runs 86 %."""

MAD_TO_SIGMA = 1.4826
"""A Gaussian's standard deviation per median absolute deviation (1 / Φ⁻¹(3/4))."""

FLOOR_TO_SIGMA = 0.5
"""σ is at least this times the noise floor: a change within the floor is noise, read as ±2 σ."""


@dataclass(frozen=True)
class Step:
    """A change of level in one series: at run position ``at`` (the first run of the new level)."""

    at: int
    before: float
    after: float
    direction: int
    """+1 the quantity grew beyond noise (an error: worse), -1 it shrank."""


def noise_sigma(values: np.ndarray, floors: list[Floor]) -> np.ndarray:
    """σ per series (rows of ``values``, NaN missing): the robust scatter of consecutive
    differences, at least ``FLOOR_TO_SIGMA`` times the noise floor at the series' level."""
    sigma = np.zeros(values.shape[0])
    allowed = np.zeros(values.shape[0])
    for i, (row, floor) in enumerate(zip(values, floors, strict=True)):
        finite = row[np.isfinite(row)]
        if finite.size == 0:
            continue
        level = float(np.median(np.abs(finite)))
        allowed[i] = noise_floor(level, level, floor)
        if finite.size > 2:
            sigma[i] = MAD_TO_SIGMA * np.median(np.abs(np.diff(finite))) / np.sqrt(2.0)
    return np.maximum(sigma, FLOOR_TO_SIGMA * allowed)


def optimal_partition(values: np.ndarray, penalty: float | np.ndarray) -> np.ndarray:
    """The exact penalized L2 piecewise-constant fit of every row of ``values`` (runs along
    axis 1, NaN for a run without the row, which then costs nothing), in units where each row's
    σ is 1; ``penalty`` one for all rows or one per row. Returns ``left (series, n + 1)``:
    ``left[s, r]`` the start of the last segment of the best fit of the first ``r`` runs of
    series ``s`` (walk it back with ``segment_starts``). A NaN between two levels makes a tie
    (either side of it costs the same), so callers fit packed rows (``packed_finite``)."""
    count, n = values.shape
    penalty = np.broadcast_to(np.asarray(penalty, dtype=float), (count,))[:, None]
    present = np.isfinite(values)
    y = np.where(present, values, 0.0)
    zero = np.zeros((count, 1))
    weight = np.hstack([zero, np.cumsum(present, axis=1)])
    total = np.hstack([zero, np.cumsum(y, axis=1)])
    square = np.hstack([zero, np.cumsum(y * y, axis=1)])
    best = np.empty((count, n + 1))
    best[:, 0] = -penalty[:, 0]
    left = np.zeros((count, n + 1), dtype=int)
    for r in range(1, n + 1):
        w = weight[:, r : r + 1] - weight[:, :r]
        s = total[:, r : r + 1] - total[:, :r]
        cost = square[:, r : r + 1] - square[:, :r] - s * s / np.maximum(w, 1.0)
        candidates = best[:, :r] + penalty + np.maximum(cost, 0.0)  # round-off can go below 0
        left[:, r] = np.argmin(candidates, axis=1)
        best[:, r] = candidates[np.arange(count), left[:, r]]
    return left


def segment_starts(left_row: np.ndarray) -> list[int]:
    """The first run of every segment of one series' fit, in order."""
    starts, r = [], left_row.size - 1
    while r > 0:
        r = int(left_row[r])
        starts.append(r)
    return starts[::-1]


def segment_levels(row: np.ndarray, starts: list[int]) -> list[float]:
    """The mean of each segment of ``row`` (segments begin at ``starts``; NaN runs skipped)."""
    bounds = [*starts, row.size]
    return [
        float(np.nanmean(row[a:b])) if np.isfinite(row[a:b]).any() else float("nan")
        for a, b in itertools.pairwise(bounds)
    ]


def level_moved(before: float, after: float, floor: Floor) -> bool:
    """Whether the noise rule calls the change between two levels of a series a move."""
    return classify_change(Reading(error=before), Reading(error=after), floor) != "unchanged"


def merge_within_noise(row: np.ndarray, starts: list[int], floor: Floor) -> list[Step]:
    """The fit's boundaries that the noise rule calls a move, as steps (neighbouring segments
    whose levels are within noise are merged first, then the levels recomputed)."""
    starts = list(starts)
    while True:
        levels = segment_levels(row, starts)
        still = [
            k
            for k in range(1, len(starts))
            if not level_moved(levels[k - 1], levels[k], floor) or np.isnan(levels[k])
        ]
        if not still:
            break
        del starts[still[0]]
    return [
        Step(starts[k], levels[k - 1], levels[k], moved(levels[k - 1], levels[k], floor))
        for k in range(1, len(starts))
    ]


def within_noise(values: np.ndarray, floors: list[Floor]) -> np.ndarray:
    """Per series, True when its whole range is within the noise floor, so that no two levels
    of any fit can differ by a move (the usual nightly series: bit-identical runs). Exact: two
    levels lie in [low, high], and the floor at the smaller magnitude is the least of theirs."""
    with np.errstate(all="ignore"):
        low = np.where(np.isfinite(values), values, np.inf).min(axis=1)
        high = np.where(np.isfinite(values), values, -np.inf).max(axis=1)
    magnitude = np.where(low * high > 0, np.minimum(np.abs(low), np.abs(high)), 0.0)
    return np.array(
        [
            not np.isfinite(hi - lo) or hi - lo <= noise_floor(m, m, floor)
            for lo, hi, m, floor in zip(low, high, magnitude, floors, strict=True)
        ],
        dtype=bool,
    )


def packed_finite(values: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Per row, its finite values moved to the front in run order and NaN after them, the run
    position of each packed column (``order``) and the count of finite values per row."""
    finite = np.isfinite(values)
    order = np.argsort(~finite, axis=1, kind="stable")  # finite first, each in run order
    counts = finite.sum(axis=1)
    packed = np.take_along_axis(values, order, axis=1)
    packed[np.arange(values.shape[1])[None, :] >= counts[:, None]] = np.nan
    return packed, order, counts


def finite_steps(values: np.ndarray, floors: list[Floor]) -> list[list[Step]]:
    """The steps of the finite values of each series (infinite and NaN runs left out), at
    run positions of ``values``: the fit runs on the packed finite values, so that no step
    falls on a run without one."""
    found: list[list[Step]] = [[] for _ in range(values.shape[0])]
    packed, order, counts = packed_finite(values)
    fitted = np.nonzero((counts >= 2) & ~within_noise(packed, floors))[0]
    if fitted.size == 0:
        return found
    width = int(counts[fitted].max())
    rows, fitted_floors = packed[fitted, :width], [floors[i] for i in fitted]
    sigma = noise_sigma(rows, fitted_floors)
    centre = np.nanmedian(rows, axis=1)[:, None]  # every fitted row has a finite value
    scaled = (rows - centre) / sigma[:, None]  # sigma >= half the floor > 0
    penalty = PENALTY_PER_LOG_RUN * np.log(counts[fitted])  # the runs that measured it
    left = optimal_partition(scaled, penalty)
    for index, row, left_row, floor in zip(fitted, rows, left, fitted_floors, strict=True):
        count = int(counts[index])
        starts = [k for k in segment_starts(left_row) if k < count]  # a NaN tail adds no start
        for step in merge_within_noise(row[:count], starts, floor):
            found[index].append(
                Step(int(order[index, step.at]), step.before, step.after, step.direction)
            )
    return found


def infinite_steps(row: np.ndarray, steps: list[Step]) -> list[Step]:
    """``steps`` (the finite fit's, of one series) with a step wherever the series crosses
    between finite and infinite values (or between -inf and +inf), at the first run of the
    new class; ``before`` / ``after`` are the finite level there or the infinite value. A
    finite step at the same run gives way to the crossing."""
    measured = np.nonzero(~np.isnan(row))[0]
    kinds = np.where(np.isfinite(row[measured]), 0, np.sign(row[measured]))
    if not kinds.any():
        return steps
    finite_row = np.where(np.isfinite(row), row, np.nan)
    starts = [0, *(s.at for s in steps)]
    levels = np.full(row.size, np.nan)
    for start, stop, level in zip(
        starts, [*starts[1:], row.size], segment_levels(finite_row, starts), strict=True
    ):
        levels[start:stop] = level

    def level(position: int) -> float:
        return float(row[position]) if np.isinf(row[position]) else float(levels[position])

    crossings = {
        int(b): Step(int(b), level(a), level(b), 1 if level(b) > level(a) else -1)
        for a, b, kind_a, kind_b in zip(measured, measured[1:], kinds, kinds[1:], strict=False)
        if kind_a != kind_b
    }
    kept = [s for s in steps if s.at not in crossings]
    return sorted([*kept, *crossings.values()], key=lambda s: s.at)


def detect_steps(values: np.ndarray, floors: list[Floor] | None = None) -> list[list[Step]]:
    """The steps of each series: ``values (series, runs)`` with NaN where a run has no number
    for the series (did not measure it, or its row has no value), ±inf where the number is
    infinite; ``floors (series,)`` each series' noise floor (``noise.floor_for`` of its scene
    and metric; None: ``noise.REGULAR`` for all). The finite values of a series are
    fitted (``finite_steps``: fewer than 2 of them, or a range within noise, give none), and
    every crossing between finite and infinite values is a step (``infinite_steps``). Every
    step is at a run that measured the series."""
    values = np.asarray(values, dtype=float)
    if values.ndim != 2:
        return []
    if values.shape[1] < 2:
        return [[] for _ in range(values.shape[0])]
    floors = list(floors) if floors is not None else [REGULAR] * values.shape[0]
    found = finite_steps(values, floors)
    return [infinite_steps(row, steps) for row, steps in zip(values, found, strict=True)]
