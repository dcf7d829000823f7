"""The interpolants between observed steps: exact where they must be, within their stated error
bounds, and far below the engines' own errors on the library's RK4 scenes."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from validation.engines.registry import create_adapter
from validation.measure.interpolation import (
    cubic_through,
    hermite_orientation,
    hermite_position,
)
from validation.measure.recording import record
from validation.reference.newton_euler import reference_motion
from validation.reference.rotation import rotation_angle
from validation.scenario import load_scenario
from validation.scenario.compiled import compile_scene
from validation.scenario.engine_spec import parse_engine_spec

RNG = np.random.default_rng(20261201)

EXACT = 1e-12
"""Relative to the quantity's size: what double-precision evaluation of a cubic leaves."""

BOUND_SLACK = 1.0 + 1e-6
"""The measured error may exceed the derived bound by round-off only."""


def test_the_position_hermite_is_exact_for_a_constant_acceleration():
    for _ in range(20):
        x0, v0, a = RNG.normal(size=(3, 3))
        t0, h = RNG.uniform(0, 10), RNG.uniform(1e-4, 1e-1)
        t = np.array([t0, t0 + h])
        pos = np.stack([x0 + v0 * s + 0.5 * a * s**2 for s in (0.0, h)])
        vel = np.stack([v0 + a * s for s in (0.0, h)])
        tau = RNG.uniform(0, h)
        truth = x0 + v0 * tau + 0.5 * a * tau**2
        got = hermite_position(t0 + tau, t, pos, vel)
        assert np.abs(got - truth).max() <= EXACT * (1 + np.abs(truth).max()), (got, truth)


@pytest.mark.parametrize("h", [1e-1, 3e-2, 1e-2])
def test_the_position_hermite_keeps_its_error_bound_on_a_sine(h):
    """x = A sin(ωt): |x⁗| <= A ω⁴, so the bound is h⁴ A ω⁴ / 384."""
    amplitude, omega = 0.3, 7.0
    t = np.array([0.2, 0.2 + h])
    pos = (amplitude * np.sin(omega * t))[:, None]
    vel = (amplitude * omega * np.cos(omega * t))[:, None]
    inner = np.linspace(t[0], t[1], 101)
    error = max(
        abs(hermite_position(x, t, pos, vel)[0] - amplitude * np.sin(omega * x)) for x in inner
    )
    bound = h**4 * amplitude * omega**4 / 384
    assert error <= bound * BOUND_SLACK, f"h {h}: error {error:.3g} > bound {bound:.3g}"
    assert error >= 0.1 * bound, f"h {h}: the bound {bound:.3g} is not tight ({error:.3g})"


def test_the_cubic_through_four_values_is_exact_for_a_cubic_and_keeps_its_bound():
    coefficients = RNG.normal(size=4)
    t = 5.0 + np.array([0.0, 1.0, 2.0, 3.0]) * 1e-3
    values = np.polyval(coefficients, t - 5.0)
    mid = 5.0 + 1.5e-3
    exact = np.polyval(coefficients, mid - 5.0)
    assert abs(cubic_through(mid, t, values) - exact) <= EXACT * (1 + abs(exact))
    h, omega = 2e-2, 5.0  # a cosine: |f⁗| <= ω⁴, bound 9 h⁴ ω⁴ / 384 at mid-step
    t = 1.0 + np.arange(4) * h
    error = abs(
        cubic_through(1.0 + 1.5 * h, t, np.cos(omega * t)) - np.cos(omega * (1.0 + 1.5 * h))
    )
    bound = 9 * h**4 * omega**4 / 384
    assert error <= bound * BOUND_SLACK, f"error {error:.3g} > bound {bound:.3g}"


def _quat(rotation: Rotation) -> np.ndarray:
    return rotation.as_quat(scalar_first=True)


def test_the_orientation_hermite_is_exact_for_a_constant_angular_velocity():
    for _ in range(20):
        omega = RNG.normal(size=3) * 10
        start = Rotation.random(random_state=RNG)
        h = RNG.uniform(1e-4, 5e-2)
        t = np.array([1.0, 1.0 + h])
        quats = np.stack([_quat(Rotation.from_rotvec(omega * s) * start) for s in (0.0, h)])
        tau = RNG.uniform(0, h)
        truth = _quat(Rotation.from_rotvec(omega * tau) * start)
        got = hermite_orientation(1.0 + tau, t, quats, np.stack([omega, omega]))
        assert rotation_angle(got, truth) <= EXACT * 100, rotation_angle(got, truth)


def test_the_orientation_hermite_converges_at_fourth_order_on_a_tumble():
    """A body whose ω turns at a constant rate: the mid-step error falls by 2⁴ or more per
    halving of the step (the error of a cubic through Hermite data)."""
    spin, turn = np.array([0.0, 0.0, 6.0]), np.array([1.5, 0.0, 0.0])

    def orientation(time: float) -> Rotation:  # ω(t) = R_turn(t) spin: rotation about a moving axis
        return Rotation.from_rotvec(turn * time) * Rotation.from_rotvec(spin * time)

    def angular_velocity(time: float) -> np.ndarray:
        return turn + Rotation.from_rotvec(turn * time).apply(spin)

    errors = []
    for h in (4e-2, 2e-2, 1e-2):
        t = np.array([0.3, 0.3 + h])
        quats = np.stack([_quat(orientation(x)) for x in t])
        rates = np.stack([angular_velocity(x) for x in t])
        mid = 0.3 + 0.5 * h
        errors.append(
            float(
                rotation_angle(hermite_orientation(mid, t, quats, rates), _quat(orientation(mid)))
            )
        )
    ratios = np.array(errors[:-1]) / np.array(errors[1:])
    assert (ratios >= 2**3.5).all(), f"mid-step errors {errors}: ratios {ratios}"


# --- on the library's RK4 scenes --------------------------------------------------------------

LIBRARY = Path(__file__).resolve().parent.parent / "scenarios"
RK4 = "mujoco(integrator=RK4)"
RK4_SCENES = [
    "formulas/projectile.yaml",
    "stiff/stiff_spring_chain.yaml",
    "rotation/torque_free_symmetric_top.yaml",
    "rotation/dzhanibekov_flip_times.yaml",
]
"""Library scenes that list MuJoCo RK4 and where nothing can touch (so the DOP853 reference
holds between steps): constant gravity, a stiff spring chain, a precession, a tumble."""

ADDED_FRACTION = 0.05
"""The interpolant may add at most 5 % of the engine's own largest error at the observed steps
(plus round-off): "far below the engines'" made a number. Measured at 200 mid-steps: the
projectile 3.46e-13 m between steps as at the steps (a linear interpolation: 1.23e-6 m); the
precession 7.4e-11 rad as at the steps (the nearer step: 5.0e-3 rad); the Dzhanibekov tumble
1.92e-7 rad as at the steps (nearer step: 1.1e-2 rad); the spring chain 5.86e-5 m against
5.99e-5 m at the steps."""


@pytest.mark.slow
@pytest.mark.parametrize("path", RK4_SCENES)
def test_between_steps_rk4_reads_no_more_error_than_at_its_steps(path):
    scene = compile_scene(load_scenario(LIBRARY / path))
    adapter = create_adapter(parse_engine_spec(RK4))
    adapter.load(scene)
    try:
        states = record(adapter, scene, sample_every=1).trajectory
    finally:
        adapter.close()
    t = states.t
    mid = 0.5 * (t[:-1] + t[1:])
    reference = reference_motion(scene, np.sort(np.concatenate([t, mid])))
    steps, mids = slice(0, None, 2), slice(1, None, 2)  # the reference at the steps, between them
    at_steps_pos, at_mid_pos = reference.pos[steps], reference.pos[mids]
    at_steps_quat, at_mid_quat = reference.quat[steps], reference.quat[mids]
    for body in range(scene.count):
        own = np.linalg.norm(states.pos[:, body] - at_steps_pos[:, body], axis=1).max()
        own_angle = rotation_angle(states.quat[:, body], at_steps_quat[:, body]).max()
        picks = np.linspace(0, mid.size - 1, 200).astype(int)  # 200 mid-steps over the run
        read = max(
            np.linalg.norm(
                hermite_position(
                    mid[k], t[k : k + 2], states.pos[k : k + 2, body], states.vel[k : k + 2, body]
                )
                - at_mid_pos[k, body]
            )
            for k in picks
        )
        read_angle = max(
            rotation_angle(
                hermite_orientation(
                    mid[k],
                    t[k : k + 2],
                    states.quat[k : k + 2, body],
                    states.ang_vel[k : k + 2, body],
                ),
                at_mid_quat[k, body],
            )
            for k in picks
        )
        assert read <= own * (1 + ADDED_FRACTION) + 1e-12, (
            f"{path} body {body}: {read:.3g} m between steps, {own:.3g} m at the steps"
        )
        assert read_angle <= own_angle * (1 + ADDED_FRACTION) + 1e-12, (
            f"{path} body {body}: {read_angle:.3g} rad between steps, {own_angle:.3g} at the steps"
        )


def test_the_interpolants_give_the_same_bits_every_time():
    """The same observed states give the same value to the last bit, call after call (SciPy's
    BarycentricInterpolator permutes its nodes at random: the library's mid-step velocities
    moved by an ulp from run to run; it varied on 105 of 200 inputs like these)."""
    rng = np.random.default_rng(1)
    for _ in range(50):
        t = rng.uniform(0, 10) + np.arange(4) * 1e-3
        values = rng.normal(size=(4, 3))
        first = cubic_through(t[1] + 0.37e-3, t, values)
        for _ in range(10):
            assert cubic_through(t[1] + 0.37e-3, t, values).tobytes() == first.tobytes(), t
