"""The reference side's joint tree (``validation.reference.articulated``) against closed forms.

Each dynamic quantity is checked against what it must equal independently of how it is
computed: the mass matrix of a double pendulum written out by hand, the velocity-product bias
against Lagrange's equations from finite differences of that mass matrix (Christoffel symbols),
a large-amplitude compound pendulum's period against the complete elliptic integral, a slider on
a spring against the harmonic oscillator, a ball joint swinging in a plane against a hinge, and
energy over a chaotic double pendulum and a falling chain. The kinematics round-trips: the
stated poses at q = 0, joint coordinates read back from the poses of any configuration.
"""

from __future__ import annotations

import math

import numpy as np
import pytest
from scipy.special import ellipk

from validation.reference.articulated import (
    WORLD,
    Loads,
    StatedJoint,
    bias_forces,
    build_tree,
    energy,
    forward_kinematics,
    initial_velocities,
    joint_coordinates,
    mass_matrix,
    reference_motion,
)
from validation.reference.loads import Springs
from validation.reference.mass_properties import box_inertia, sphere_inertia

G = 9.81
GRAVITY = np.array([0.0, 0.0, -G])
Y_AXIS = np.array([0.0, 1.0, 0.0])

ROUND_OFF = 1e-12
"""Relative: kinematics and mass matrices are a few dozen float operations on unit-sized numbers."""

FINITE_DIFFERENCE = 1e-6
"""rad: the step of the central differences of M(q) (truncation ~h² = 1e-12, round-off
~eps/h = 2e-10 relative); their Christoffel sums agree to ``CHRISTOFFEL_TOLERANCE``."""

CHRISTOFFEL_TOLERANCE = 1e-7
"""Relative to |b|: the central differences' round-off eps·|M|/h = 2e-10 amplified by the sums."""

REFERENCE_TOLERANCE = 1e-8
"""Relative: DOP853 at rtol 3e-14 over a few hundred of its steps of a swing, with margin for
the closed forms evaluated in floats (module constants)."""


def no_loads(bodies: int, gravity=GRAVITY, springs: Springs | None = None) -> Loads:
    return Loads(
        gravity=np.asarray(gravity, dtype=float),
        springs=springs or empty_springs(),
        force=np.zeros((bodies, 3)),
        torque=np.zeros((bodies, 3)),
    )


def empty_springs() -> Springs:
    return Springs(
        body_a=np.zeros(0, dtype=int),
        body_b=np.zeros(0, dtype=int),
        anchor_a=np.zeros((0, 3)),
        anchor_b=np.zeros((0, 3)),
        stiffness=np.zeros(0),
        damping=np.zeros(0),
        rest_length=np.zeros(0),
    )


def identity_quats(n: int) -> np.ndarray:
    return np.tile([1.0, 0.0, 0.0, 0.0], (n, 1))


# --- a double pendulum of two balls on hinges about y ----------------------------------------

LENGTH = 0.7
MASS = 1.3
RADIUS = 0.05


X_AXIS = np.array([1.0, 0.0, 0.0])


def double_pendulum(types=("hinge", "hinge"), elbow_axis=Y_AXIS):
    """Pivot at the origin; ball 1 at (0, 0, -l), hinged to the world about y; ball 2 at
    (0, 0, -2l), hinged at ball 1's centre about ``elbow_axis``."""
    inertia = np.array([sphere_inertia(MASS, RADIUS)] * 2)
    pos = np.array([[0.0, 0.0, -LENGTH], [0.0, 0.0, -2 * LENGTH]])
    joints = [
        StatedJoint("shoulder", types[0], WORLD, 0, np.zeros(3), Y_AXIS),
        StatedJoint("elbow", types[1], 0, 1, pos[0], elbow_axis),
    ]
    return build_tree(joints, np.full(2, MASS), inertia, pos, identity_quats(2), np.zeros(2, bool))


def double_pendulum_mass_matrix(theta2: float) -> np.ndarray:
    """By hand: absolute angles φ1 = θ1, φ2 = θ1 + θ2; T = ½ (m l² + I) φ̇1² + ½ I φ̇2²
    + ½ m l² (φ̇1² + φ̇2² + 2 φ̇1 φ̇2 cos(φ2 - φ1)), then M_rel = Tᵀ M_abs T."""
    inertia = 0.4 * MASS * RADIUS**2
    ml2 = MASS * LENGTH**2
    coupling = ml2 * math.cos(theta2)
    absolute = np.array([[2 * ml2 + inertia, coupling], [coupling, ml2 + inertia]])
    to_absolute = np.array([[1.0, 0.0], [1.0, 1.0]])
    return to_absolute.T @ absolute @ to_absolute


@pytest.mark.parametrize("q", [(0.0, 0.0), (0.4, -1.1), (2.5, 3.0)])
def test_the_double_pendulums_mass_matrix_is_the_hand_written_one(q):
    tree = double_pendulum()
    got = mass_matrix(tree, np.array(q))
    want = double_pendulum_mass_matrix(q[1])
    assert np.allclose(got, want, rtol=ROUND_OFF, atol=ROUND_OFF * np.abs(want).max()), (got, want)


def test_the_stated_poses_are_q_zero_and_coordinates_read_back():
    tree = double_pendulum()
    at_zero = forward_kinematics(tree, tree.zero())
    assert np.allclose(at_zero.pos, tree.fixed_pos, atol=ROUND_OFF)
    q = np.array([0.3, -0.8])
    pose = forward_kinematics(tree, q)
    read = joint_coordinates(tree, pose.pos[None], pose.rot[None])
    assert math.isclose(read["shoulder"][0], 0.3, abs_tol=ROUND_OFF), read
    assert math.isclose(read["elbow"][0], -0.8, abs_tol=ROUND_OFF), read
    # the elbow's pivot is ball 1's centre: ball 2 stays at l from it
    assert math.isclose(np.linalg.norm(pose.pos[1] - pose.pos[0]), LENGTH, rel_tol=ROUND_OFF)


def christoffel_bias(tree, q: np.ndarray, nu: np.ndarray) -> np.ndarray:
    """Lagrange's velocity terms ``Ṁ ν - ½ ∂(νᵀ M ν)/∂q`` from central differences of M(q)."""
    nv = nu.size
    derivatives = []
    for k in range(nv):
        step = np.zeros(nv)
        step[k] = FINITE_DIFFERENCE
        derivatives.append(
            (mass_matrix(tree, q + step) - mass_matrix(tree, q - step)) / (2 * FINITE_DIFFERENCE)
        )
    m_dot = sum(nu[k] * derivatives[k] for k in range(nv))
    gradient = np.array([0.5 * nu @ derivatives[k] @ nu for k in range(nv)])
    return m_dot @ nu - gradient


ELBOWS = {
    "parallel": ("hinge", Y_AXIS),
    "crossed": ("hinge", X_AXIS),
    "bead": ("slider", np.array([0.0, 0.0, 1.0])),
}
"""The elbow joint of ``double_pendulum`` in the bias test: parallel axes; crossed axes (about
x, a hinge inside a hinge like Drake's babyboot), which turn the elbow's axis with the shoulder
(the ω_P × u θ̇ terms parallel axes never show); a bead sliding along the swinging arm (the
Coriolis term 2 ω_P × u ṡ)."""


@pytest.mark.parametrize("elbow", sorted(ELBOWS))
@pytest.mark.parametrize("q, nu", [((0.4, -1.1), (2.0, -3.0)), ((1.9, 0.7), (-0.5, 4.0))])
def test_the_velocity_product_bias_is_lagranges(q, nu, elbow):
    kind, axis = ELBOWS[elbow]
    tree = double_pendulum(("hinge", kind), axis)
    q, nu = np.array(q), np.array(nu)
    weightless = no_loads(2, gravity=np.zeros(3))
    got = bias_forces(tree, q, nu, weightless)
    want = christoffel_bias(tree, q, nu)
    error = np.abs(got - want).max() / np.abs(want).max()
    assert error < CHRISTOFFEL_TOLERANCE, (got, want, error)


def test_gravity_bias_is_the_weights_torque_about_each_pivot():
    tree = double_pendulum()
    q = np.array([0.5, 0.3])
    got = bias_forces(tree, q, np.zeros(2), no_loads(2))
    # b = ∂V/∂q, V = -m g l (cos φ1) - m g l (2 cos φ1... ): V = -m g l (2 cos φ1 + cos φ2)
    phi1, phi2 = q[0], q[0] + q[1]
    want = MASS * G * LENGTH * np.array([2 * math.sin(phi1) + math.sin(phi2), math.sin(phi2)])
    assert np.allclose(got, want, rtol=ROUND_OFF), (got, want)


# --- motion --------------------------------------------------------------------------------

ROD = np.array([0.02, 0.02, 0.5])
"""m: half extents of the compound pendulum's bar (1 m long)."""


def compound_pendulum(amplitude: float):
    """A 1 kg bar hinged about y at its top end (the origin), released from rest at
    ``amplitude`` rad: I_O = I_cm + m d², d = 0.5 m."""
    mass = 1.0
    turn = np.array([math.cos(amplitude / 2), 0.0, math.sin(amplitude / 2), 0.0])
    centre = 0.5 * np.array([-math.sin(amplitude), 0.0, -math.cos(amplitude)])
    # stated at the released pose: the joint's q = 0 is there, so θ(t) is relative to it
    joint = StatedJoint("pivot", "hinge", WORLD, 0, np.zeros(3), Y_AXIS)
    inertia = np.array([box_inertia(mass, 2 * ROD)])
    tree = build_tree([joint], np.ones(1), inertia, centre[None], turn[None], np.zeros(1, bool))
    inertia_pivot = inertia[0][1, 1] + mass * 0.25
    return tree, inertia_pivot


def test_a_large_swing_has_the_elliptic_integrals_period():
    amplitude = 2.0  # rad: far from the small-angle period (31 % longer)
    tree, inertia_pivot = compound_pendulum(amplitude)
    period = 4 * math.sqrt(inertia_pivot / (G * 0.5)) * ellipk(math.sin(amplitude / 2) ** 2)
    times = np.linspace(0.0, period, 41)  # dense enough to follow the angle past π
    motion, q, _ = reference_motion(tree, tree.zero(), np.zeros(1), no_loads(1), times)
    angle = q[:, 0]  # relative to the release: -amplitude at the bottom, -2 amplitude opposite
    quarter, half, whole = angle[10], angle[20], angle[40]
    assert abs(quarter + amplitude) < REFERENCE_TOLERANCE, angle
    assert abs(half + 2 * amplitude) < REFERENCE_TOLERANCE, angle
    assert abs(whole) < REFERENCE_TOLERANCE, angle
    read = joint_coordinates(tree, motion.pos, _rotations(motion.quat))["pivot"]
    assert np.allclose(read, angle, atol=REFERENCE_TOLERANCE), (read, angle)


def _rotations(quat: np.ndarray) -> np.ndarray:
    from validation.reference.rotation import quat_to_matrix

    return quat_to_matrix(quat)


def test_a_chaotic_double_pendulum_keeps_its_energy():
    tree = double_pendulum()
    loads = no_loads(2)
    q0, nu0 = np.array([2.0, 1.0]), np.array([0.0, 3.0])
    times = np.linspace(0.0, 5.0, 11)
    _, q, nu = reference_motion(tree, q0, nu0, loads, times)
    energies = np.array([energy(tree, q[s], nu[s], loads) for s in range(times.size)])
    scale = abs(energies[0]) + MASS * G * LENGTH
    drift = np.abs(energies - energies[0]).max() / scale
    assert drift < REFERENCE_TOLERANCE, drift


def test_a_slider_on_a_spring_is_the_harmonic_oscillator():
    """A 2 kg box slides along x on a spring (k = 50 N/m) to a world point, no gravity:
    s(t) = A cos(√(k/m) t) from s = A at rest (A = 0.1 m: stated stretched)."""
    mass, stiffness, amplitude = 2.0, 50.0, 0.1
    springs = Springs(
        body_a=np.array([0]),
        body_b=np.array([WORLD]),
        anchor_a=np.zeros((1, 3)),
        anchor_b=np.zeros((1, 3)),
        stiffness=np.array([stiffness]),
        damping=np.zeros(1),
        rest_length=np.zeros(1),
    )
    joint = StatedJoint(
        "rail", "slider", WORLD, 0, np.array([amplitude, 0, 0]), np.array([1.0, 0, 0])
    )
    inertia = np.array([box_inertia(mass, np.array([0.2, 0.2, 0.2]))])
    pos = np.array([[amplitude, 0.0, 0.0]])
    tree = build_tree([joint], np.full(1, mass), inertia, pos, identity_quats(1), np.zeros(1, bool))
    omega = math.sqrt(stiffness / mass)
    times = np.linspace(0.1, 2.0, 5)
    _, q, _ = reference_motion(
        tree, tree.zero(), np.zeros(1), no_loads(1, np.zeros(3), springs), times
    )
    want = amplitude * np.cos(omega * times) - amplitude  # relative to the stated pose
    assert np.allclose(q[:, 0], want, atol=REFERENCE_TOLERANCE * amplitude), (q[:, 0], want)


def test_a_ball_joint_swinging_in_a_plane_moves_as_a_hinge():
    hinged, balled = double_pendulum(), double_pendulum(("ball", "hinge"))
    times = np.linspace(0.0, 2.0, 9)
    swing = np.array([0.0, 1.5, 0.0])  # rad/s about y, in the ball's parent (world) frame
    _, q_hinge, _ = reference_motion(
        hinged, hinged.zero(), np.array([1.5, 0.0]), no_loads(2), times
    )
    nu_ball = np.concatenate([swing, [0.0]])
    motion_ball, _, _ = reference_motion(balled, balled.zero(), nu_ball, no_loads(2), times)
    read = joint_coordinates(balled, motion_ball.pos, _rotations(motion_ball.quat))
    assert np.allclose(read["shoulder"][:, 1], q_hinge[:, 0], atol=REFERENCE_TOLERANCE), read
    assert np.allclose(read["shoulder"][:, [0, 2]], 0.0, atol=REFERENCE_TOLERANCE), read


def test_stated_velocities_become_joint_rates_and_foreign_ones_are_measured():
    tree = double_pendulum()
    # the shoulder turning at 2 rad/s about y: ball 1 at (0, 0, -l) moves at ω × r along -x
    vel = np.array([[-2.0 * LENGTH, 0.0, 0.0], [-4.0 * LENGTH, 0.0, 0.0]])
    ang_vel = np.array([[0.0, 2.0, 0.0], [0.0, 2.0, 0.0]])
    nu0, residual = initial_velocities(tree, vel, ang_vel)
    assert np.allclose(nu0, [2.0, 0.0], atol=ROUND_OFF) and residual < ROUND_OFF, (nu0, residual)
    vel[1, 2] = 0.25  # ball 2 moving along z, which no hinge about y can do
    _, residual = initial_velocities(tree, vel, ang_vel)
    assert residual > 0.1, residual


def test_a_chain_falling_from_horizontal_keeps_its_energy():
    links, half = 6, 0.1
    mass = np.ones(links)
    inertia = np.array([box_inertia(1.0, np.array([2 * half, 0.02, 0.02]))] * links)
    pos = np.array([[(2 * k + 1) * half, 0.0, 0.0] for k in range(links)])
    joints = [StatedJoint("j0", "hinge", WORLD, 0, np.zeros(3), Y_AXIS)]
    joints += [
        StatedJoint(f"j{k}", "hinge", k - 1, k, np.array([2 * k * half, 0.0, 0.0]), Y_AXIS)
        for k in range(1, links)
    ]
    tree = build_tree(joints, mass, inertia, pos, identity_quats(links), np.zeros(links, bool))
    loads = no_loads(links)
    times = np.linspace(0.0, 1.0, 6)
    _, q, nu = reference_motion(tree, tree.zero(), np.zeros(links), loads, times)
    energies = np.array([energy(tree, q[s], nu[s], loads) for s in range(times.size)])
    scale = links * G * 2 * half * links
    assert np.abs(energies - energies[0]).max() / scale < REFERENCE_TOLERANCE, energies
    assert q[-1, 0] > 0.5, "the chain did not fall"  # about +y: x toward -z is positive


BABYBOOT_SPREAD_DEGREES = (1.9e-6, 1.3e-5)
"""deg: how far apart the four published simulations of Drake's chaotic babyboot (MotionGenesis's
Kutta-Merson at two settings and MATLAB's ode45, drake/multibody/benchmarks/chaotic_babyboot/MG/
test/MG_chaotic_babyboot_test.cc) put q_A and q_B at 10 s; the reference must land within three
times that spread of their expected values."""


def test_the_reference_reproduces_drakes_chaotic_babyboot_at_10_seconds():
    """A hinge inside a hinge, unstable: pendulum A (10 g at 7.5 cm, I_Ax = 50 g·cm²) about
    world x, plate B (100 g at 20 cm, I_B = diag(2500, 500, 2000) g·cm²) about A's rod; from
    q_A = 90°, q_B = 1° at rest. Published at 10 s: q_A = -61.312983340691°, q_B =
    -929.47789677244° (the same scene is scenarios/joints/chaotic_babyboot.yaml)."""

    def turn_x(angle):
        c, s = math.cos(angle), math.sin(angle)
        return np.array([[1.0, 0.0, 0.0], [0.0, c, -s], [0.0, s, c]])

    def turn_z(angle):
        c, s = math.cos(angle), math.sin(angle)
        return np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])

    q_a, q_b = math.radians(90.0), math.radians(1.0)
    pivot = np.array([0.0, 0.0, 2.0])
    rod = turn_x(q_a) @ np.array([0.0, 0.0, -1.0])
    frame_a = turn_x(q_a)
    frame_b = turn_x(q_a) @ np.diag([1.0, -1.0, -1.0]) @ turn_z(q_b)  # z along the rod
    pos = np.array([pivot + 0.075 * rod, pivot + 0.20 * rod])
    quats = np.array([_quaternion(frame_a), _quaternion(frame_b)])
    inertia = np.array([np.diag([5e-6] * 3), np.diag([2.5e-4, 5e-5, 2e-4])])
    joints = [
        StatedJoint("A", "hinge", WORLD, 0, pivot, X_AXIS),
        StatedJoint("B", "hinge", 0, 1, pos[1], rod),
    ]
    tree = build_tree(joints, np.array([0.01, 0.1]), inertia, pos, quats, np.zeros(2, bool))
    _, q, _ = reference_motion(tree, tree.zero(), np.zeros(2), no_loads(2), np.array([10.0]))
    got = np.degrees(q[-1] + [q_a, q_b])
    published = np.array([-61.312983340691, -929.47789677244])
    assert np.all(np.abs(got - published) < 3 * np.array(BABYBOOT_SPREAD_DEGREES)), got - published


def _quaternion(matrix: np.ndarray) -> np.ndarray:
    """w x y z of a rotation matrix with trace > -1 (the babyboot's frames)."""
    w = 0.5 * math.sqrt(1.0 + np.trace(matrix))
    return np.array(
        [
            w,
            (matrix[2, 1] - matrix[1, 2]) / (4 * w),
            (matrix[0, 2] - matrix[2, 0]) / (4 * w),
            (matrix[1, 0] - matrix[0, 1]) / (4 * w),
        ]
    )
