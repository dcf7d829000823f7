"""Per-body contact values whose PyBullet products equal the scene's pair values (a log
least-squares fit where products cannot express every pair)."""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from validation.scenario import Scenario
from validation.scenario.physics import pair_rule

PAIR_VALUE_TOLERANCE = 1e-12
"""Relative. A pair whose product of per-body values differs from the scene's pair value by
more than round-off is reported in the provenance notes."""
NULL_SPACE_TOLERANCE = 1e-10
"""Relative eigenvalue of a pair system's Gram matrix below which a direction is free
(the matrices hold 0 and 1; their nonzero eigenvalues are O(1), far above this)."""

GROUND = "ground"
"""The name scene pairs use for the ground plane."""


PAIR_TIERS = ("stated in scenario.pairs", "with a static body", "between moving bodies")
"""Priority of a pair's value when per-body products cannot give every pair its own: the
pairs a scene states (its authors name the contacts that matter), then contacts with the
ground or a fixed body (where everything lands), then the rest (often never meeting)."""


@dataclass
class PairSystem:
    """The scene's pair values of one quantity over classes of interchangeable objects.

    Objects are the bodies then the ground. Objects with the same own value, both static or
    both moving, and not named in ``scenario.pairs`` are interchangeable: they get one
    per-body value, which keeps the fit small for piles of identical bodies.

    Attributes:
        names: object names. static: object is a fixed body or the ground.
        class_of: (objects,) class index of each object. members: objects of each class.
        targets: {(class a, class b): scene pair value}, a <= b; pairs that can meet only
            (two static objects never do).
        tiers: {(a, b): index into ``PAIR_TIERS``}. counts: {(a, b): object pairs}.
        anchor: the ground's class, or None.
    """

    names: list[str]
    static: list[bool]
    class_of: list[int]
    members: list[list[int]]
    targets: dict[tuple[int, int], float] = field(default_factory=dict)
    tiers: dict[tuple[int, int], int] = field(default_factory=dict)
    counts: dict[tuple[int, int], int] = field(default_factory=dict)
    anchor: int | None = None

    def label(self, cls: int) -> str:
        first, size = self.names[self.members[cls][0]], len(self.members[cls])
        return first if size == 1 else f"{first} (and {size - 1} like it)"


def pair_system(scenario: Scenario, quantity: str) -> PairSystem:
    """``quantity`` (restitution or friction) per pair of object classes: the scene's rule
    (``pair_rule``) unless ``scenario.pairs`` states the pair's value."""
    objects = [*scenario.bodies, *([scenario.ground] if scenario.ground else [])]
    names = [b.name for b in scenario.bodies] + ([GROUND] if scenario.ground else [])
    static = [getattr(b, "fixed", True) for b in objects]
    own = [float(getattr(b, quantity)) for b in objects]
    stated = {name for pair in scenario.pairs for name in (pair.a, pair.b)}
    keys: dict[tuple, int] = {}
    class_of = [
        keys.setdefault((own[i], static[i], names[i] if names[i] in stated else ""), len(keys))
        for i in range(len(objects))
    ]
    members: list[list[int]] = [[] for _ in keys]
    for i, cls in enumerate(class_of):
        members[cls].append(i)
    system = PairSystem(names, static, class_of, members)
    system.anchor = class_of[-1] if scenario.ground else None
    for a in range(len(members)):
        for b in range(a, len(members)):
            first_a, first_b = members[a][0], members[b][0]
            size_a, size_b = len(members[a]), len(members[b])
            count = size_a * (size_a - 1) // 2 if a == b else size_a * size_b
            if count == 0 or (static[first_a] and static[first_b]):
                continue
            system.targets[(a, b)] = pair_rule(quantity, own[first_a], own[first_b])
            system.tiers[(a, b)] = 1 if static[first_a] or static[first_b] else 2
            system.counts[(a, b)] = count
    index = {name: i for i, name in enumerate(names)}
    for override in scenario.pairs:
        value = getattr(override, quantity)
        key = tuple(sorted((class_of[index[override.a]], class_of[index[override.b]])))
        if value is not None and key in system.targets:
            system.targets[key], system.tiers[key] = value, 0
    return system


def _zero_objects(count: int, targets, tiers) -> np.ndarray:
    """Objects set to 0 so that zero-valued pairs get 0, tier by tier: an object may be
    zeroed only if no pair of an earlier or the same tier needs it positive; of the two,
    the one with fewer positive pairs overall goes."""
    zero, needed, positive_count = [False] * count, [False] * count, [0] * count
    for (a, b), t in targets.items():
        if t > 0:
            positive_count[a] += 1
            positive_count[b] += 1
    for tier in range(len(PAIR_TIERS)):
        pairs = [(pair, t) for pair, t in targets.items() if tiers[pair] == tier]
        for (a, b), t in pairs:
            if t > 0 and not (zero[a] or zero[b]):
                needed[a] = needed[b] = True
        for (a, b), t in pairs:
            candidates = [i for i in (a, b) if not needed[i]]
            if t == 0 and not (zero[a] or zero[b]) and candidates:
                zero[min(candidates, key=positive_count.__getitem__)] = True
    return np.array(zero, dtype=bool)


def _null_space(matrix: np.ndarray) -> np.ndarray:
    """Orthonormal basis (columns) of the null space of ``matrix``, from its Gram matrix."""
    gram = matrix.T @ matrix
    moments, vectors = np.linalg.eigh(gram)
    return vectors[:, moments <= NULL_SPACE_TOLERANCE * max(moments.max(initial=0.0), 1.0)]


def _log_fit(
    count: int, targets, tiers, weights, zero: np.ndarray, anchor: int | None
) -> np.ndarray:
    """log x (count,) fitting log x_a + log x_b = log t tier by tier (lexicographic least
    squares: each tier is fitted within the freedom the earlier tiers leave), then the
    ground pinned to 1 if still free (a ground–body pair then reads as the body's value)."""
    log_x = np.zeros(count)
    free = np.eye(count)
    systems = []
    for tier in range(len(PAIR_TIERS)):
        rows = [(pair, t) for pair, t in targets.items() if tiers[pair] == tier and t > 0]
        rows = [((a, b), t) for (a, b), t in rows if not (zero[a] or zero[b])]
        matrix = np.zeros((len(rows), count))
        scale = np.sqrt([weights[pair] for pair, _ in rows])
        for k, ((a, b), _) in enumerate(rows):
            matrix[k, a] += scale[k]
            matrix[k, b] += scale[k]
        systems.append((matrix, scale * np.log([t for _, t in rows])))
    if anchor is not None:
        systems.append((np.eye(count)[[anchor]], np.zeros(1)))
    for matrix, rhs in systems:
        if not len(rhs) or not free.shape[1]:
            continue
        reduced = matrix @ free
        step = np.linalg.lstsq(reduced, rhs - matrix @ log_x, rcond=None)[0]
        log_x = log_x + free @ step
        free = free @ _null_space(reduced)
    return log_x


def per_object_values(count: int, targets, tiers, anchor: int | None, weights=None):
    """Per-object values x with x_a·x_b = target for every pair where that is possible.

    Args:
        targets: {(a, b): the scene's pair value}, a <= b object (or class) indices.
        tiers: {(a, b): index into ``PAIR_TIERS``}, the pair's priority.
        anchor: the ground's index (kept at 1 when that costs nothing), or None.
        weights: {(a, b): how many object pairs the entry stands for}; default 1 each.

    Returns the values (count,) and ``{pair: product}`` for every pair that misses its
    target. Exact whenever some assignment is (always for geometric-mean friction, and
    for max-rule restitution unless pairs conflict); otherwise zero-valued pairs are met
    by zeroing an object, and positive ones by least squares on log x, tier by tier.
    """
    zero = _zero_objects(count, targets, tiers)
    weights = weights or dict.fromkeys(targets, 1)
    log_x = _log_fit(count, targets, tiers, weights, zero, anchor)
    values = np.where(zero, 0.0, np.exp(log_x))
    misses = {
        (a, b): float(values[a] * values[b])
        for (a, b), t in targets.items()
        if abs(values[a] * values[b] - t) > PAIR_VALUE_TOLERANCE * max(t, 1.0)
    }
    return values, misses
