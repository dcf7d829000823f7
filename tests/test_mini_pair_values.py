"""mini's contact values and normal targets, pinned entry by entry.

``solver.pair_values`` gives each contact the restitution and friction of its body pair: a pair
the scene states wins, else the mixing rules of ``Settings`` (Box2D's: restitution the larger,
friction the geometric mean), written out here independently. ``solver._normal_targets`` is
Newton's law as the articles state it (formulas.md section 3): an approaching contact targets
``-e (v_rel·n)``, a separating or resting one 0, whatever its e. The library's scenes state
equal values or a pair for most contacts, so a wrong rule or a bounce on separating contacts
can hide there (issue 34, item 11); these tests fail on either.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from mini_engine import Body, Contacts, Settings, Sphere, build_model
from mini_engine.model import PairProperties
from mini_engine.solver import _normal_targets, pair_values

RULES = {
    "restitution": {
        "max": max,
        "min": min,
        "mean": lambda a, b: (a + b) / 2,
        "product": lambda a, b: a * b,
    },
    "friction": {
        "geometric_mean": lambda a, b: math.sqrt(a * b),
        "min": min,
        "max": max,
        "product": lambda a, b: a * b,
    },
}
"""Each mixing rule of ``Settings`` written out for two scalars."""

BODY_VALUES = ((0.8, 0.9), (0.3, 0.1), (0.5, 0.4))
"""(restitution, friction) of three bodies: every pair's values differ under every rule."""

VALUE_TOLERANCE = 1e-15
"""The rules are one or two float operations (a square root): exact to an ulp of values <= 1."""


def three_bodies(pairs=()):
    bodies = [
        Body(Sphere(0.1), position=(2.0 * k, 0.0, 0.0), restitution=e, friction=mu)
        for k, (e, mu) in enumerate(BODY_VALUES)
    ]
    model, _ = build_model(bodies, pairs=pairs)
    return model


def every_pair_contacts() -> Contacts:
    """One contact per ordered body pair (0,1), (1,2), (2,0), (1,0): the rule is symmetric."""
    a = np.array([0, 1, 2, 1])
    b = np.array([1, 2, 0, 0])
    count = a.size
    normal = np.tile([1.0, 0.0, 0.0], (count, 1))
    return Contacts(a, b, np.zeros((count, 3)), normal, np.zeros(count))


def expected(quantity: str, rule: str, contacts: Contacts) -> np.ndarray:
    column = 0 if quantity == "restitution" else 1
    return np.array(
        [
            RULES[quantity][rule](BODY_VALUES[i][column], BODY_VALUES[j][column])
            for i, j in zip(contacts.body_a, contacts.body_b, strict=True)
        ]
    )


@pytest.mark.parametrize("rule", sorted(RULES["restitution"]))
def test_restitution_of_a_pair_follows_its_rule(rule):
    contacts = every_pair_contacts()
    restitution, _ = pair_values(three_bodies(), contacts, Settings(restitution_mix=rule))
    want = expected("restitution", rule, contacts)
    assert np.allclose(restitution, want, rtol=0, atol=VALUE_TOLERANCE), (rule, restitution, want)


@pytest.mark.parametrize("rule", sorted(RULES["friction"]))
def test_friction_of_a_pair_follows_its_rule(rule):
    contacts = every_pair_contacts()
    _, friction = pair_values(three_bodies(), contacts, Settings(friction_mix=rule))
    want = expected("friction", rule, contacts)
    assert np.allclose(friction, want, rtol=0, atol=VALUE_TOLERANCE), (rule, friction, want)


def test_the_default_rules_are_box2ds_max_and_geometric_mean():
    contacts = every_pair_contacts()
    restitution, friction = pair_values(three_bodies(), contacts, Settings())
    assert np.array_equal(restitution, [0.8, 0.5, 0.8, 0.8]), restitution
    assert np.allclose(friction, [0.3, 0.2, 0.6, 0.3], rtol=0, atol=VALUE_TOLERANCE), friction


def test_a_stated_pair_wins_over_the_rules_for_its_value_only():
    """Pair (2, 0) states e only, pair (1, 2) μ only (as (2, 1): order does not matter)."""
    pairs = (PairProperties(2, 0, restitution=0.05), PairProperties(2, 1, friction=0.7))
    contacts = every_pair_contacts()
    restitution, friction = pair_values(three_bodies(pairs), contacts, Settings())
    assert np.array_equal(restitution, [0.8, 0.5, 0.05, 0.8]), restitution
    assert np.allclose(friction, [0.3, 0.7, 0.6, 0.3], rtol=0, atol=VALUE_TOLERANCE), friction


RESTITUTION = 0.6
"""e of every contact of the target tests."""


DEFAULT_SETTINGS = Settings()
"""The documented law: no restitution threshold, no position correction."""


def targets(before: np.ndarray, settings: Settings = DEFAULT_SETTINGS, depth=None) -> np.ndarray:
    depth = np.zeros_like(before) if depth is None else depth
    return _normal_targets(depth, before, np.full_like(before, -RESTITUTION), settings)


def test_an_approaching_contact_targets_minus_e_times_its_approach_speed():
    before = np.array([-2.0, -1e-6, -0.5])
    assert np.array_equal(targets(before), RESTITUTION * -before), targets(before)


def test_a_separating_or_resting_contact_targets_zero_whatever_its_e():
    before = np.array([0.0, 1e-6, 0.4, 3.0])
    assert np.array_equal(targets(before), np.zeros(4)), targets(before)


def test_an_approach_below_the_threshold_stops_dead():
    settings = Settings(restitution_threshold=0.1)
    before = np.array([-0.05, -0.1, -0.2])
    want = np.array([0.0, 0.0, RESTITUTION * 0.2])
    assert np.array_equal(targets(before, settings), want), targets(before, settings)


def test_baumgarte_raises_a_target_to_its_correction_speed_only():
    settings = Settings(position_correction="baumgarte")
    before = np.array([-2.0, 0.5])
    depth = np.array([0.05, 0.05])
    floor = min(
        settings.baumgarte_factor * (0.05 - settings.penetration_slop) / settings.dt,
        settings.max_correction_speed,
    )
    want = np.maximum([RESTITUTION * 2.0, 0.0], floor)
    assert np.array_equal(targets(before, settings, depth), want), targets(before, settings, depth)
