"""mini_engine's friction is isotropic Coulomb, whatever the solver's tangent basis.

Coulomb friction with maximal dissipation: a contact sticks when the impulse that stops its
slip lies in the disc μ λ_n, and otherwise slides with a friction impulse of magnitude μ λ_n
opposing its slip. So a body sliding on its contacts decelerates along its own slip and
never veers or turns, in any direction. The case that tells a right solver from a wrong one
is a rectangular box sliding on its four corners in a direction that is not a tangent axis
of the solver: each corner's 2x2 tangent block ``K = J_t M⁻¹ J_tᵀ`` has unequal diagonal
terms and an off-diagonal one (``solver._TangentBlock``), which a per-row treatment of the
two tangent rows turns into a skewed friction force (launched at 30° on μ = 0.4, the box had
moved at 35.5° and was heading at 45.7° after 0.15 s; on an incline it turned about the
normal). A square box or a sphere cannot
tell: their corners' row masses are equal.

Setting: SI units, world frame, z up, dt = 1 ms, semi-implicit Euler, mini's default solver
(10 sweeps, warm start).
"""

from __future__ import annotations

import functools
import math

import numpy as np
import pytest
from scipy.optimize import brentq

from mini_engine import Body, Box, Plane, Settings, Sphere, build_model, step
from mini_engine.solver import _friction_update

DT = 1e-3
"""s, the step of every run here."""

SETTINGS = Settings(dt=DT)

G = 9.81
"""m/s², mini's gravity (Model default)."""

MU = 0.4
"""Floor friction of the level-floor runs (the audit's value)."""

BOX_HALF_EXTENTS = (0.2, 0.1, 0.05)
"""m. A 0.4 x 0.2 x 0.1 m box: its corners' two tangent row masses differ (1/m + h²/I_xx +
a²/I_zz against 1/m + h²/I_yy + b²/I_zz), which a square box's do not."""

SLIDE_SPEED = 1.0
"""m/s, the launch speed of the level-floor slides."""

MID_SLIDE_STEPS = 150
"""t = 0.15 s: still sliding (the stop is at v0/(μg) = 0.2548 s), at 0.41 m/s."""

HEADINGS_DEG = (0.0, 30.0, 45.0, 73.0)
"""Launch headings from world x; 0° is a tangent axis of the level floor (t1 = y, t2 = -x), the
others are not."""

HEADING_TOLERANCE = 1e-9
"""rad. Coulomb friction opposes the slip exactly, so the heading is exact to round-off:
measured at most 5.3e-11 rad (position, at 0°) and 4.4e-12 rad (velocity) at t = 0.15 s; 1e-9
leaves 20x for other machines' round-off. The per-row rule was up to 0.12 rad off in track and
0.32 rad in velocity (at 45°)."""

SPEED_TOLERANCE = 1e-12
"""m/s. Semi-implicit Euler integrates the constant deceleration μg exactly: v_n = v0 - μg·n·dt,
so only round-off is left: 150 increments of 3.9e-3 m/s, each rounded to 1.1e-16 m/s, about
1.7e-14 m/s (measured at most 5.8e-15 m/s). The per-row rule was up to 0.02 m/s fast (45°)."""

DISTANCE_TOLERANCE = 1e-9
"""m. x_n = dt·Σv_k = v0 t - μg t (t + dt)/2 exactly (the scheme's a·t·dt/2 offset included);
measured at most 2.2e-12 m, round-off of the first steps settling the four normal impulses;
1e-9 leaves 400x. The per-row rule went 1.0 to 2.0 mm too far along the heading."""

ANTIPARALLEL_TOLERANCE = 1e-9
"""rad. At convergence a sliding contact's friction impulse is antiparallel to its final slip
(``solver._friction_update``): at 0.4 m/s its angular error shrinks by a factor of at least
1 + τ s / (μ λ_n) ≈ 150 per sweep (τ = 0.35 kg, μ λ_n ≈ 1e-3 N·s per corner), so 10 sweeps
leave round-off (measured: 0 to double precision at every corner and
heading); the per-row rule left 0.37 rad."""

RIM_TOLERANCE = 1e-12
"""Relative. A sliding contact's impulse lies on the rim |λ| = μ λ_n, to round-off (measured
at most 2.1e-16)."""

YAW_TOLERANCE = 1e-8
"""rad/s. A rigid box sliding on its base does not turn: the centre of pressure moves μh along
the slip, so the corners' friction has no moment about the normal. What is left is the first
step's, solved from no warm start in 10 sweeps (measured 8.8e-7 rad/s, at the moment the box
starts to slide), which the sliding corners damp to 2e-11 rad/s within 0.3 s. The per-row
rule turned the box at 5.7e-3 and 0.026 rad/s on the incline below."""

LATERAL_TOLERANCE = 1e-8
"""m. Off the fall line: the first step's transient above moves the box at most 6.3e-10 m
sideways (measured); the per-row rule drifted 3.3 cm in 0.5 s and 4.8 cm in 0.3 s."""

INCLINE_SPEED_TOLERANCE = 1e-9
"""m/s. v = v0 + g(sin θ - μ cos θ)·t is exact for semi-implicit Euler once the box slides; the
box released at rest (μ = 0.2) spends its first step going from sticking to sliding, solved
from no warm start in 10 sweeps, and keeps that step's error: measured 7.8e-11 m/s (launched,
μ = 0.5: 1.2e-14); 1e-9 leaves 10x. The per-row rule was 0.0094 m/s (μ = 0.2, 0.5 s) and
0.029 m/s (μ = 0.5, 0.3 s) fast."""

STICK_SPEED = 1e-10
"""m/s. A sticking box's corners are held by impulses that cancel their slip; the first step
(no warm start, 10 sweeps on four coupled corners) leaves at most 5.6e-7 m/s (measured), and
from the tenth step on the box moves at most 4.3e-12 m/s (measured); 1e-10 leaves 20x."""

STICK_DRIFT = 1e-8
"""m. The first steps' 5.6e-7 m/s lasting a few ms: measured 4.6e-10 m in 1 s; 1e-8 leaves 20x."""

ONE_UPDATE_SLIP = 1e-14
"""m/s. With one solver sweep a single sticking contact is stopped by one update of the full
2x2 block, exact but for round-off on the ball's 0.7 m/s (measured 1.8e-16 m/s, a few ulps);
each row on its own mass left 6.7e-4 m/s."""

INCLINE_DEG = 17.0
"""Incline angle: tan 17° = 0.306, between the sliding box's μ = 0.2 (it accelerates at
g(sin θ - μ cos θ) = 0.992 m/s²) and μ = 0.5 (it decelerates at 1.823 m/s²)."""

TILT_AXIS = np.array([1.0, 1.0, 0.0]) / math.sqrt(2.0)
"""The incline is tilted about (1, 1, 0)/√2, so its fall line (cos θ, -cos θ, -√2 sin θ)/√2 is
oblique to world x and y and to the solver's tangents t1, t2 of that normal."""


def _incline() -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The incline's quaternion (w x y z, +z to its normal), unit normal and unit fall line."""
    theta = math.radians(INCLINE_DEG)
    quat = np.concatenate([[math.cos(theta / 2)], TILT_AXIS * math.sin(theta / 2)])
    normal = np.array([math.sin(theta), -math.sin(theta), math.sqrt(2.0) * math.cos(theta)])
    fall_line = np.array([math.cos(theta), -math.cos(theta), -math.sqrt(2.0) * math.sin(theta)])
    return quat, normal / math.sqrt(2.0), fall_line / math.sqrt(2.0)


def _heading(degrees: float) -> np.ndarray:
    angle = math.radians(degrees)
    return np.array([math.cos(angle), math.sin(angle), 0.0])


def _level_slide(degrees: float, steps: int = MID_SLIDE_STEPS):
    """The box launched at ``degrees`` on the level floor, after ``steps`` steps: the state, the
    last step's contact report and the positions it started from."""
    model, state = build_model(
        [
            Body(Plane(), fixed=True, friction=MU),
            Body(
                Box(BOX_HALF_EXTENTS),
                mass=1.0,
                position=(0.0, 0.0, BOX_HALF_EXTENTS[2]),
                velocity=SLIDE_SPEED * _heading(degrees),
                friction=MU,
            ),
        ]
    )
    start = state.pos
    report = None
    for _ in range(steps):
        start = state.pos
        state, report = step(model, state, SETTINGS)
    return state, report, start


def _incline_box(mu: float, speed: float):
    """The box lying on the incline, launched down the fall line at ``speed`` m/s; model,
    state, normal and fall line."""
    quat, normal, fall_line = _incline()
    model, state = build_model(
        [
            Body(Plane(), fixed=True, orientation=quat, friction=mu),
            Body(
                Box(BOX_HALF_EXTENTS),
                mass=1.0,
                position=BOX_HALF_EXTENTS[2] * normal,
                orientation=quat,
                velocity=speed * fall_line,
                friction=mu,
            ),
        ]
    )
    return model, state, normal, fall_line


def _angle(a: np.ndarray, b: np.ndarray) -> float:
    """rad, the angle between vectors ``a`` and ``b`` (atan2: exact near 0 and π)."""
    return math.atan2(float(np.linalg.norm(np.cross(a, b))), float(a @ b))


# --- a box sliding on a level floor ------------------------------------------------------------


@pytest.mark.parametrize("degrees", HEADINGS_DEG)
def test_a_box_sliding_on_a_level_floor_keeps_its_heading(degrees):
    state, _, _ = _level_slide(degrees)
    moved = state.pos[1] - (0.0, 0.0, BOX_HALF_EXTENTS[2])
    heading = _heading(degrees)
    track, course = _angle(moved, heading), _angle(state.vel[1], heading)
    assert track <= HEADING_TOLERANCE and course <= HEADING_TOLERANCE, (
        f"launched at {degrees}°, the box moved at {math.degrees(math.atan2(moved[1], moved[0])):.6f}° "
        f"and heads at {math.degrees(math.atan2(state.vel[1, 1], state.vel[1, 0])):.6f}° "
        f"({track:.3g} and {course:.3g} rad off; tolerance {HEADING_TOLERANCE} rad)"
    )


@pytest.mark.parametrize("degrees", HEADINGS_DEG)
def test_a_box_sliding_on_a_level_floor_decelerates_at_mu_g_along_its_slip(degrees):
    state, _, _ = _level_slide(degrees)
    t = MID_SLIDE_STEPS * DT
    heading = _heading(degrees)
    speed = float(state.vel[1] @ heading)
    distance = float((state.pos[1] - (0.0, 0.0, BOX_HALF_EXTENTS[2])) @ heading)
    expected_speed = SLIDE_SPEED - MU * G * t
    expected_distance = SLIDE_SPEED * t - MU * G * t * (t + DT) / 2.0
    assert abs(speed - expected_speed) <= SPEED_TOLERANCE, (
        f"at {degrees}°, t = {t} s: speed along the slip {speed!r} m/s, expected "
        f"v0 - μg t = {expected_speed!r} (off {speed - expected_speed:.3g}; tolerance "
        f"{SPEED_TOLERANCE})"
    )
    assert abs(distance - expected_distance) <= DISTANCE_TOLERANCE, (
        f"at {degrees}°, t = {t} s: distance along the slip {distance!r} m, expected "
        f"v0 t - μg t (t + dt)/2 = {expected_distance!r} (off {distance - expected_distance:.3g};"
        f" tolerance {DISTANCE_TOLERANCE})"
    )


@pytest.mark.parametrize("degrees", HEADINGS_DEG)
def test_the_friction_impulse_at_each_sliding_corner_opposes_that_corners_slip(degrees):
    state, report, start = _level_slide(degrees)
    contacts = report.contacts
    assert contacts.count == 4, f"the box rests on {contacts.count} corners, not 4"
    for i in range(contacts.count):
        box_side = 1.0 if contacts.body_b[i] == 1 else -1.0  # the report's impulse acts on B
        arm = contacts.point[i] - start[1]
        slip = state.vel[1] + np.cross(state.ang_vel[1], arm)
        slip -= (slip @ contacts.normal[i]) * contacts.normal[i]
        friction = box_side * report.friction_impulse[i]
        limit = MU * report.normal_impulse[i]
        off = math.pi - _angle(friction, slip)
        assert off <= ANTIPARALLEL_TOLERANCE, (
            f"at {degrees}°, corner {i}: friction impulse {friction} N·s is {off:.3g} rad from "
            f"antiparallel to the slip {slip} m/s (tolerance {ANTIPARALLEL_TOLERANCE} rad)"
        )
        magnitude = float(np.linalg.norm(friction))
        assert abs(magnitude - limit) <= RIM_TOLERANCE * limit, (
            f"at {degrees}°, corner {i}: sliding friction impulse {magnitude!r} N·s, expected "
            f"μ λ_n = {limit!r} (a sliding contact's impulse lies on the disc's rim)"
        )


# --- a box on an incline whose fall line is oblique to the world axes -------------------------


INCLINE_SLIDES = {"accelerating": (0.2, 0.0, 500), "decelerating": (0.5, SLIDE_SPEED, 300)}
"""μ, launch speed down the fall line (m/s) and steps of the two incline slides: released at
rest and accelerating for 0.5 s; launched at 1 m/s and decelerating for 0.3 s (it stops at
0.549 s)."""


@functools.cache
def _incline_slide(name: str) -> tuple[float, float, float, float]:
    """The incline slide ``name`` run to its end: its distance off the fall line (m), its
    angular velocity about the normal (rad/s), its speed down the fall line (m/s) and the
    closed form of that speed, v0 + g(sin θ - μ cos θ) t."""
    mu, speed, steps = INCLINE_SLIDES[name]
    model, state, normal, fall_line = _incline_box(mu, speed)
    for _ in range(steps):
        state, _ = step(model, state, SETTINGS)
    theta = math.radians(INCLINE_DEG)
    moved = state.pos[1] - BOX_HALF_EXTENTS[2] * normal
    return (
        float(np.linalg.norm(moved - (moved @ fall_line) * fall_line)),
        float(state.ang_vel[1] @ normal),
        float(state.vel[1] @ fall_line),
        speed + G * (math.sin(theta) - mu * math.cos(theta)) * steps * DT,
    )


@pytest.mark.parametrize("name", INCLINE_SLIDES)
def test_a_box_sliding_down_an_oblique_incline_does_not_yaw(name):
    _, yaw, _, _ = _incline_slide(name)
    assert abs(yaw) <= YAW_TOLERANCE, (
        f"{name} (μ = {INCLINE_SLIDES[name][0]}): the box turns about the incline's normal at "
        f"{yaw:.3g} rad/s at the end (tolerance {YAW_TOLERANCE})"
    )


@pytest.mark.parametrize("name", INCLINE_SLIDES)
def test_a_box_sliding_down_an_oblique_incline_keeps_to_the_fall_line(name):
    lateral, _, down, expected = _incline_slide(name)
    assert lateral <= LATERAL_TOLERANCE, (
        f"{name} (μ = {INCLINE_SLIDES[name][0]}): the box ends {lateral:.3g} m off the fall "
        f"line (tolerance {LATERAL_TOLERANCE})"
    )
    assert abs(down - expected) <= INCLINE_SPEED_TOLERANCE, (
        f"{name} (μ = {INCLINE_SLIDES[name][0]}): the box ends moving down the fall line at "
        f"{down!r} m/s, expected v0 + g(sin θ - μ cos θ) t = {expected!r} (off "
        f"{down - expected:.3g}; tolerance {INCLINE_SPEED_TOLERANCE})"
    )


def test_a_box_on_an_incline_with_mu_above_tan_theta_stays_put():
    model, state, normal, _ = _incline_box(0.5, 0.0)  # tan 17° = 0.306 < 0.5: it sticks
    fastest = 0.0
    for k in range(1000):
        state, _ = step(model, state, SETTINGS)
        if k >= 10:  # after the first steps (no warm start at the first)
            fastest = max(fastest, float(np.linalg.norm(state.vel[1])))
    drift = float(np.linalg.norm(state.pos[1] - BOX_HALF_EXTENTS[2] * normal))
    assert fastest <= STICK_SPEED, (
        f"the sticking box moved at up to {fastest:.3g} m/s (tolerance {STICK_SPEED})"
    )
    assert drift <= STICK_DRIFT, (
        f"the sticking box drifted {drift:.3g} m in 1 s (tolerance {STICK_DRIFT})"
    )


def test_one_update_stops_a_sticking_contact_whatever_its_tangent_block():
    """A ball of unequal inertia (principal axes turned 30° about z) rolls down the incline
    from rest; with μ = 1 its one contact sticks. Its tangent block is anisotropic and not
    diagonal in the solver's tangents, yet with one solver sweep the contact point's slip
    after every step is zero: the full 2x2 block stops it in one update."""
    quat, normal, _ = _incline()
    radius = 0.1
    model, state = build_model(
        [
            Body(Plane(), fixed=True, orientation=quat, friction=1.0),
            Body(
                Sphere(radius),
                mass=1.0,
                inertia=(0.002, 0.004, 0.005),
                position=radius * normal,
                orientation=(math.cos(math.radians(15)), 0.0, 0.0, math.sin(math.radians(15))),
                friction=1.0,
            ),
        ]
    )
    settings = Settings(dt=DT, solver_iterations=1)
    worst = 0.0
    for _ in range(300):
        start = state.pos
        state, report = step(model, state, settings)
        arm = report.contacts.point[0] - start[1]
        slip = state.vel[1] + np.cross(state.ang_vel[1], arm)
        slip -= (slip @ normal) * normal
        worst = max(worst, float(np.linalg.norm(slip)))
    assert float(np.linalg.norm(state.vel[1])) > 0.5, "the ball did not roll"
    assert worst <= ONE_UPDATE_SLIP, (
        f"with one sweep the ball's contact still slips at up to {worst:.3g} m/s "
        f"(tolerance {ONE_UPDATE_SLIP})"
    )


# --- the update itself, on arbitrary tangent blocks ---------------------------------------------

FIXED_POINT_UPDATES = 400
"""Updates of one contact alone. Each cuts an angular error by at least (κ - 1)/(κ + 1) (the
bound in ``_friction_update``), 0.82 for the κ <= 10 drawn here: 400 updates bring an error of
π below 1e-30."""

KKT_TOLERANCE = 1e-9
"""rad and relative. A converged contact's impulse is antiparallel to its slip and on the rim,
to round-off of the O(1) values drawn (measured at most 8.9e-15 rad and 2.2e-16)."""

MINIMUM_TOLERANCE = 1e-9
"""Relative to the disc. The converged impulse is the least-kinetic-energy impulse of the disc,
found here independently by Brent's method on the rim angle (to 1e-15 rad): both are exact to
round-off (measured at most 4e-16)."""

RIM_SCAN = 3600
"""Rim angles scanned to bracket the least-energy one (0.1° apart: the energy on the rim has at
most two minima, 2 eigenvalues apart, far wider than that)."""


def _least_energy_impulse(block, sticking, radius):
    """The impulse of the disc |λ| <= radius nearest to ``sticking`` in the K-norm, found
    without the solver: ``sticking`` if it fits, else the rim angle where the energy's
    derivative changes sign, bracketed by a 3600-point scan and found by Brent's method."""
    if np.linalg.norm(sticking) <= radius:
        return sticking

    def rim(angle):
        return radius * np.array([math.cos(angle), math.sin(angle)])

    def energy(angle):
        gap = rim(angle) - sticking
        return 0.5 * gap @ block @ gap

    def slope(angle):  # dE/dφ = (dλ/dφ) · K (λ - λ_s)
        return (
            radius * np.array([-math.sin(angle), math.cos(angle)]) @ block @ (rim(angle) - sticking)
        )

    angles = np.linspace(-math.pi, math.pi, RIM_SCAN, endpoint=False)
    best = angles[np.argmin([energy(a) for a in angles])]
    width = 2 * math.pi / RIM_SCAN
    return rim(brentq(slope, best - width, best + width, xtol=1e-15, rtol=4 * np.finfo(float).eps))


@pytest.mark.parametrize("seed", range(40))
def test_a_contact_converges_to_coulomb_friction_on_any_tangent_block(seed):
    """One contact of random tangent block K (condition number up to 10, eigenvectors at any
    angle to the tangents), free slip and disc, updated alone until it no longer changes:
    its impulse is the least-energy impulse of the disc, and when it slides it has magnitude
    μ λ_n and opposes the final slip."""
    rng = np.random.default_rng(seed)
    stiff, angle = rng.uniform(0.5, 2.0), rng.uniform(0.0, math.pi)
    rotation = np.array([[math.cos(angle), -math.sin(angle)], [math.sin(angle), math.cos(angle)]])
    block = rotation @ np.diag([stiff, stiff * rng.uniform(1.0, 10.0)]) @ rotation.T  # 1/kg
    free_slip = rng.normal(size=2)  # m/s
    radius = float(rng.uniform(0.05, 1.5) * np.linalg.norm(np.linalg.solve(block, free_slip)))
    impulse = rng.normal(size=2) * radius  # a warm start anywhere
    for _ in range(FIXED_POINT_UPDATES):
        impulse = _friction_update(
            (free_slip + block @ impulse)[None, :],
            impulse[None, :],
            np.linalg.inv(block)[None, :, :],
            np.array([2.0 / np.trace(block)]),
            np.array([radius]),
        )[0]
    slip = free_slip + block @ impulse
    sticking = -np.linalg.solve(block, free_slip)
    expected = _least_energy_impulse(block, sticking, radius)
    assert np.linalg.norm(impulse - expected) <= MINIMUM_TOLERANCE * radius, (
        f"converged to {impulse}, the least-energy impulse is {expected} (disc {radius:.4g}, "
        f"K = {block.tolist()})"
    )
    if np.linalg.norm(sticking) > radius:  # sliding
        off = math.pi - _angle(np.append(impulse, 0.0), np.append(slip, 0.0))
        rim = abs(np.linalg.norm(impulse) - radius) / radius
        assert off <= KKT_TOLERANCE and rim <= KKT_TOLERANCE, (
            f"sliding: impulse {impulse} is {off:.3g} rad from antiparallel to the final slip "
            f"{slip} and {rim:.3g} off the rim (K = {block.tolist()})"
        )
