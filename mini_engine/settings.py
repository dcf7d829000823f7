"""Every numerical choice of the engine, in one frozen place.

The defaults are the documented engine (``docs/formulas.md``):
semi-implicit Euler, ``α = I⁻¹τ`` without the gyroscopic term, the impulse of
the articles with Newton's restitution law and no velocity threshold, no
friction unless a body asks for it, and no position correction. Everything the
articles leave open is a named option here, so that a report can show what the
option changes.

Option values are plain strings so that an engine spec such as
``mini(gyroscopic=implicit)`` maps onto a field without translation; each
string option has its table of accepted values below, and ``Settings`` rejects
anything else when it is built.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, fields, replace

INTEGRATORS = ("semi_implicit_euler", "explicit_euler")
"""``semi_implicit_euler``: v ← v + a dt, then x ← x + v dt (the articles' choice).
``explicit_euler``: x ← x + v dt with the old v, then v ← v + a dt (documented, unreliable)."""

GYROSCOPIC_MODES = ("none", "explicit", "implicit")
"""``none``: α = I⁻¹τ as documented (ω × Iω dropped).
``explicit``: α = I⁻¹(τ − ω × Iω), evaluated at the start of the step.
``implicit``: one Newton step on I(ω' − ω) + dt ω' × Iω' = 0 in the body frame
(Bullet's ``BT_ENABLE_GYROSCOPIC_FORCE_IMPLICIT_BODY``; Catto, GDC 2015)."""

ORIENTATION_UPDATES = ("exponential_map", "linearized")
"""``exponential_map``: q ← exp(½ dt ω) ⊗ q, the exact rotation for constant ω
(what MuJoCo and Bullet do). ``linearized``: q ← normalize(q + ½ dt [0, ω] ⊗ q)."""

POSITION_CORRECTIONS = ("none", "baumgarte", "split_impulse")
"""``none``: impulses only; penetration is never removed (no energy added).
``baumgarte``: a bias velocity β·(depth − slop)/dt in the normal target; it
pushes bodies apart and that velocity stays as kinetic energy (energy is gained).
``split_impulse``: the same bias solved on separate pseudo-velocities that move
positions only and are then discarded; penetration is removed without adding
kinetic energy (potential energy changes by the lift)."""

RESTITUTION_MIXES = ("max", "min", "mean", "product")
"""How a pair's restitution comes from the two bodies' values (Box2D: max)."""

FRICTION_MIXES = ("geometric_mean", "min", "max", "product")
"""How a pair's friction coefficient comes from the two bodies' values (Box2D: geometric mean)."""


@dataclass(frozen=True)
class Settings:
    """Numerical settings of ``mini_engine.step``; frozen, every field documented.

    The physics of the scene (masses, shapes, gravity, springs) is in the
    ``Model``; these are the method choices and their constants.
    """

    dt: float = 1e-3
    """s, the fixed time step, > 0."""

    integrator: str = "semi_implicit_euler"
    """Time integrator, one of ``INTEGRATORS``."""

    gyroscopic: str = "none"
    """Gyroscopic term ω × Iω, one of ``GYROSCOPIC_MODES``; ``none`` is the documented law."""

    orientation_update: str = "exponential_map"
    """Quaternion update from ω, one of ``ORIENTATION_UPDATES`` (the articles are silent)."""

    position_correction: str = "none"
    """Penetration handling, one of ``POSITION_CORRECTIONS``; ``none`` as in the articles."""

    restitution_threshold: float = 0.0
    """m/s. Restitution applies only to contacts approaching faster than this. 0 keeps
    Newton's law exact (measured e = requested e); qu3e and Bullet use 1 and 0.2 m/s."""

    restitution_mix: str = "max"
    """Pair restitution rule, one of ``RESTITUTION_MIXES`` (Box2D's rule by default)."""

    friction_mix: str = "geometric_mean"
    """Pair friction rule, one of ``FRICTION_MIXES`` (Box2D's rule by default)."""

    solver_iterations: int = 10
    """Maximum sequential-impulse sweeps over all contacts per step (Box2D-Lite uses 10).
    One contact needs one sweep; piles and stacks need more."""

    position_iterations: int = 50
    """Maximum sweeps of the split-impulse pseudo-velocity solve. It starts from zero every
    step (nothing to warm-start from), so it gets more than the velocity solve: with 10,
    a box pushed out of a 4 cm overlap with another came out tilted and slid 7 cm sideways
    in 2 s; with 50 it rests upright. Stops early at ``solver_tolerance``."""

    warm_start: bool = True
    """Start each contact's sequential impulses from the impulse of the matching contact
    of the previous step (Box2D, Bullet, qu3e all do). Without it a 5-box stack needs ~200
    sweeps per step to converge from zero (measured: 10 sweeps leave 3.4 mm/s of
    approach); with it, resting impulses carry over and a few sweeps suffice. A new
    impact has no previous contact, so the documented single impulse is unchanged."""

    solver_tolerance: float = 1e-9
    """m/s. The sweeps stop early once no contact changed its relative velocity by more
    than this in a whole sweep; 1e-9 m/s is far below any speed the reports resolve."""

    contact_margin: float = 1e-6
    """m. Shapes closer than this count as touching (depth down to -margin). Without it a
    body resting exactly on another flickers in and out of contact on round-off (depth
    ±1e-16 m). 1 µm is far below what any report resolves, and it never brakes a body
    before impact: a contact within the margin gets the full Newton restitution."""

    baumgarte_factor: float = 0.2
    """β, fraction of the penetration removed per step by ``baumgarte`` and
    ``split_impulse`` (Box2D-Lite's k_biasFactor = 0.2)."""

    penetration_slop: float = 1e-3
    """m. Penetration allowed before position correction acts, so resting contacts
    persist between steps (Box2D uses 5 mm for metre-sized bodies; 1 mm here suits the
    library's 5-10 cm bodies; scenes with millimetre bodies should lower it)."""

    max_correction_speed: float = 1.0
    """m/s. Upper bound of the position-correction bias velocity, so that a deep
    initial penetration is removed gradually instead of launching bodies."""

    broadphase_padding: float = 0.0
    """m. Extra radius of the broad phase's bounding spheres only (more candidate pairs, the
    same contacts): contacts are still those within ``contact_margin``."""

    def __post_init__(self) -> None:
        for name, allowed in CHOICES.items():
            value = getattr(self, name)
            if value not in allowed:
                raise ValueError(
                    f"Settings.{name}: expected one of {', '.join(allowed)}; got {value!r}"
                )
        if not (isinstance(self.dt, int | float) and math.isfinite(self.dt) and self.dt > 0.0):
            raise ValueError(
                f"Settings.dt: expected a finite number of seconds > 0; got {self.dt!r}"
            )
        for name in _NON_NEGATIVE:
            value = getattr(self, name)
            if not value >= 0.0:
                raise ValueError(f"Settings.{name}: expected a number >= 0; got {value!r}")
        for name in ("solver_iterations", "position_iterations"):
            value = getattr(self, name)
            if not (isinstance(value, int) and not isinstance(value, bool) and value >= 1):
                raise ValueError(f"Settings.{name}: expected an integer >= 1; got {value!r}")

    def replace(self, **changes: object) -> Settings:
        """A copy with some fields changed (validated again)."""
        return replace(self, **changes)

    def as_dict(self) -> dict[str, object]:
        """Every field and its value, for provenance records."""
        return {f.name: getattr(self, f.name) for f in fields(self)}


CHOICES: dict[str, tuple[str, ...]] = {
    "integrator": INTEGRATORS,
    "gyroscopic": GYROSCOPIC_MODES,
    "orientation_update": ORIENTATION_UPDATES,
    "position_correction": POSITION_CORRECTIONS,
    "restitution_mix": RESTITUTION_MIXES,
    "friction_mix": FRICTION_MIXES,
}
"""String-valued settings and their accepted values."""

_NON_NEGATIVE = (
    "restitution_threshold",
    "solver_tolerance",
    "contact_margin",
    "baumgarte_factor",
    "penetration_slop",
    "max_correction_speed",
    "broadphase_padding",
)
"""Float settings that must be >= 0 (NaN fails the comparison; inf is allowed, as "no limit")."""
