"""What a scene needs of an engine, as capability words (``validation.engine_api``): its
shapes and its features, each with the reason (the first body, spring or pair that needs it).

``missing`` compares a scene's needs with an engine's ``Capabilities``; a scene that needs
anything missing is not run in that engine (``validation.measure.runner``: status
``unsupported``, the message naming each missing capability and why).
"""

from __future__ import annotations

from collections.abc import Callable

from validation.engine_api import FEATURES, Capabilities
from validation.scenario.schema import Scenario

UP = (0.0, 0.0, 1.0)
"""The untilted ground's normal (the schema normalises every normal)."""


def _contacts(scenario: Scenario) -> str | None:
    colliding = sum(body.collides for body in scenario.bodies)
    if scenario.ground is not None and colliding:
        return "the scene has a ground"
    if colliding > 1:
        return f"{colliding} bodies may touch"
    return None


def _placed_shapes(scenario: Scenario) -> str | None:
    body = next((b for b in scenario.bodies if b.shape.placed), None)
    return None if body is None else f"body {body.name!r}'s shape sits off its centre of mass"


def _non_colliding(scenario: Scenario) -> str | None:
    body = next((b for b in scenario.bodies if not b.collides), None)
    return None if body is None else f"body {body.name!r} takes part in no contact"


def _coefficient(scenario: Scenario, quantity: str) -> str | None:
    """The first contact value of ``quantity`` > 0 (bodies, ground, pairs), when contacts
    can happen at all (a lone body's coefficient never acts)."""
    if _contacts(scenario) is None:
        return None
    body = next((b for b in scenario.bodies if getattr(b, quantity) > 0), None)
    if body is not None:
        return f"body {body.name!r} has {quantity} {getattr(body, quantity)}"
    if scenario.ground is not None and getattr(scenario.ground, quantity) > 0:
        return f"the ground has {quantity} {getattr(scenario.ground, quantity)}"
    pair = next((p for p in scenario.pairs if (getattr(p, quantity) or 0) > 0), None)
    if pair is not None:
        return f"pair {pair.a}-{pair.b} has {quantity} {getattr(pair, quantity)}"
    return None


def _tilted(scenario: Scenario) -> str | None:
    ground = scenario.ground
    if ground is None or tuple(ground.normal) == UP:
        return None
    return f"the ground's normal is {list(ground.normal)}"


def _fixed(scenario: Scenario) -> str | None:
    body = next((b for b in scenario.bodies if b.fixed), None)
    return None if body is None else f"body {body.name!r} is fixed"


def _springs(scenario: Scenario) -> str | None:
    if not scenario.springs:
        return None
    return f"{len(scenario.springs)} spring(s), the first {scenario.springs[0].a}-{scenario.springs[0].b}"


def _loads(scenario: Scenario) -> str | None:
    body = next((b for b in scenario.bodies if any(b.force) or any(b.torque)), None)
    return None if body is None else f"body {body.name!r} has an applied force or torque"


def _joints(scenario: Scenario) -> str | None:
    if not scenario.joints:
        return None
    first = scenario.joints[0]
    return f"{len(scenario.joints)} joint(s), the first {first.name!r} ({first.type})"


def _joint_limits(scenario: Scenario) -> str | None:
    joint = next((j for j in scenario.joints if j.limits is not None), None)
    return None if joint is None else f"joint {joint.name!r} has limits {list(joint.limits)}"


FEATURE_NEEDS: dict[str, Callable[[Scenario], str | None]] = {
    "ground": lambda s: None if s.ground is None else "the scene has a ground",
    "tilted_ground": _tilted,
    "contacts": _contacts,
    "fixed_bodies": _fixed,
    "springs": _springs,
    "loads": _loads,
    "restitution": lambda s: _coefficient(s, "restitution"),
    "friction": lambda s: _coefficient(s, "friction"),
    "joints": _joints,
    "joint_limits": _joint_limits,
    "non_colliding": _non_colliding,
    "placed_shapes": _placed_shapes,
}
"""Feature -> why a scene needs it (None when it does not); one entry per ``FEATURES``."""

assert set(FEATURE_NEEDS) == set(FEATURES), "a feature without its rule"


def scene_needs(scenario: Scenario) -> dict[str, str]:
    """Capability word -> why ``scenario`` needs it: each shape it uses, each feature."""
    needs: dict[str, str] = {}
    for body in scenario.bodies:
        needs.setdefault(body.shape.type, f"body {body.name!r} is a {body.shape.type}")
    for feature, rule in FEATURE_NEEDS.items():
        reason = rule(scenario)
        if reason is not None:
            needs[feature] = reason
    return needs


def missing(capabilities: Capabilities, scenario: Scenario) -> dict[str, str]:
    """Capability word -> reason, for each need of ``scenario`` the engine lacks."""
    return {
        word: reason
        for word, reason in scene_needs(scenario).items()
        if word not in capabilities.supported
    }


def unsupported_message(engine: str, lacking: dict[str, str]) -> str:
    """``freeflight cannot represent: contacts (the scene has a ground); ...``."""
    parts = [f"{word} ({reason})" for word, reason in lacking.items()]
    return f"{engine} cannot represent: {'; '.join(parts)}"
