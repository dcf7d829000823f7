"""Model building, mass properties, settings validation, springs and the orientation update."""

from __future__ import annotations

import numpy as np
import pytest

from mini_engine import (
    Body,
    Box,
    Capsule,
    Plane,
    Settings,
    Sphere,
    Spring,
    build_model,
    step,
)
from mini_engine.forces import spring_forces
from mini_engine.integrate import ORIENTATION_RULES
from mini_engine.rotation import quat_to_matrix, rotation_quat

EXACT = 1e-12
"""Relative. Closed-form mass properties are computed with a handful of flops."""


@pytest.mark.parametrize(
    ("shape", "mass", "expected"),
    [
        (Sphere(0.1), 2.0, [0.008, 0.008, 0.008]),  # 2/5 m r²
        (Box((0.05, 0.2, 0.45)), 10.0, [0.80833333, 0.68333333, 0.14166667]),  # m(b²+c²)/12
        # engines.md 1.3: MuJoCo computes the capsule exactly (m = 1, r = 0.1, half-length 0.2)
        (Capsule(0.1, 0.2), 1.0, [0.026625, 0.026625, 0.00475]),
    ],
)
def test_solid_mass_properties(shape, mass, expected):
    model, _ = build_model([Body(shape, mass=mass)])
    got = np.diag(model.body_inertia[0])
    assert np.allclose(got, expected, rtol=1e-7), f"inertia {got}, expected {expected}"
    assert np.allclose(model.body_inv_inertia[0] @ model.body_inertia[0], np.eye(3), atol=EXACT)


def test_explicit_inertia_overrides_the_shape():
    full = [[0.3, 0.02, 0.0], [0.02, 0.25, 0.0], [0.0, 0.0, 0.1]]
    model, _ = build_model(
        [Body(Box((0.1, 0.1, 0.1)), inertia=full), Body(Sphere(1), inertia=(1, 2, 2.5))]
    )
    assert np.array_equal(model.body_inertia[0], np.array(full))
    assert np.array_equal(np.diag(model.body_inertia[1]), [1, 2, 2.5])
    assert not model.body_isotropic[0] and not model.body_isotropic[1]


@pytest.mark.parametrize(
    ("body", "field"),
    [
        (Body(Sphere(0.1), mass=0.0), "mass"),
        (Body(Sphere(0.1), mass=float("nan")), "mass"),
        (Body(Plane()), "fixed"),
        (Body(Sphere(0.1), orientation=(1, 0.1, 0, 0)), "orientation"),
        (Body(Sphere(0.1), inertia=[[1, 0.5, 0], [0, 1, 0], [0, 0, 1]]), "inertia"),
        (Body(Sphere(0.1), inertia=(1, -1, 1)), "inertia"),
        (Body(Sphere(0.1), position=(0, 0)), "position"),
    ],
)
def test_impossible_bodies_are_rejected_naming_the_field(body, field):
    with pytest.raises(ValueError, match=rf"\.{field}: expected"):
        build_model([body])


def test_near_unit_quaternion_is_normalised():
    _, state = build_model([Body(Sphere(0.1), orientation=(1 + 5e-7, 0, 0, 0))])
    assert abs(np.linalg.norm(state.quat[0]) - 1.0) < 1e-15


@pytest.mark.parametrize(
    "changes",
    [
        {"integrator": "rk4"},
        {"gyroscopic": "yes"},
        {"dt": 0.0},
        {"dt": float("nan")},
        {"solver_iterations": 0},
        {"restitution_threshold": -1.0},
        {"position_correction": "magic"},
    ],
)
def test_settings_reject_unknown_choices_and_bad_numbers(changes):
    name = next(iter(changes))
    with pytest.raises(ValueError, match=rf"Settings\.{name}: expected"):
        Settings(**changes)


def test_spring_force_and_torque_at_an_off_centre_anchor():
    """A spring stretched 0.5 m along x from a body-local anchor (0, 0.1, 0) to a world point."""
    model, state = build_model(
        [Body(Sphere(0.1))],
        springs=[
            Spring(
                0,
                None,
                anchor_a=(0, 0.1, 0),
                anchor_b=(1.5, 0.1, 0),
                stiffness=100.0,
                rest_length=1.0,
            )
        ],
        gravity=(0, 0, 0),
    )
    force, torque = spring_forces(model, state, quat_to_matrix(state.quat))
    assert np.allclose(force[0], [50.0, 0, 0]), f"force {force[0]}"
    assert np.allclose(torque[0], np.cross([0, 0.1, 0], [50.0, 0, 0])), f"torque {torque[0]}"


def test_spring_between_two_bodies_conserves_momentum_and_is_damped():
    model, state = build_model(
        [
            Body(Sphere(0.1), mass=1.0, velocity=(1, 0, 0)),
            Body(Sphere(0.1), mass=3.0, position=(1, 0, 0)),
        ],
        springs=[Spring(0, 1, stiffness=50.0, damping=2.0, rest_length=1.0)],
        gravity=(0, 0, 0),
    )
    p0 = model.body_mass @ state.vel
    cfg = Settings(dt=1e-3)
    for _ in range(10_000):  # damping rate c / (2 μ) = 1.33 /s: e^-13 after 10 s
        state, _ = step(model, state, cfg)
    p1 = model.body_mass @ state.vel
    relative = state.vel[1] - state.vel[0]
    assert np.abs(p1 - p0).max() < 1e-12, f"momentum changed by {p1 - p0}"
    assert np.linalg.norm(relative) < 1e-3, f"relative velocity {relative} not damped out"


@pytest.mark.parametrize("rule", sorted(ORIENTATION_RULES))
def test_orientation_update_rotates_about_world_axis(rule):
    """ω = (0, 0, 1) rad/s for 1 s turns a body 1 rad about world z (exactly for the
    exponential map, to O(dt) for the linearized rule)."""
    omega = np.array([[0.0, 0.0, 1.0]])
    quat = np.array([[np.cos(0.3), np.sin(0.3), 0.0, 0.0]])  # start tilted about x
    for _ in range(1000):
        quat = ORIENTATION_RULES[rule](quat, omega, 1e-3)
    expected = quat_to_matrix(rotation_quat(np.array([[0, 0, 1.0]]))) @ quat_to_matrix(
        np.array([[np.cos(0.3), np.sin(0.3), 0.0, 0.0]])
    )
    error = np.abs(quat_to_matrix(quat) - expected).max()
    tolerance = 1e-12 if rule == "exponential_map" else 1e-6
    assert error < tolerance, f"{rule}: rotation error {error:.3e}"
