"""When a scene can define a metric: one table, read at load time and by the metrics.

A metric of ``METRIC_NAMES`` is defined by a scene unless one of its conditions in
``UNDEFINED_WHEN`` holds; each condition is a predicate of the scene's ``Traits`` with the
reason in plain words. The loader refuses a check or a known finding on a metric the scene
cannot define (``validation.scenario.checks``), and ``validation.measure.metrics`` computes
no row for it: both read this table, so a check can never name a row that is silently absent.

The traits are the compiled scene's own (``CompiledScene.can_touch``, ``external_loads``,
``uniform_acceleration``, ``applies_torque``), so what the table calls "bodies can touch" is
what the recording and the engines call so.

What a run can still leave out is not in the table: a scene where bodies can touch has a
``restitution_error`` row only once an impact happened (a resting stack has none), and a
``divergence`` row only against another engine that ran.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

from validation.scenario.compiled import CompiledScene


@dataclass(frozen=True)
class Traits:
    """What a scene's metrics depend on, read once from the compiled scene.

    Attributes:
        can_touch: two bodies, or a body and the ground, can meet.
        springs: a spring acts. damped_spring: a spring has damping > 0.
        external_loads: a ground, a fixed body or a spring to the world can push the bodies.
        uniform_acceleration: g + F/m is the same vector for every moving body.
        applies_torque: a constant applied torque acts.
        engines: how many engine specs the scene lists.
        joints: the scene has joints. damped_joint: a joint has damping > 0.
        models: the scene has ``models`` (robot model files): the model tiers are defined.
        banded: the scene's ``checks`` give ``joint_divergence`` a tolerance (the band
            ``agreement_time`` measures the time within).
    """

    can_touch: bool
    springs: bool
    damped_spring: bool
    external_loads: bool
    uniform_acceleration: bool
    applies_torque: bool
    engines: int
    joints: bool = False
    damped_joint: bool = False
    models: bool = False
    banded: bool = False


def scene_traits(scene: CompiledScene) -> Traits:
    """The traits of a compiled scene."""
    springs = scene.scenario.springs
    return Traits(
        can_touch=scene.can_touch,
        springs=bool(springs),
        damped_spring=any(spring.damping > 0.0 for spring in springs),
        external_loads=scene.external_loads,
        uniform_acceleration=scene.uniform_acceleration,
        applies_torque=scene.applies_torque,
        engines=len(scene.scenario.engines),
        joints=bool(scene.scenario.joints),
        damped_joint=any(joint.damping > 0.0 for joint in scene.scenario.joints),
        models=bool(scene.scenario.models),
        banded="joint_divergence" in scene.scenario.checks,
    )


Condition = tuple[Callable[[Traits], bool], str]
"""(holds for the scene, why the metric is then undefined)."""

_PUSHED = (
    lambda t: t.external_loads,
    "a ground, a fixed body, a spring or a joint to the world pushes the bodies, so momentum "
    "is not an invariant",
)
_NOT_FREE = (
    (lambda t: t.can_touch, "bodies can touch, so there is no ballistic closed form"),
    (lambda t: t.springs, "a spring acts, so there is no ballistic closed form"),
    (lambda t: t.joints, "joints hold the bodies, so there is no ballistic closed form"),
)
_NOTHING_TOUCHES = (lambda t: not t.can_touch, "nothing in the scene can touch")
_NO_MODELS = (
    lambda t: not t.models,
    "the scene has no models, and the model tiers judge a model file's reading",
)
_ONE_ENGINE = (
    lambda t: t.engines < 2,
    "the scene lists one engine, so there is no reference engine to diverge from",
)

UNDEFINED_WHEN: dict[str, tuple[Condition, ...]] = {
    "energy_drift": (
        (
            lambda t: t.applies_torque,
            "an applied torque does work with no potential, so energy is not an invariant",
        ),
        (lambda t: t.damped_spring, "a damped spring dissipates energy"),
        (lambda t: t.damped_joint, "a damped joint dissipates energy"),
    ),
    "angular_momentum_drift": (
        _PUSHED,
        (
            lambda t: not t.uniform_acceleration,
            "g + F/m differs between bodies, so the applied forces exert a torque about the "
            "centre of mass",
        ),
    ),
    "linear_momentum_drift": (_PUSHED,),
    "position_error": _NOT_FREE,
    "velocity_error": _NOT_FREE,
    "restitution_error": (_NOTHING_TOUCHES,),
    "penetration_max": (_NOTHING_TOUCHES,),
    "joint_violation": ((lambda t: not t.joints, "the scene has no joints"),),
    "divergence": (_ONE_ENGINE,),
    "model_fields": (_NO_MODELS,),
    "fk_error": (_NO_MODELS,),
    "mass_matrix_error": (_NO_MODELS,),
    "bias_force_error": (_NO_MODELS,),
    "joint_divergence": (_NO_MODELS, _ONE_ENGINE),
    "agreement_time": (
        _NO_MODELS,
        _ONE_ENGINE,
        (
            lambda t: not t.banded,
            "its band is the scene's joint_divergence tolerance, and checks gives none",
        ),
    ),
}
"""Metric name -> the conditions under which a scene cannot define it (every metric of
``schema.METRIC_NAMES``; a scene's own expectations are always defined)."""


def why_undefined(metric: str, traits: Traits) -> str | None:
    """Why the scene cannot define ``metric`` (the first condition that holds), or None when
    it can; a metric outside the table (an expectation's) is always defined."""
    return next((why for holds, why in UNDEFINED_WHEN.get(metric, ()) if holds(traits)), None)


def defined_metrics(traits: Traits) -> set[str]:
    """The metrics of ``UNDEFINED_WHEN`` the scene defines."""
    return {metric for metric in UNDEFINED_WHEN if why_undefined(metric, traits) is None}
