"""The reference side (``validation.reference``): it agrees with mini_engine where mini_engine
is right, and its own formulas are checked against independent computations (integrals over
the solid, SciPy's rotations, the spring energy's gradient)."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from random_scenes import random_spring_scene, random_unit_quaternions
from scipy.integrate import quad
from scipy.spatial.transform import Rotation

from mini_engine import Box, Capsule, Sphere
from mini_engine.forces import applied_loads as mini_applied_loads
from mini_engine.forces import spring_energies as mini_spring_energies
from mini_engine.rotation import quat_multiply as mini_quat_multiply
from mini_engine.rotation import quat_to_matrix as mini_quat_to_matrix
from mini_engine.shapes import solid_inertia
from validation.reference import loads, rotation
from validation.reference.mass_properties import box_inertia, capsule_inertia, sphere_inertia

AGREEMENT = 1e-12
"""Relative. Two implementations of one closed form differ by round-off only (measured:
below 1e-15 for the inertias, the spring loads and energies, 0 for the rotations)."""

INTEGRAL_AGREEMENT = 1e-10
"""Relative. ``scipy.integrate.quad`` at epsrel 1e-13 over the solid's slices (each piece
smooth between the breakpoints) against the closed form."""

GRADIENT_AGREEMENT = 1e-6
"""Relative. Central differences of step ``GRADIENT_STEP``: truncation ~ step² times the
energy's third derivative, round-off ~ 1e-16 / step of the energy, both far below this."""

GRADIENT_STEP = 1e-5
"""m for positions, rad for rotations: the central-difference step of the gradient check."""

HYPOTHESIS = settings(max_examples=300, deadline=None)
"""300 random configurations per property: well under a second each; hypothesis shrinks."""

length = st.floats(1e-3, 10.0)
mass = st.floats(1e-3, 1e3)


def relative_difference(got: np.ndarray, want: np.ndarray) -> float:
    """max |got - want| / max |want| (0 when both are zero)."""
    scale = float(np.max(np.abs(want), initial=0.0))
    difference = float(np.max(np.abs(np.asarray(got) - np.asarray(want)), initial=0.0))
    return difference / scale if scale > 0.0 else difference


# --- (a) the two implementations agree -----------------------------------------------------


@HYPOTHESIS
@given(
    body_mass=mass, radius=length, half_length=st.floats(0.0, 10.0), half=st.tuples(*[length] * 3)
)
def test_solid_inertias_agree_with_mini_engine(body_mass, radius, half_length, half):
    pairs = {
        "sphere": (solid_inertia(Sphere(radius), body_mass), sphere_inertia(body_mass, radius)),
        "box": (solid_inertia(Box(half), body_mass), box_inertia(body_mass, half)),
        "capsule": (
            solid_inertia(Capsule(radius, half_length), body_mass),
            capsule_inertia(body_mass, radius, half_length),
        ),
    }
    for shape, (mini, reference) in pairs.items():
        error = relative_difference(reference, mini)
        assert error <= AGREEMENT, (
            f"{shape}: reference {np.diag(reference).tolist()}, mini {np.diag(mini).tolist()}, "
            f"relative difference {error:.3g}"
        )


@HYPOTHESIS
@given(seed=st.integers(0, 2**32 - 1))
def test_spring_loads_and_energies_agree_with_mini_engine(seed):
    model, state, springs = random_spring_scene(seed)
    mini_force, mini_torque = mini_applied_loads(model, state, mini_quat_to_matrix(state.quat))
    rot = rotation.quat_to_matrix(state.quat)
    constant = (~model.body_fixed, model.body_force, model.body_torque)
    state_arrays = (state.pos, rot, state.vel, state.ang_vel)
    force, torque = loads.applied_loads(springs, *constant, *state_arrays)
    error = relative_difference(np.stack([force, torque]), np.stack([mini_force, mini_torque]))
    assert error <= AGREEMENT, (
        f"seed {seed}: reference force {force.tolist()} torque {torque.tolist()}, mini force "
        f"{mini_force.tolist()} torque {mini_torque.tolist()}: relative difference {error:.3g}"
    )
    mini_energy = mini_spring_energies(model, state.pos, mini_quat_to_matrix(state.quat))
    energy = loads.spring_energies(springs, state.pos, rot)
    error = relative_difference(energy, mini_energy)
    assert error <= AGREEMENT, f"seed {seed}: reference {energy}, mini {mini_energy}: {error:.3g}"


def test_batched_spring_energy_is_the_energy_of_each_state():
    """A recording of s states in one call gives each state's energy (the invariants' use)."""
    model, state, springs = random_spring_scene(7)
    rng = np.random.default_rng(8)
    pos = state.pos + 0.1 * rng.normal(size=(5, *state.pos.shape))
    rot = rotation.quat_to_matrix(random_unit_quaternions(rng, 5 * model.n_bodies))
    rot = rot.reshape(5, model.n_bodies, 3, 3)
    batched = loads.spring_energy(springs, pos, rot)
    one_by_one = [
        float(loads.spring_energies(springs, p, r).sum()) for p, r in zip(pos, rot, strict=True)
    ]
    assert np.allclose(batched, one_by_one, rtol=AGREEMENT, atol=0.0), (batched, one_by_one)


@HYPOTHESIS
@given(seed=st.integers(0, 2**32 - 1))
def test_rotations_agree_with_mini_engine(seed):
    rng = np.random.default_rng(seed)
    p, q = random_unit_quaternions(rng, 8), random_unit_quaternions(rng, 8)
    matrix_error = relative_difference(rotation.quat_to_matrix(p), mini_quat_to_matrix(p))
    product_error = relative_difference(rotation.quat_multiply(p, q), mini_quat_multiply(p, q))
    assert matrix_error <= AGREEMENT and product_error <= AGREEMENT, (
        f"seed {seed}: matrices differ by {matrix_error:.3g}, products by {product_error:.3g}"
    )


# --- (b) the reference's own formulas, checked independently --------------------------------


def slice_integrals(radius_at, z_max: float, breaks: tuple[float, ...]) -> tuple[float, ...]:
    """(volume, ∫(x² + y²) dV, ∫(y² + z²) dV) m³, m⁵, m⁵ of a solid of revolution about z
    whose slice at height z is a disc of radius ``radius_at(z)``, for |z| <= ``z_max``: a disc
    of radius a has area π a², ∫(x² + y²) dA = π a⁴/2 and ∫ y² dA = π a⁴/4."""

    def integral(slice_value) -> float:
        value, _ = quad(slice_value, -z_max, z_max, points=breaks, epsabs=0.0, epsrel=1e-13)
        return value

    volume = integral(lambda z: np.pi * radius_at(z) ** 2)
    axial = integral(lambda z: np.pi * radius_at(z) ** 4 / 2.0)
    transverse = integral(
        lambda z: np.pi * radius_at(z) ** 4 / 4.0 + z * z * np.pi * radius_at(z) ** 2
    )
    return volume, axial, transverse


CAPSULES = [(0.05, 0.15), (1.0, 0.0), (0.01, 3.0), (2.0, 0.1), (0.3, 0.3)]
"""(radius, half_length) m: the library's capsule, a ball, a thin rod, a flat pill, equal parts."""


def test_capsule_inertia_equals_the_integral_over_the_solid():
    """Disc slices along the axis: the cylinder's slices have the radius r, each cap's
    sqrt(r² - (|z| - h)²); no decomposition into cylinder and caps, no parallel-axis term."""
    body_mass = 2.5
    for radius, half_length in CAPSULES:

        def radius_at(z, r=radius, h=half_length):
            return np.sqrt(max(r * r - max(abs(z) - h, 0.0) ** 2, 0.0))

        volume, axial, transverse = slice_integrals(
            radius_at, half_length + radius, (-half_length, half_length)
        )
        density = body_mass / volume
        integrated = np.diag([transverse, transverse, axial]) * density
        closed_form = capsule_inertia(body_mass, radius, half_length)
        error = relative_difference(closed_form, integrated)
        assert error <= INTEGRAL_AGREEMENT, (
            f"r={radius}, h={half_length}: closed form {np.diag(closed_form).tolist()}, "
            f"integral {np.diag(integrated).tolist()}, relative difference {error:.3g}"
        )


def test_sphere_and_box_inertia_equal_the_integral_over_the_solid():
    body_mass, radius = 3.0, 0.7
    volume, axial, transverse = slice_integrals(
        lambda z: np.sqrt(max(radius * radius - z * z, 0.0)), radius, ()
    )
    sphere = sphere_inertia(body_mass, radius)
    for moment in (axial, transverse):  # a ball's: equal about every axis
        integrated = moment * body_mass / volume
        error = relative_difference(sphere, np.eye(3) * integrated)
        assert error <= INTEGRAL_AGREEMENT, (np.diag(sphere).tolist(), integrated, error)
    half = np.array([0.1, 0.4, 1.3])
    # ∫ x² over [-h, h] is 2h³/3; the box's second moments are products of 1D integrals
    second = np.array([quad(lambda x: x * x, -h, h, epsrel=1e-13)[0] for h in half])
    width = 2.0 * half
    box_volume = width.prod()
    integrated = np.diag(
        [
            (second[1] * width[0] * width[2] + second[2] * width[0] * width[1]),
            (second[0] * width[1] * width[2] + second[2] * width[0] * width[1]),
            (second[0] * width[1] * width[2] + second[1] * width[0] * width[2]),
        ]
    ) * (body_mass / box_volume)
    box = box_inertia(body_mass, half)
    error = relative_difference(box, integrated)
    assert error <= INTEGRAL_AGREEMENT, (np.diag(box).tolist(), np.diag(integrated).tolist(), error)


def test_capsule_limits_are_the_ball_and_the_thin_rod():
    """half_length -> 0 is a ball (exactly); radius -> 0 a thin rod, m ℓ²/12 across and 0 along,
    to first order in r/ℓ (the caps and the cylinder's own r²/4 term)."""
    body_mass = 1.7
    ball = capsule_inertia(body_mass, 0.4, 0.0)
    assert relative_difference(ball, sphere_inertia(body_mass, 0.4)) <= AGREEMENT, ball
    half_length, radius = 1.0, 1e-6
    rod = capsule_inertia(body_mass, radius, half_length)
    thin_rod = body_mass * (2.0 * half_length) ** 2 / 12.0
    across = abs(rod[0, 0] - thin_rod) / thin_rod
    assert across <= 10.0 * radius / half_length, (rod[0, 0], thin_rod, across)
    assert rod[2, 2] <= body_mass * radius**2, rod[2, 2]


def anchor_lengths(springs: loads.Springs, pos: np.ndarray, quat: np.ndarray) -> np.ndarray:
    """(k,) m, each spring's anchor distance, computed here with SciPy's rotations."""
    rot = Rotation.from_quat(quat, scalar_first=True)
    ends = []
    for body, anchor in ((springs.body_a, springs.anchor_a), (springs.body_b, springs.anchor_b)):
        world = body == loads.WORLD
        safe = np.where(world, 0, body)
        moved = pos[safe] + rot[safe].apply(anchor)
        ends.append(np.where(world[:, None], anchor, moved))
    return np.linalg.norm(ends[1] - ends[0], axis=1)


def turned(quat: np.ndarray, angle: np.ndarray) -> np.ndarray:
    """(n, 4) the orientations ``quat (n, 4)`` turned further by the world rotation vectors
    ``angle (n, 3)`` rad, one per body (SciPy's rotations)."""
    rot = Rotation.from_rotvec(angle) * Rotation.from_quat(quat, scalar_first=True)
    return rot.as_quat(scalar_first=True)


@settings(max_examples=60, deadline=None)
@given(seed=st.integers(0, 2**32 - 1))
def test_spring_loads_are_minus_the_gradient_of_tension_times_length(seed):
    """With each spring's tension f frozen at the state (f = k (L - rest) + c dL/dt, dL/dt by
    central differences of SciPy-rotated anchors along the motion), the spring loads are minus
    the gradient of Σ f L: forces along the centres' displacements, torques along world-frame
    turns of each body about its centre."""
    _, state, springs = random_spring_scene(seed)
    pos, quat, vel, ang_vel = state.pos, state.quat, state.vel, state.ang_vel
    step = GRADIENT_STEP
    stretch_speed = (
        anchor_lengths(springs, pos + step * vel, turned(quat, step * ang_vel))
        - anchor_lengths(springs, pos - step * vel, turned(quat, -step * ang_vel))
    ) / (2.0 * step)
    tension = springs.stiffness * (anchor_lengths(springs, pos, quat) - springs.rest_length)
    tension += springs.damping * stretch_speed

    def work(p: np.ndarray, q: np.ndarray) -> float:
        return float(np.sum(tension * anchor_lengths(springs, p, q)))

    gradient_force, gradient_torque = np.zeros_like(pos), np.zeros_like(pos)
    for body in range(len(pos)):
        for axis in range(3):
            shift = np.zeros_like(pos)
            shift[body, axis] = step
            change = work(pos + shift, quat) - work(pos - shift, quat)
            gradient_force[body, axis] = -change / (2.0 * step)
            change = work(pos, turned(quat, shift)) - work(pos, turned(quat, -shift))
            gradient_torque[body, axis] = -change / (2.0 * step)
    force, torque = loads.spring_loads(
        springs, len(pos), pos, rotation.quat_to_matrix(quat), vel, ang_vel
    )
    scale = max(np.abs(force).max(), np.abs(torque).max(), 1e-9)
    error = max(np.abs(force - gradient_force).max(), np.abs(torque - gradient_torque).max())
    assert error <= GRADIENT_AGREEMENT * scale, (
        f"seed {seed}: force {force.tolist()} vs {gradient_force.tolist()}; torque "
        f"{torque.tolist()} vs {gradient_torque.tolist()} (difference {error:.3g}, scale {scale:.3g})"
    )


@HYPOTHESIS
@given(seed=st.integers(0, 2**32 - 1))
def test_rotations_agree_with_scipy(seed):
    rng = np.random.default_rng(seed)
    p, q = random_unit_quaternions(rng, 8), random_unit_quaternions(rng, 8)
    rot_p = Rotation.from_quat(p, scalar_first=True)
    rot_q = Rotation.from_quat(q, scalar_first=True)
    matrix_error = relative_difference(rotation.quat_to_matrix(p), rot_p.as_matrix())
    assert matrix_error <= AGREEMENT, (
        f"seed {seed}: matrices differ from SciPy's by {matrix_error:.3g}"
    )
    product = rotation.quat_multiply(p, q)
    expected = (rot_p * rot_q).as_quat(scalar_first=True)
    sign = np.sign(np.sum(product * expected, axis=1, keepdims=True))  # q and -q: one rotation
    product_error = relative_difference(product, sign * expected)
    assert product_error <= AGREEMENT, (
        f"seed {seed}: {product.tolist()} vs SciPy {expected.tolist()}"
    )
    angle = rotation.rotation_angle(p, q)
    scipy_angle = (rot_q.inv() * rot_p).magnitude()
    assert np.allclose(angle, scipy_angle, rtol=0.0, atol=1e-12), (angle, scipy_angle)


@pytest.mark.parametrize("shape", [(1,), (3,), (32,), (33,), (4, 8), (5, 7), (300,)])
def test_small_arrays_from_the_product_table_are_the_formulas_bit_for_bit(shape, monkeypatch):
    """Why rotation.TABLE_ROWS may switch small arrays (the integration's right-hand side) to
    the table of products: matrices, Hamilton and cross products equal the written-out
    formulas' in every bit, signed zeros included, on either side of the switch and with
    leading axes."""
    rng = np.random.default_rng(sum(shape))
    p, q = rng.normal(size=(*shape, 4)), rng.normal(size=(*shape, 4))
    p.reshape(-1, 4)[1::3, 1:3] = -0.0  # signed zeros among random entries
    q.reshape(-1, 4)[2::4, 0] = -0.0

    def results() -> dict[str, np.ndarray]:
        return {
            "matrix": rotation.quat_to_matrix(p),
            "product": rotation.quat_multiply(p, q),
            "cross": rotation.cross(p[..., 1:], q[..., :3]),
        }

    table = results()
    monkeypatch.setattr(rotation, "TABLE_ROWS", -1)  # the written-out formulas only
    for name, slow in results().items():
        assert table[name].shape == slow.shape, (name, table[name].shape, slow.shape)
        differing = int(np.count_nonzero(table[name].view(np.uint64) != slow.view(np.uint64)))
        assert differing == 0, f"{shape}: {differing} {name} entries differ in their bits"


def test_integer_quaternions_take_the_product_table_as_the_formulas_do(monkeypatch):
    """An integer array gives the written-out formulas' results (dtype included) on the
    table's path too."""
    quat = np.array([[1, 0, 0, 0], [0, 1, 0, 0], [0, 0, 0, -1]])
    table = (rotation.quat_to_matrix(quat), rotation.quat_multiply(quat, quat[::-1].copy()))
    monkeypatch.setattr(rotation, "TABLE_ROWS", -1)
    formulas = (rotation.quat_to_matrix(quat), rotation.quat_multiply(quat, quat[::-1].copy()))
    for fast, slow in zip(table, formulas, strict=True):
        assert fast.dtype == slow.dtype and np.array_equal(fast, slow), (fast, slow)
