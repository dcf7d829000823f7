"""Impact events, and the records of them a run keeps: bounded by named constants, never by
the number of impacts (``ImpactEvent`` is found by ``recording.ImpactDetector``).

A run may have millions of impacts (10,000 spheres bouncing for 5 s in PyBullet: 1.4
million, about 950 bytes each as ``ImpactEvent``: 1.4 GB), and it keeps what reads them need:
``restitution_error`` (the impact with the largest |Δe| beyond its band, and how many there
were), impacts.csv, and the report's impacts table (the largest |Δe| per engine) and its
e-against-speed chart (an even spread). As each impact closes, the log counts it and keeps:

- an evenly spaced sample in closing order: every impact while there are at most
  ``MAX_SAMPLED_IMPACTS``; beyond, every s-th one (s a power of two, doubled each time the
  sample outgrows the bound, the impacts off the new stride dropped), so between half the
  bound and the bound of them, spread over the whole run;
- the ``MAX_WORST_IMPACTS`` worst by each ranking of ``RANKINGS``: |Δe| beyond the band (what
  ``restitution_error`` reports) and |Δe| (the report's max |Δe|); ties go to the earlier
  impact and a NaN ranks worst (the first one), as ``np.argmax`` picks over all of them, so
  the impact ``restitution_error`` would pick from every impact is always kept.

``events()`` is the union, in closing order: for a run of at most ``MAX_SAMPLED_IMPACTS``
impacts (every run of the library's scenes) every impact, exactly as it closed.
"""

from __future__ import annotations

import heapq
import math
from collections.abc import Callable, Iterable
from dataclasses import dataclass, field
from typing import TYPE_CHECKING

import numpy as np

from validation.measure.restitution import restitution_band

if TYPE_CHECKING:
    from validation.scenario.compiled import CompiledScene

MAX_SAMPLED_IMPACTS = 10_000
"""Impacts a run keeps in its evenly spaced sample (``ImpactLog``), every one up to this
many: the library's busiest run (simbenchmark_666_pile in PyBullet) has 2,362 impacts, and
10,000 records are about 10 MB (``ImpactEvent``s of about 950 bytes with their per-body
accelerations, measured with tracemalloc) in the worker and the command's process, and
1.5 MB of impacts.csv."""

MAX_WORST_IMPACTS = 100
"""Impacts kept per ranking of ``RANKINGS`` besides the sample: the worst ones, which the
report's table and ``restitution_error`` read, whatever the sample has thinned out."""

KEPT_IMPACTS_BOUND = MAX_SAMPLED_IMPACTS + MAX_WORST_IMPACTS * 2
"""The most impact records a run keeps (the sample and both rankings' worst)."""


@dataclass(frozen=True, slots=True)
class ImpactEvent:
    """One impact of two bodies (or a body and the ground).

    Attributes:
        body_a, body_b: names (``ground`` for the plane); the normal points from A to B.
        time_start: s, the first observation in contact. time_end: s, the first one apart
            (for a plastic impact, e = 0: the observation that closed it while still touching).
        normal: (3,) unit, world frame, at first contact.
        normal_velocity_before: m/s, ``(v_PB - v_PA)·n`` just before the impulse (< 0).
        normal_velocity_after: m/s, the same just after (both carried to the impulse centroid).
        time_impulse: s, the impulse centroid (for a one-step impulse: the end of that step).
        approach_acceleration: m/s², the relative normal acceleration before contact (what
            acts besides the impulse: gravity, a support); step: s, between observations.
        acceleration_a, acceleration_b: (3,) m/s², world frame, each body's acceleration
            over the observed step before the contact (what acted on it then: g + F/m in free
            flight, nothing net on a body resting on a support; zeros for the ground); None
            when fewer than two states before the contact were observed.
        angular_acceleration_a, angular_acceleration_b: (3,) rad/s², the same for ω.
    """

    body_a: str
    body_b: str
    time_start: float
    time_end: float
    time_impulse: float
    normal: tuple[float, float, float]
    normal_velocity_before: float
    normal_velocity_after: float
    approach_acceleration: float = 0.0
    step: float = 0.0
    acceleration_a: tuple[float, float, float] | None = None
    acceleration_b: tuple[float, float, float] | None = None
    angular_acceleration_a: tuple[float, float, float] | None = None
    angular_acceleration_b: tuple[float, float, float] | None = None

    def acceleration_of(self, body: str) -> np.ndarray | None:
        """(3,) m/s², body ``body``'s observed acceleration before the contact (or None)."""
        found = self.acceleration_a if body == self.body_a else self.acceleration_b
        return None if found is None else np.array(found)

    def angular_acceleration_of(self, body: str) -> np.ndarray | None:
        """(3,) rad/s², body ``body``'s observed angular acceleration before the contact."""
        found = self.angular_acceleration_a if body == self.body_a else self.angular_acceleration_b
        return None if found is None else np.array(found)

    @property
    def restitution(self) -> float:
        """Measured e = -(v_rel'·n)/(v_rel·n) (formulas.md section 5)."""
        return -self.normal_velocity_after / self.normal_velocity_before

    def band(self, requested: float) -> float:
        """The discretization band of e_measured for a requested ``e`` (module docstring of
        ``validation.measure.restitution``): ``(1 + e) |a·n| h / |v_before|``."""
        return restitution_band(
            requested, self.approach_acceleration, self.step, self.normal_velocity_before
        )


def restitution_error_of(event: ImpactEvent, requested: float) -> tuple[float, float]:
    """(|Δe|, band) of one impact for a requested e: ``|e_measured - e|`` and its
    discretization band (``ImpactEvent.band``)."""
    return abs(event.restitution - requested), event.band(requested)


RANKINGS: dict[str, Callable[[float, float], float]] = {
    "beyond_band": lambda error, band: error - band,
    "delta_e": lambda error, band: error,
}
"""How impacts are ranked worst, from (|Δe|, band): by how far |Δe| is beyond the band
(``restitution_error``), by |Δe| alone (the report's max |Δe| per engine)."""


def _worse_first(score: float, ordinal: int) -> tuple[bool, float, int]:
    """A heap key that orders impacts from the least bad: a NaN is worse than any number (the
    first NaN is what ``np.argmax`` picks), then the larger score, then the earlier impact."""
    nan = math.isnan(score)
    return (nan, 0.0 if nan else score, -ordinal)


@dataclass
class ImpactLog:
    """The impacts of one run as they close: their count, an evenly spaced sample and the
    worst of each ranking (module docstring)."""

    scene: CompiledScene
    count: int = 0
    """Impacts closed so far (every one, kept or not)."""
    stride: int = 1
    """The sample keeps the impacts whose ordinal (0-based, closing order) it divides."""
    sample: list[tuple[int, ImpactEvent]] = field(default_factory=list)
    worst: dict[str, list] = field(default_factory=lambda: {name: [] for name in RANKINGS})
    """Ranking -> a min-heap of ``(_worse_first key, event)``, at most ``MAX_WORST_IMPACTS``."""
    requested: dict[tuple[str, str], float] = field(default_factory=dict)
    """The scene's e per pair of body names, looked up once per pair."""

    def add(self, events: Iterable[ImpactEvent]) -> None:
        """Count and keep ``events`` (consecutive, in closing order)."""
        for event in events:
            self._add(self.count, event)
            self.count += 1

    def _add(self, ordinal: int, event: ImpactEvent) -> None:
        if ordinal % self.stride == 0:
            self.sample.append((ordinal, event))
            if len(self.sample) > MAX_SAMPLED_IMPACTS:
                self.stride *= 2
                self.sample = [(k, e) for k, e in self.sample if k % self.stride == 0]
        error, band = restitution_error_of(event, self._requested(event))
        for name, rank in RANKINGS.items():
            heap = self.worst[name]
            entry = (_worse_first(rank(error, band), ordinal), event)
            if len(heap) < MAX_WORST_IMPACTS:
                heapq.heappush(heap, entry)
            elif entry[0] > heap[0][0]:
                heapq.heapreplace(heap, entry)

    def _requested(self, event: ImpactEvent) -> float:
        pair = (event.body_a, event.body_b)
        if pair not in self.requested:
            self.requested[pair] = self.scene.pair_value(*pair, "restitution")
        return self.requested[pair]

    def events(self) -> list[ImpactEvent]:
        """The kept impacts, in closing order: every one when there were at most
        ``MAX_SAMPLED_IMPACTS``."""
        kept = dict(self.sample)
        for heap in self.worst.values():
            kept.update((-key[2], event) for key, event in heap)
        return [kept[ordinal] for ordinal in sorted(kept)]
