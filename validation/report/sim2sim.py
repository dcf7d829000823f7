"""Phase 3 of report.html, the sim2sim card of a scene with models (issue 36): per engine, the
first tier where its rows disagree, the row's message (the link, joint or matrix entry it
names) and its numbers, or that it agrees on every tier, and what that points at.

The tiers are checked in the order a reader debugging a model would: the fields the engine
holds after loading (tier 1), its forward kinematics (2), its mass matrix and bias forces
(3), then the trajectory (4). A disagreement in tiers 1-3 is the model conversion's (the
model file or the engine's loader); a disagreement in the trajectory alone, the models
agreeing, is the solver's. The card reads only the scene's display rows
(``build.build_rows``): it renders from results.csv like every other part of the page.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

from validation.measure.definitions import TIERS
from validation.report.outcomes import RED_OUTCOMES

TIER_LABELS = (
    "tier 1: model fields",
    "tier 2: forward kinematics",
    "tier 3: mass matrix and bias forces",
    "tier 4: trajectory",
)
"""How the card names each tier of ``TIERS``."""

MODEL_TIERS = 3
"""The first this many tiers judge the model as the engine holds it (its conversion); the
rest judge its motion (the solver)."""

CARD_METRICS = frozenset(
    (*(m for tier in TIERS[:MODEL_TIERS] for m in tier), "joint_divergence", "agreement_time")
)
"""A scene gets a card when it has a row of one of these: the model tiers and the joint-space
comparison (energy and joint rows alone are every jointed scene's, models or not)."""

DISAGREEING = (*RED_OUTCOMES, "known")
"""Row outcomes that are a disagreement: a failed check, a tier that could not be computed (a
run failure of the row), and a known finding (declared, measured, still a difference)."""

FIX_MODEL = "the model conversion: fix the model file or this engine's loader"
FIX_SOLVER = "the solver: the engine holds the model as the reference does, its motion differs"
AGREES = "agrees on every tier"
NOT_MEASURED = "no tier measured"

TIER_OF = {metric: k for k, tier in enumerate(TIERS) for metric in tier}
"""Metric -> the index of its tier in ``TIERS``."""


def first_disagreement(rows: list[dict[str, Any]]) -> tuple[int, dict[str, Any]] | None:
    """The first tier (index into ``TIERS``) where one of an engine's display rows disagrees,
    with that tier's worst disagreeing row (rows come worst first), or None."""
    disagreeing = [r for r in rows if r["metric"] in TIER_OF and r["outcome"] in DISAGREEING]
    if not disagreeing:
        return None
    tier = min(TIER_OF[r["metric"]] for r in disagreeing)
    return tier, next(r for r in disagreeing if TIER_OF[r["metric"]] == tier)


@dataclass(frozen=True)
class CardLine:
    """One engine's line of the card (display strings, as ``build.build_rows`` gives them).

    Attributes:
        engine: the engine spec. tier: the first disagreeing tier's label, ``AGREES`` or
            ``NOT_MEASURED``. fix: what the tier points at (``FIX_MODEL``, ``FIX_SOLVER``),
            empty when it agrees or was not measured.
        metric, outcome, outcome_label, value, tolerance, ratio, message, known: the row that
            disagrees (for ``NOT_MEASURED``, the engine's worst row: its run's status).
    """

    engine: str
    tier: str
    fix: str = ""
    metric: str = ""
    outcome: str = ""
    outcome_label: str = ""
    value: str = ""
    tolerance: str = ""
    ratio: str = ""
    message: str = ""
    known: str = ""

    @property
    def agrees(self) -> bool:
        return self.tier == AGREES


SHOWN = ("metric", "outcome", "outcome_label", "value", "tolerance", "ratio", "message", "known")
"""The columns of a display row a card line shows."""


def engine_line(engine: str, rows: list[dict[str, Any]]) -> CardLine:
    """One engine's line of the card from its display rows (worst first): its first
    disagreeing tier and what that points at, that it agrees on every tier it has rows of, or
    (no tier row: its run failed or was not run) its worst row."""
    tier_rows = [r for r in rows if r["metric"] in TIER_OF]
    if not tier_rows:
        worst = rows[0] if rows else {}
        return CardLine(engine, NOT_MEASURED, **{k: str(worst.get(k, "")) for k in SHOWN})
    found = first_disagreement(tier_rows)
    if found is None:
        return CardLine(engine, AGREES)
    tier, row = found
    fix = FIX_MODEL if tier < MODEL_TIERS else FIX_SOLVER
    return CardLine(engine, TIER_LABELS[tier], fix, **{k: row[k] for k in SHOWN})


def build_sim2sim_card(rows: list[dict[str, Any]], engines: list[str]) -> dict[str, Any] | None:
    """A scene's sim2sim card from its display rows (``build.build_rows``, worst first), one
    line per engine in ``engines``'s order (the scene's own, its reference engine first), or
    None when the scene has no tier rows (``CARD_METRICS``)."""
    if not any(r["metric"] in CARD_METRICS for r in rows):
        return None
    return {
        "tiers": [
            {"label": label, "metrics": ", ".join(tier)}
            for label, tier in zip(TIER_LABELS, TIERS, strict=True)
        ],
        "engines": [engine_line(e, [r for r in rows if r["engine"] == e]) for e in engines],
    }
