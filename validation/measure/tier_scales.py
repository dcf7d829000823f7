"""The model tiers' order and the scales their rows are relative to, light enough for the
report and ``physval list`` (``validation.measure.definitions`` prints them; the tiers
themselves are computed by ``validation.measure.tiers``)."""

from __future__ import annotations

TIERS: tuple[tuple[str, ...], ...] = (
    ("model_fields",),
    ("fk_error",),
    ("mass_matrix_error", "bias_force_error"),
    ("joint_divergence", "agreement_time", "energy_drift", "joint_violation"),
)
"""The tiers in the order a reader checks them (the report's sim2sim card): the first tier
whose rows disagree says whether to fix the model or blame the solver."""

MODEL_METRICS = ("model_fields", "fk_error", "mass_matrix_error", "bias_force_error")
"""The tier metrics computed here, in the worker (the trajectory tier's are the recording's)."""

REACH_FLOOR = 0.1
"""m: the smallest model reach (the largest distance of a link's centre of mass from the
model's base) that centre-of-mass, anchor and rotation differences are relative to: a model
smaller than a hand is judged as one of 10 cm, so a stub of one link still has a scale."""

TYPE_DIFFERENCE = 1.0
"""The relative difference of a field that differs in kind (a joint's type, a limit present
on one side only): as large as a quantity that is wholly wrong."""

LIMIT_FLOOR = 1.0
"""rad or m: a limit's difference is relative to max(|limit|, this): a limit at 0 (a joint
that starts at its stop) is judged on the scale of a radian."""

RANDOM_STATES = 4
"""Seeded random joint states probed besides the initial one (tiers 2 and 3)."""

PROBE_SPEED = 1.0
"""rad/s or m/s: joint rates are drawn uniformly in ±this, the order of a swing's."""

FINITE_DIFFERENCE = "one-step finite difference"
"""How a row computed from two steps of an engine says so in its message."""
