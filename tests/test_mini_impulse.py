"""The documented impulse (formulas.md section 3) as the solver applies it.

A single contact is fed straight to the solver and compared with the formula
written out independently here; then whole sphere impacts are compared with
their closed forms.
"""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import assume, given, settings
from hypothesis import strategies as st

from mini_engine import Body, Contacts, Settings, Sphere, build_model, step
from mini_engine.quantities import kinetic_energy, linear_momentum
from mini_engine.rotation import quat_normalize, quat_to_matrix, world_inertia
from mini_engine.solver import solve_contacts

MACHINE_EPSILON = np.finfo(float).eps

FORMULA_TOLERANCE = 1e-9
"""Relative. The solver computes the same j by an algebraically equal route (the scalar triple
product rewritten, one sweep); only round-off separates them, amplified at most by the mass
ratio range used here (1e3)."""

MOMENTUM_TOLERANCE = 1e-12
"""Relative to the momentum scale: the impulse pair ±j n cancels exactly up to round-off."""


def documented_impulse(m_a, m_b, inv_i_a, inv_i_b, x_a, x_b, v_a, v_b, w_a, w_b, point, n, e):
    """formulas.md section 3, line by line."""
    r_a, r_b = point - x_a, point - x_b
    v_pa = v_a + np.cross(w_a, r_a)
    v_pb = v_b + np.cross(w_b, r_b)
    v_rel = v_pb - v_pa
    denominator = (
        1 / m_a
        + 1 / m_b
        + np.dot(
            np.cross(inv_i_a @ np.cross(r_a, n), r_a) + np.cross(inv_i_b @ np.cross(r_b, n), r_b), n
        )
    )
    j = -(1 + e) * np.dot(v_rel, n) / denominator
    return (
        j,
        v_a - j / m_a * n,
        v_b + j / m_b * n,
        w_a - inv_i_a @ np.cross(r_a, j * n),
        w_b + inv_i_b @ np.cross(r_b, j * n),
    )


unit = st.floats(-1.0, 1.0)
vec3 = st.lists(unit, min_size=3, max_size=3).map(np.array)


@settings(max_examples=300, deadline=None)
@given(
    masses=st.tuples(st.floats(0.1, 100.0), st.floats(0.1, 100.0)),
    shapes=st.lists(st.floats(0.5, 2.0), min_size=6, max_size=6),
    quats=st.lists(unit, min_size=8, max_size=8).filter(
        lambda q: np.linalg.norm(q[:4]) > 0.1 and np.linalg.norm(q[4:]) > 0.1
    ),
    offsets=st.tuples(vec3, vec3),
    velocities=st.tuples(vec3, vec3, vec3, vec3),
    normal=vec3.filter(lambda n: np.linalg.norm(n) > 0.1),
    e=st.floats(0.0, 1.0),
)
def test_single_contact_impulse_equals_documented_formula(
    masses, shapes, quats, offsets, velocities, normal, e
):
    n = normal / np.linalg.norm(normal)
    v_a, v_b, w_a, w_b = (3.0 * v for v in velocities)
    x_a, x_b = np.zeros(3), 0.5 * n
    point = 0.25 * n + 0.2 * offsets[0]
    v_rel = (v_b + np.cross(w_b, point - x_b)) - (v_a + np.cross(w_a, point - x_a))
    assume(abs(np.dot(v_rel, n)) > 1e-3)
    if np.dot(v_rel, n) > 0:  # reversing every velocity reverses v_rel: now approaching
        v_a, v_b, w_a, w_b = -v_a, -v_b, -w_a, -w_b
    quat = quat_normalize(np.array([quats[:4], quats[4:]]))
    inertia = np.array([np.diag(shapes[:3]), np.diag(shapes[3:])]) * np.array(masses)[:, None, None]
    model, state = build_model(
        [
            Body(
                Sphere(0.25),
                mass=masses[i],
                inertia=inertia[i],
                position=x,
                orientation=quat[i],
                restitution=e,
            )
            for i, x in enumerate((x_a, x_b))
        ],
        gravity=(0.0, 0.0, 0.0),
    )
    inv_world = world_inertia(quat_to_matrix(quat), np.linalg.inv(inertia))
    contact = Contacts(np.array([0]), np.array([1]), point[None], n[None], np.array([0.0]))
    vel, ang_vel = np.array([v_a, v_b]), np.array([w_a, w_b])
    solution = solve_contacts(model, contact, state.pos, inv_world, vel, ang_vel, Settings())

    j, va2, vb2, wa2, wb2 = documented_impulse(
        masses[0], masses[1], inv_world[0], inv_world[1], x_a, x_b, v_a, v_b, w_a, w_b, point, n, e
    )
    scale = max(1.0, np.abs([va2, vb2, wa2, wb2]).max())
    error = max(
        np.abs(solution.vel - [va2, vb2]).max(), np.abs(solution.ang_vel - [wa2, wb2]).max()
    )
    assert error < FORMULA_TOLERANCE * scale, f"velocity error {error:.3e} (j = {j:.6g})"
    assert abs(solution.report.normal_impulse[0] - j) < FORMULA_TOLERANCE * max(1.0, abs(j))

    p_before = masses[0] * v_a + masses[1] * v_b
    p_after = masses[0] * solution.vel[0] + masses[1] * solution.vel[1]
    p_scale = max(1.0, masses[0] * np.abs(v_a).max(), masses[1] * np.abs(v_b).max())
    assert np.abs(p_after - p_before).max() < MOMENTUM_TOLERANCE * p_scale * 100, (
        f"momentum changed by {np.abs(p_after - p_before).max():.3e}"
    )
    measured_e = (
        -solution.report.normal_velocity_after[0] / solution.report.normal_velocity_before[0]
    )
    assert abs(measured_e - e) < FORMULA_TOLERANCE * 10, (
        f"measured e {measured_e:.12f}, requested {e}"
    )


def head_on(m1, m2, v1, v2, e, offset=(0.0, 0.0), spin=(0.0, 0.0, 0.0)):
    """Two spheres (r = 0.1) on the x axis, no gravity; state after the impact and the reports."""
    model, state = build_model(
        [
            Body(
                Sphere(0.1),
                mass=m1,
                position=(-0.1005, 0.0, 0.0),
                velocity=(v1, *offset),
                angular_velocity=spin,
                restitution=e,
            ),
            Body(
                Sphere(0.1),
                mass=m2,
                position=(0.1005, 0.0, 0.0),
                velocity=(v2, 0.0, 0.0),
                restitution=e,
            ),
        ],
        gravity=(0.0, 0.0, 0.0),
    )
    initial = state
    reports = []
    for _ in range(200):
        state, report = step(model, state, Settings(dt=1e-3))
        if report.contacts.count:
            reports.append(report)
    return model, initial, state, reports


CLOSED_FORM_TOLERANCE = 1e-12
"""Relative. A central frictionless impact of spheres is one contact, solved in one sweep:
the closed form holds to round-off."""


@pytest.mark.parametrize("e", [0.0, 0.5, 1.0])
@pytest.mark.parametrize("mass_ratio", [1.0, 10.0, 1e6])
def test_head_on_impact_matches_closed_form(e, mass_ratio):
    m1, m2, v1, v2 = 1.0, mass_ratio, 1.0, -0.5
    model, initial, final, reports = head_on(m1, m2, v1, v2, e)
    assert len(reports) >= 1, "the spheres never touched"
    expected_1 = ((m1 - e * m2) * v1 + (1 + e) * m2 * v2) / (m1 + m2)
    expected_2 = ((m2 - e * m1) * v2 + (1 + e) * m1 * v1) / (m1 + m2)
    got = final.vel[:, 0]
    scale = max(abs(v1), abs(v2))
    assert abs(got[0] - expected_1) < CLOSED_FORM_TOLERANCE * scale * mass_ratio, (
        f"v1' = {got[0]:.15f}, closed form {expected_1:.15f}"
    )
    assert abs(got[1] - expected_2) < CLOSED_FORM_TOLERANCE * scale, (
        f"v2' = {got[1]:.15f}, closed form {expected_2:.15f}"
    )
    first = reports[0]
    measured_e = -first.normal_velocity_after[0] / first.normal_velocity_before[0]
    assert abs(measured_e - e) < CLOSED_FORM_TOLERANCE * 10, f"measured e = {measured_e:.15f}"
    p0, p1 = linear_momentum(model, initial)[0], linear_momentum(model, final)[0]
    assert np.abs(p1 - p0).max() < MOMENTUM_TOLERANCE * mass_ratio * 10, f"Δp = {p1 - p0}"
    if e == 1.0:
        k0, k1 = kinetic_energy(model, initial)[0], kinetic_energy(model, final)[0]
        assert abs(k1 - k0) / k0 < 1e-12, f"e = 1 changed KE by {(k1 - k0) / k0:.3e}"
    else:
        mu = m1 * m2 / (m1 + m2)
        lost = 0.5 * (1 - e**2) * mu * (v1 - v2) ** 2
        k0, k1 = kinetic_energy(model, initial)[0], kinetic_energy(model, final)[0]
        assert abs((k0 - k1) - lost) < 1e-9 * k0, f"KE lost {k0 - k1:.12f} J, formula {lost:.12f} J"


def test_oblique_impact_with_spin_keeps_tangential_motion_and_spin():
    """Frictionless spheres: the impulse acts along the line of centres, so the tangential
    velocity and the spins are untouched and the normal components follow the 1-D law."""
    e = 0.5
    _model, initial, final, reports = head_on(
        1.0, 2.0, 1.0, 0.0, e, offset=(0.3, -0.2), spin=(5.0, -3.0, 2.0)
    )
    pushing = [r for r in reports if r.normal_impulse.any()]
    assert len(pushing) == 1, f"impulses in {len(pushing)} steps"
    report = pushing[0]
    n = report.contacts.normal[0]
    before_a = initial.vel[0]
    # velocity of A at the contact step (no gravity: unchanged before the impact)
    tangential_before = before_a - np.dot(before_a, n) * n
    tangential_after = final.vel[0] - np.dot(final.vel[0], n) * n
    assert np.abs(tangential_after - tangential_before).max() < 1e-12
    assert np.abs(final.ang_vel - initial.ang_vel).max() < 1e-12, "spin changed"
    u1, u2 = np.dot(initial.vel[0], n), np.dot(initial.vel[1], n)
    expected = ((1.0 - e * 2.0) * u1 + (1 + e) * 2.0 * u2) / 3.0
    assert abs(np.dot(final.vel[0], n) - expected) < 1e-12, (
        f"normal velocity {np.dot(final.vel[0], n):.15f}, closed form {expected:.15f}"
    )


@pytest.mark.parametrize("e", [0.1, 0.5, 0.9, 1.0])
def test_measured_restitution_equals_requested_on_a_plane(e):
    """A sphere dropped on the ground: every impact's measured e is the requested e
    (restitution threshold 0, restitution = max of the pair, the ground's e = 0)."""
    from mini_engine import Plane

    model, state = build_model(
        [Body(Plane(), fixed=True), Body(Sphere(0.1), position=(0, 0, 0.6), restitution=e)]
    )
    measured = []
    for _ in range(3000):
        state, report = step(model, state, Settings(dt=1e-3))
        if report.contacts.count and report.normal_velocity_before[0] < -0.05:
            measured.append(-report.normal_velocity_after[0] / report.normal_velocity_before[0])
    assert measured, "no impact"
    error = np.abs(np.array(measured) - e).max()
    assert error < 1e-12, f"measured e {measured} for requested {e}"
