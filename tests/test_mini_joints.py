"""mini's joints (``mini_engine.joints``): the documented impulse with e = 0 along each
constrained direction, against closed forms.

A compound pendulum swings with the elliptic integral's period and its pivot drifts no more
than Baumgarte's steady state allows; a slider on a tilted rail accelerates at g·u along it;
two welded boxes fall as one; a ball joint swinging in a plane moves as a hinge; a damped hinge
decays exponentially; joints between free bodies exchange equal and opposite impulses, so the
linear momentum is kept to round-off.
"""

from __future__ import annotations

import math

import numpy as np
import pytest
from scipy.special import ellipk

from mini_engine import Body, Box, Joint, Settings, Sphere, build_model, step
from mini_engine.joints import JOINT_BAUMGARTE, WORLD
from mini_engine.rotation import quat_to_matrix

G = 9.81
DT = 1e-3
SETTINGS = Settings(dt=DT)
Y_AXIS = (0.0, 1.0, 0.0)

BAR_HALF = (0.02, 0.02, 0.5)
"""m: a 1 m bar, hinged at its top end."""

ROUND_OFF = 1e-12
"""Relative: impulses that cancel in pairs leave only a few ulps of the momentum."""


def run(model, state, steps: int, settings: Settings = SETTINGS):
    states = [state]
    for _ in range(steps):
        state = step(model, state, settings).state
        states.append(state)
    return states


def compound_pendulum(amplitude: float, joint_type: str = "hinge"):
    """A 1 kg bar hinged (or ball-jointed) at its top (the origin), released from rest at
    ``amplitude`` rad from hanging straight down, swinging in the x-z plane."""
    turn = (math.cos(amplitude / 2), 0.0, math.sin(amplitude / 2), 0.0)
    centre = 0.5 * np.array([-math.sin(amplitude), 0.0, -math.cos(amplitude)])
    axis = Y_AXIS if joint_type == "hinge" else (0.0, 0.0, 0.0)
    return build_model(
        [Body(Box(BAR_HALF), mass=1.0, position=tuple(centre), orientation=turn)],
        gravity=(0.0, 0.0, -G),
        joints=[Joint(joint_type, WORLD, 0, anchor=(0.0, 0.0, 0.0), axis=axis)],
    )


def swing_angle(state) -> float:
    """rad from hanging straight down, positive toward -x (the release side)."""
    x, _, z = state.pos[0]
    return math.atan2(-x, -z)


def pivot_drift(state) -> float:
    """m: the bar's top end away from the pivot."""
    top = state.pos[0] + quat_to_matrix(state.quat)[0] @ np.array([0.0, 0.0, 0.5])
    return float(np.linalg.norm(top))


AMPLITUDE = 2.0
"""rad: a large swing (its period 31 % above the small-angle one)."""

PIVOT_INERTIA = (0.04**2 + 1.0**2) / 12 + 0.25
"""kg·m²: the bar about its top end, I_cm + m d² (m = 1 kg, d = 0.5 m)."""


def test_a_large_swing_keeps_the_elliptic_period_and_its_pivot():
    period = 4 * math.sqrt(PIVOT_INERTIA / (G * 0.5)) * ellipk(math.sin(AMPLITUDE / 2) ** 2)
    model, state = compound_pendulum(AMPLITUDE)
    states = run(model, state, round(period / DT))
    half, whole = states[round(period / 2 / DT)], states[-1]
    # rad: the period read at the nearest step (≤ dt/2 of ω ≤ 6.45 rad/s, 3.2e-3 rad) plus the
    # scheme's phase error; measured 2.8e-5 and 6e-5 rad at dt = 1e-3
    angle_tolerance = 6.45 * DT / 2 + 1e-3
    assert abs(swing_angle(half) + AMPLITUDE) < angle_tolerance, swing_angle(half)
    assert abs(swing_angle(whole) - AMPLITUDE) < angle_tolerance, swing_angle(whole)
    # m: Baumgarte's steady state, the drift of one unconstrained step a·dt² over β, with the
    # largest centripetal acceleration ω²d (ω² = 2 m g d (1 - cos θ0) / I_O): 1.04e-4 m
    omega_squared = 2 * G * 0.5 * (1 - math.cos(AMPLITUDE)) / PIVOT_INERTIA
    drift_bound = omega_squared * 0.5 * DT**2 / JOINT_BAUMGARTE
    drift = max(pivot_drift(s) for s in states)
    assert drift < drift_bound, (drift, drift_bound)


def test_without_the_joint_impulse_the_bar_falls_away():
    """The control: the same bar without its joint is a free body that drops."""
    _, state = compound_pendulum(AMPLITUDE)
    free_model, free_state = build_model(
        [
            Body(
                Box(BAR_HALF),
                mass=1.0,
                position=tuple(state.pos[0]),
                orientation=tuple(state.quat[0]),
            )
        ],
        gravity=(0.0, 0.0, -G),
    )
    assert pivot_drift(run(free_model, free_state, 300)[-1]) > 0.4


def test_a_ball_joint_swinging_in_a_plane_moves_as_the_hinge():
    hinge = run(*compound_pendulum(1.0, "hinge"), 1000)
    ball = run(*compound_pendulum(1.0, "ball"), 1000)
    # m: the same impulses up to the rows the ball leaves free (no rotation about x, z happens)
    difference = max(np.abs(h.pos - b.pos).max() for h, b in zip(hinge, ball, strict=True))
    assert difference < 1e-9, difference


def test_a_slider_on_a_tilted_rail_accelerates_at_g_along_it():
    """A box on a rail through its centre, tilted 30° below +x: s(t) = ½ g sin 30° t², v = g
    sin 30° t; semi-implicit Euler is exact in v and ahead by a·t·dt/2 in s."""
    tilt = math.radians(30)
    axis = (math.cos(tilt), 0.0, -math.sin(tilt))
    model, state = build_model(
        [Body(Box((0.1, 0.1, 0.1)), mass=2.0)],
        gravity=(0.0, 0.0, -G),
        joints=[Joint("slider", WORLD, 0, anchor=(0.0, 0.0, 0.0), axis=axis)],
    )
    t = 0.5
    final = run(model, state, round(t / DT))[-1]
    acceleration = G * math.sin(tilt)
    along = final.pos[0] @ np.array(axis)
    across = np.linalg.norm(final.pos[0] - along * np.array(axis))
    assert abs(along - acceleration * t**2 / 2) < acceleration * t * DT / 2 + 1e-6, along
    assert abs(final.vel[0] @ np.array(axis) - acceleration * t) < 1e-9, final.vel[0]
    assert across < 1e-6, across  # m: the rail's Baumgarte drift, ~g cos 30° dt²/β = 4e-5 m bound
    assert np.abs(final.ang_vel[0]).max() < 1e-9, final.ang_vel[0]


def test_two_welded_boxes_fall_as_one():
    spin = np.array([0.0, 0.0, 2.0])
    bodies = [
        Body(
            Box((0.1, 0.1, 0.1)), mass=1.0, position=(0.0, 0.0, 1.0), angular_velocity=tuple(spin)
        ),
        Body(
            Box((0.1, 0.1, 0.1)),
            mass=3.0,
            position=(0.2, 0.0, 1.0),
            velocity=tuple(np.cross(spin, [0.2, 0.0, 0.0])),
            angular_velocity=tuple(spin),
        ),
    ]
    model, state = build_model(
        bodies, gravity=(0.0, 0.0, -G), joints=[Joint("fixed", 0, 1, anchor=(0.1, 0.0, 1.0))]
    )
    final = run(model, state, 500)[-1]
    gap = np.linalg.norm(final.pos[1] - final.pos[0])
    # m: Baumgarte's steady state of the spin's centripetal drift, ω² · gap · dt² / β = 4e-6
    assert abs(gap - 0.2) < 4.0 * 0.2 * DT**2 / JOINT_BAUMGARTE, gap
    assert np.abs(final.ang_vel[1] - final.ang_vel[0]).max() < 1e-6, final.ang_vel
    centre_velocity = (final.vel[0] * 1.0 + final.vel[1] * 3.0) / 4.0
    assert abs(centre_velocity[2] + G * 0.5) < 1e-9, centre_velocity  # g t exactly


def test_joints_between_free_bodies_keep_the_linear_momentum():
    bodies = [
        Body(Box((0.2, 0.1, 0.05)), mass=1.0, angular_velocity=(1.0, 2.0, 3.0)),
        Body(Sphere(0.1), mass=2.5, position=(0.5, 0.0, 0.0), velocity=(0.0, 1.0, -0.5)),
    ]
    model, state = build_model(
        bodies, gravity=(0.0, 0.0, 0.0), joints=[Joint("ball", 0, 1, anchor=(0.3, 0.0, 0.0))]
    )
    states = run(model, state, 400)
    momentum = [s.vel.T @ model.body_mass for s in states]
    scale = np.abs(momentum[0]).max()
    assert max(np.abs(p - momentum[0]).max() for p in momentum) < ROUND_OFF * scale * 10


@pytest.mark.parametrize(
    "joint_type, axis, spin",
    [("hinge", Y_AXIS, (0.0, 1.0, 0.0)), ("ball", (0.0, 0.0, 0.0), (0.6, 0.0, 0.8))],
)
def test_a_damped_joint_decays_exponentially(joint_type, axis, spin):
    """A ball spinning about a hinge through its centre (or on a ball joint there), no gravity:
    I ω' = -d ω, ω = ω0 e^(-d t / I); the explicit damping impulse takes ω (1 - d dt / I) per
    step, low by ω0 (d/I)² t dt / 2 e^(-d t/I) at first order."""
    inertia, damping, omega0 = 0.4 * 1.0 * 0.1**2, 0.01, 5.0
    model, state = build_model(
        [Body(Sphere(0.1), mass=1.0, angular_velocity=tuple(omega0 * np.array(spin)))],
        gravity=(0.0, 0.0, 0.0),
        joints=[Joint(joint_type, WORLD, 0, axis=axis, damping=damping)],
    )
    t = 1.0
    final = run(model, state, round(t / DT))[-1]
    want = omega0 * math.exp(-damping * t / inertia) * np.array(spin)
    bound = omega0 * (damping / inertia) ** 2 * t * DT / 2
    assert np.abs(final.ang_vel[0] - want).max() < bound, (final.ang_vel[0], want, bound)


@pytest.mark.parametrize(
    "joints, message",
    [
        ([Joint("hinge", WORLD, 0, axis=(0.0, 2.0, 0.0))], "axis"),
        ([Joint("spring", WORLD, 0)], "type"),
        ([Joint("ball", WORLD, 0), Joint("ball", WORLD, 0)], "already has a parent"),
        ([Joint("ball", 0, 0)], "itself"),
    ],
)
def test_impossible_joints_are_refused_by_name(joints, message):
    with pytest.raises(ValueError, match=message):
        build_model([Body(Sphere(0.1))], joints=joints)


def test_a_hinge_holds_its_axis_against_a_twist():
    """A bar on a hinge about y, kicked with a spin about x and z as well: the hinge's spin
    rows take them out (impulses along the two directions ⟂ y) and only ω_y is left."""
    model, state = compound_pendulum(0.5)
    kicked = type(state)(state.pos, state.quat, state.vel, np.array([[1.5, 0.0, -2.0]]))
    final = run(model, kicked, 200)[-1]
    axis = quat_to_matrix(final.quat)[0] @ quat_to_matrix(state.quat)[0].T @ np.array(Y_AXIS)
    assert np.linalg.norm(np.cross(axis, Y_AXIS)) < 1e-4, axis  # rad
    assert np.abs(final.ang_vel[0, [0, 2]]).max() < 1e-6, final.ang_vel
