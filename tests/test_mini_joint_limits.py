"""Hinge and slider limits in mini (``mini_engine.joints``: a one-sided row with restitution 0
while the coordinate is at or past a limit, Baumgarte's bias bringing it back) against closed
forms: the compound pendulum of ``test_joint_scenes`` released toward a limit, and a cart on a
spring-pulled slider stopped short of the spring's rest.

Each arrives at its limit at the speed energy gives it there; the row engages on the first
state past it, so it passes by at most one step's travel (``overshoot``); its bias then sends it
back at β·(past)/dt, which gravity (or the spring) stops within (β·past/dt)²/(2|a|) (``rebound``);
it comes to rest at the limit.
"""

from __future__ import annotations

import math
import re

import numpy as np
import pytest
from test_joint_scenes import AMPLITUDE, DT, PIVOT_INERTIA, compound_pendulum, recorded

from mini_engine.joints import JOINT_BAUMGARTE, Joint, build_joints
from validation.reference.articulated import joint_coordinates
from validation.reference.rotation import quat_to_matrix
from validation.scenario import Scenario

G = 9.81
BAR_HALF = 0.5
OMEGA0_SQUARED = G * BAR_HALF / PIVOT_INERTIA
"""1/s², m g d / I_O of the compound pendulum."""

LOWER = -1.5
"""rad from the release at θ0 = 2 rad: the limit at 0.5 rad from the bottom, on the release
side (the bar swings into it)."""

AT_LIMIT = AMPLITUDE + LOWER
"""rad from the bottom where the limit is (0.5)."""

ARRIVAL = math.sqrt(2 * OMEGA0_SQUARED * (math.cos(AT_LIMIT) - math.cos(AMPLITUDE)))
"""rad/s, the rate at the limit from the energy: ½ I q'² = m g d (cos θ_limit - cos θ0), 6.2."""

OVERSHOOT = ARRIVAL * DT + OMEGA0_SQUARED * DT**2
"""rad: the most the coordinate can pass the limit: a step's travel at the arrival rate, and
what gravity (|α| <= ω0²) adds over it; 6.2e-3 (measured 5.2e-3)."""

REBOUND = (JOINT_BAUMGARTE * OVERSHOOT / DT) ** 2 / (2 * OMEGA0_SQUARED * math.sin(AT_LIMIT))
"""rad: the bias sends the bar back at β·(past)/dt at most, against gravity's α >= ω0² sin
θ_limit (it grows away from the bottom): it rises at most v²/(2α), 0.11 rad (measured 0.068)."""

AT_REST = 1e-9
"""rad from the limit at the end (2 s): resting there, the row holds C = 0 (Baumgarte's bias
shrinks what is left by 1 - β a step: 0.8^1000 after the last rebound), to round-off."""


def _limited_pendulum(limits: list[float]) -> Scenario:
    stated = compound_pendulum(["mini"], duration=2.0).model_dump()
    stated["joints"][0]["limits"] = limits
    return Scenario.model_validate(stated)


def test_a_pendulum_released_toward_a_hinge_limit_stops_there():
    scene, trajectory = recorded("mini", _limited_pendulum([LOWER, 0.0]))
    swing = joint_coordinates(scene.joint_tree, trajectory.pos, quat_to_matrix(trajectory.quat))
    angle = swing["pivot"]
    assert LOWER - angle.min() < OVERSHOOT, (angle.min(), OVERSHOOT)
    assert LOWER - angle.min() > 0.0, "it reached the limit"
    hit = int(np.argmax(angle <= LOWER))
    assert angle[hit:].max() - LOWER < REBOUND, (angle[hit:].max(), REBOUND)
    assert abs(angle[-1] - LOWER) < AT_REST, angle[-1]


def test_without_the_limit_the_same_pendulum_swings_through():
    """The control: the unlimited bar passes -1.5 rad by far (it turns at -2 θ0 = -4 rad)."""
    scene, trajectory = recorded("mini", compound_pendulum(["mini"], duration=2.0))
    angle = joint_coordinates(scene.joint_tree, trajectory.pos, quat_to_matrix(trajectory.quat))
    assert angle["pivot"].min() < -2 * AMPLITUDE + 1e-3, angle["pivot"].min()


LIMITS_PAST_A_HALF_TURN = [-3.5, 0.5]
"""rad: a lower limit past -π (the bar turns to -4), 4 rad apart (less than a turn)."""


def test_a_hinge_limit_past_a_half_turn_holds():
    """mini reads the angle within π of the limits' middle (-1.5 rad): -3.5 is read as itself,
    not as 2.78."""
    stated = compound_pendulum(["mini"], duration=2.0).model_dump()
    stated["joints"][0]["limits"] = LIMITS_PAST_A_HALF_TURN
    scene, trajectory = recorded("mini", Scenario.model_validate(stated))
    angle = joint_coordinates(scene.joint_tree, trajectory.pos, quat_to_matrix(trajectory.quat))
    lower = LIMITS_PAST_A_HALF_TURN[0]
    arrival = math.sqrt(2 * OMEGA0_SQUARED * (math.cos(AMPLITUDE + lower) - math.cos(AMPLITUDE)))
    past = lower - angle["pivot"].min()
    assert 0.0 < past < arrival * DT + OMEGA0_SQUARED * DT**2, angle["pivot"].min()


STIFFNESS = 100.0
"""N/m on a 1 kg cart: ω = 10 rad/s."""
STRETCH = 0.2
"""m: the spring's stretch at t = 0; it pulls the cart toward -x."""
SLIDE_LOWER = -0.1
"""m: the limit, halfway to the spring's rest."""
SLIDE_ARRIVAL = math.sqrt(STIFFNESS) * math.sqrt(STRETCH**2 - (STRETCH + SLIDE_LOWER) ** 2)
"""m/s at the limit, from the energy: ω √(A² - (A - 0.1)²), 1.73."""
SLIDE_OVERSHOOT = SLIDE_ARRIVAL * DT + STIFFNESS * STRETCH * DT**2
"""m: a step's travel at the arrival speed, and what the spring's pull (<= k A / m) adds."""
SLIDE_REBOUND = (JOINT_BAUMGARTE * SLIDE_OVERSHOOT / DT) ** 2 / (
    2 * STIFFNESS * (STRETCH + SLIDE_LOWER)
)
"""m: the bias's speed back, against the spring's pull there (k (A + lower) / m, growing as
the cart goes back)."""


def test_a_cart_on_a_spring_stops_at_its_slider_limit():
    from test_joint_expectations import slider_on_a_spring

    stated = slider_on_a_spring(1.0).model_dump()
    stated["joints"][0]["limits"] = [SLIDE_LOWER, 0.0]
    scene, trajectory = recorded("mini", Scenario.model_validate(stated))
    slide = joint_coordinates(scene.joint_tree, trajectory.pos, quat_to_matrix(trajectory.quat))
    travel = slide["rail"]
    assert 0.0 < SLIDE_LOWER - travel.min() < SLIDE_OVERSHOOT, (travel.min(), SLIDE_OVERSHOOT)
    hit = int(np.argmax(travel <= SLIDE_LOWER))
    assert travel[hit:].max() - SLIDE_LOWER < SLIDE_REBOUND, travel[hit:].max()
    assert abs(travel[-1] - SLIDE_LOWER) < AT_REST, travel[-1]


@pytest.mark.parametrize(
    "joint, words",
    [
        (Joint("ball", -1, 0, limits=(-1.0, 1.0)), "a ball joint takes none"),
        (Joint("hinge", -1, 0, axis=(0, 1, 0), limits=(0.1, 1.0)), "lower <= 0 <= upper"),
        (Joint("hinge", -1, 0, axis=(0, 1, 0), limits=(-4.0, 3.0)), "less than 2π apart"),
    ],
)
def test_minis_joints_refuse_limits_they_cannot_hold(joint, words):
    with pytest.raises(ValueError, match=re.escape(words)):
        build_joints([joint], np.zeros((1, 3)), np.array([[1.0, 0, 0, 0]]), np.zeros(1, bool))
