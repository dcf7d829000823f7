"""Contact scenes in mini_engine: broad phase, colouring, resting, stacking, piles, worlds."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from mini_engine import (
    SHARED_WORLD,
    Body,
    Box,
    Capsule,
    Plane,
    Settings,
    Sphere,
    build_model,
    replicate,
    step,
)
from mini_engine.broadphase import candidate_pairs
from mini_engine.quantities import kinetic_energy, potential_energy
from mini_engine.rotation import quat_to_matrix
from mini_engine.scenes import sphere_pile
from mini_engine.solver import colour_contacts

# --- broad phase --------------------------------------------------------------------------


def brute_force_pairs(model, pos):
    """All pairs whose bounding spheres overlap (or plane within reach), the slow obvious way."""
    found = set()
    rot = quat_to_matrix(np.tile([1.0, 0, 0, 0], (model.n_bodies, 1)))
    for a in range(model.n_bodies):
        for b in range(a + 1, model.n_bodies):
            if model.body_fixed[a] and model.body_fixed[b]:
                continue
            planes = [i for i in (a, b) if model.body_shape[i] == 0]
            if planes:
                p, o = (a, b) if planes[0] == a else (b, a)
                height = (pos[o] - pos[p]) @ rot[p][:, 2]
                if height <= model.body_bound_radius[o]:
                    found.add((a, b))
            elif np.linalg.norm(pos[a] - pos[b]) <= model.body_bound_radius[[a, b]].sum():
                found.add((a, b))
    return found


@settings(max_examples=40, deadline=None)
@given(
    seed=st.integers(0, 2**31 - 1),
    count=st.integers(2, 60),
    spread=st.floats(0.2, 3.0),
    big=st.booleans(),
)
def test_broad_phase_finds_exactly_the_overlapping_bounding_spheres(seed, count, spread, big):
    rng = np.random.default_rng(seed)
    bodies = [Body(Plane(), fixed=True)]
    for i in range(count):
        radius = 2.0 if (big and i == 0) else rng.uniform(0.05, 0.2)
        bodies.append(Body(Sphere(radius), position=rng.uniform(-spread, spread, 3)))
    model, state = build_model(bodies)
    a, b = candidate_pairs(model, state.pos, quat_to_matrix(state.quat), 0.0)
    found = set(zip(a.tolist(), b.tolist(), strict=True))
    assert len(found) == a.size, "a pair was reported twice"
    expected = brute_force_pairs(model, state.pos)
    assert found == expected, f"missing {expected - found}, extra {found - expected}"


def test_bodies_in_different_worlds_are_never_paired():
    bodies = [Body(Plane(), fixed=True, world=SHARED_WORLD)]
    bodies += [Body(Sphere(0.1), position=(0, 0, 0.05), world=w) for w in range(3)]
    model, state = build_model(bodies)
    a, b = candidate_pairs(model, state.pos, quat_to_matrix(state.quat), 0.0)
    pairs = set(zip(a.tolist(), b.tolist(), strict=True))
    assert pairs == {(0, 1), (0, 2), (0, 3)}, f"pairs {pairs}"


@settings(max_examples=50, deadline=None)
@given(seed=st.integers(0, 2**31 - 1), bodies=st.integers(2, 40), contacts=st.integers(1, 200))
def test_colouring_never_puts_two_contacts_of_one_body_in_one_colour(seed, bodies, contacts):
    rng = np.random.default_rng(seed)
    static_row = bodies
    row_a = rng.integers(0, bodies + 1, contacts)
    row_b = rng.integers(0, bodies, contacts)
    row_b = np.where(row_b == row_a, static_row, row_b)
    colour = colour_contacts(row_a, row_b, static_row)
    assert (colour >= 0).all()
    for c in np.unique(colour):
        members = np.flatnonzero(colour == c)
        touched = np.concatenate([row_a[members], row_b[members]])
        touched = touched[touched != static_row]
        assert np.unique(touched).size == touched.size, f"colour {c} shares a body"


# --- resting and stacking -----------------------------------------------------------------

SINK_LIMIT = Settings().penetration_slop
"""m. A resting body may not sink deeper than the slop the position correction allows (1 mm);
with no correction at all it must not sink past it either."""

ENERGY_GAIN_LIMIT = 1e-9
"""J. A resting 2 kg box may lose energy to the contact but must not gain any beyond
round-off of 10,000 energy evaluations near 2 J."""


@pytest.mark.parametrize("correction", ["none", "baumgarte", "split_impulse"])
def test_box_resting_on_plane_for_10_s_neither_sinks_nor_gains_energy(correction):
    half = 0.1
    model, state = build_model(
        [Body(Plane(), fixed=True), Body(Box((0.2, 0.15, half)), mass=2.0, position=(0, 0, half))]
    )
    cfg = Settings(dt=1e-3, position_correction=correction)
    energy0 = kinetic_energy(model, state)[0] + potential_energy(model, state)[0]
    lowest, gain = np.inf, -np.inf
    for _ in range(10_000):
        state, _ = step(model, state, cfg)
        lowest = min(lowest, state.pos[1, 2])
        energy = kinetic_energy(model, state)[0] + potential_energy(model, state)[0]
        gain = max(gain, energy - energy0)
    assert half - lowest < SINK_LIMIT, f"{correction}: sank {half - lowest:.3e} m"
    assert gain < ENERGY_GAIN_LIMIT, f"{correction}: gained {gain:.3e} J"


STACK_DRIFT = 0.01
"""m. Frictionless boxes of half-size 0.1 m: a sideways drift of 10 % of the half-width
over 5 s still counts as standing; a collapse moves them by metres."""


@pytest.mark.parametrize("friction", [0.0, 0.5])
def test_stack_of_five_boxes_stays_up_for_5_s(friction):
    bodies = [Body(Plane(), fixed=True, friction=friction)]
    bodies += [
        Body(Box((0.1, 0.1, 0.1)), position=(0, 0, 0.1 + 0.2 * k), friction=friction)
        for k in range(5)
    ]
    model, state = build_model(bodies)
    cfg = Settings(dt=1e-3)
    for _ in range(5000):
        state, _ = step(model, state, cfg)
    sink = (0.1 + 0.2 * np.arange(5)) - state.pos[1:, 2]
    drift = np.abs(state.pos[1:, :2]).max()
    assert sink.max() < SINK_LIMIT, f"boxes sank by {sink} m"
    assert drift < STACK_DRIFT, f"boxes drifted {drift:.4f} m sideways"


@pytest.mark.parametrize("correction", ["none", "split_impulse"])
def test_capsule_dropped_on_its_side_comes_to_rest_on_the_ground(correction):
    """Without position correction the capsule keeps the overlap of its impact step (at most
    the impact speed times dt); split impulse removes it down to the slop."""
    drop, dt = 0.25, 1e-3
    model, state = build_model(
        [
            Body(Plane(), fixed=True),
            Body(
                Capsule(0.05, 0.2),
                position=(0, 0, 0.05 + drop),
                orientation=(0.7071068, 0.7071068, 0, 0),
            ),
        ]
    )
    for _ in range(2000):
        state, _ = step(model, state, Settings(dt=dt, position_correction=correction))
    allowed = SINK_LIMIT if correction == "split_impulse" else np.sqrt(2 * 9.81 * drop) * dt
    sink = 0.05 - state.pos[1, 2]
    assert -1e-9 < sink < allowed, f"{correction}: sank {sink:.5f} m, allowed {allowed:.5f} m"
    assert np.abs(state.vel[1]).max() < 1e-6, f"still moving at {state.vel[1]} m/s"


# --- piles ---------------------------------------------------------------------------------


def walled_pile(count: int, radius: float = 0.05, width: float = 1.2, seed: int = 0):
    """``count`` spheres in layers of 100 above a ground plane inside four wall planes."""
    return sphere_pile(count, radius=radius, width=width, seed=seed)


PILE_OVERLAP = 0.025
"""m, half a sphere radius. Without position correction (the documented default) the overlap
of each impact stays and the pile's weight adds to it: measured 4.4 mm at the walls after
1.5 s. A sphere escaping the box (tunnelling) would overlap by a whole radius or more."""


@pytest.mark.slow
def test_thousand_spheres_poured_into_a_box_settle_without_non_finite_values():
    model, state = walled_pile(1000)
    cfg = Settings(dt=2e-3)
    for _ in range(750):
        state, report = step(model, state, cfg)
        assert state.is_finite(), f"non-finite state at t = {state.time:.3f} s"
    spheres = np.flatnonzero(model.body_dynamic)
    speed = np.linalg.norm(state.vel[spheres], axis=1).max()
    assert report.contacts.count > 1000, f"only {report.contacts.count} contacts"
    inside = np.abs(state.pos[spheres, :2]).max()
    assert inside <= 0.6 - 0.05 + PILE_OVERLAP, f"a sphere centre at {inside:.4f} m left the box"
    lowest = state.pos[spheres, 2].min()
    assert lowest > 0.05 - PILE_OVERLAP, f"lowest centre at {lowest:.4f} m"
    assert speed < 1.0, f"fastest sphere still at {speed:.3f} m/s after 1.5 s"


# --- worlds ---------------------------------------------------------------------------------


def test_replicated_worlds_evolve_exactly_like_one_world():
    """Copies in one model never touch and give bit-identical trajectories to a single copy:
    a tumbling box in flight (the Gazebo "complex" box, airborne for the 1.5 s) and a sphere
    bouncing on one ground plane shared by every world."""
    bodies = [
        Body(Plane(), fixed=True, world=SHARED_WORLD),
        Body(
            Box((0.05, 0.2, 0.45)),
            mass=10.0,
            position=(0, 0, 1.0),
            velocity=(-2, 2, 8),
            angular_velocity=(0.1, 5.0, 0.1),
            restitution=0.5,
        ),
        Body(Sphere(0.1), position=(2.0, 0, 0.5), restitution=0.9),
    ]
    model, state = build_model(bodies)
    many_model, many_state = replicate(model, state, 8)
    cfg = Settings(dt=1e-3, gyroscopic="implicit")
    for _ in range(1500):
        state, _ = step(model, state, cfg)
        many_state, _ = step(many_model, many_state, cfg)
    single = state.pos[1:]
    copies = many_state.pos[:-1].reshape(8, 2, 3)
    error = np.abs(copies - single[None]).max()
    assert error == 0.0, f"copies differ from the single world by {error:.3e} m"


# --- position correction and its energy -------------------------------------------------------

DEEP = 0.02
"""m. Initial penetration of the deep-penetration check: 20 times the slop."""


def deep_penetration_run(correction: str) -> tuple[float, float]:
    """A sphere started 2 cm into the ground, e = 0: (largest upward speed m/s, final depth m)."""
    model, state = build_model(
        [Body(Plane(), fixed=True), Body(Sphere(0.1), position=(0, 0, 0.1 - DEEP))]
    )
    cfg = Settings(dt=1e-3, position_correction=correction)
    fastest = 0.0
    for _ in range(1000):
        state, _ = step(model, state, cfg)
        fastest = max(fastest, state.vel[1, 2])
    return fastest, 0.1 - state.pos[1, 2]


def test_position_correction_energy_effects_are_as_documented():
    """none keeps the overlap and adds nothing; baumgarte pushes out through the velocity
    (kinetic energy is created); split impulse pushes out through the pose only."""
    none_speed, none_depth = deep_penetration_run("none")
    baumgarte_speed, baumgarte_depth = deep_penetration_run("baumgarte")
    split_speed, split_depth = deep_penetration_run("split_impulse")
    slop = Settings().penetration_slop
    assert none_speed == 0.0 and abs(none_depth - DEEP) < 1e-12, (none_speed, none_depth)
    assert baumgarte_speed > 0.1, f"baumgarte pushed out at only {baumgarte_speed:.4f} m/s"
    assert baumgarte_depth < slop, f"baumgarte left {baumgarte_depth:.4f} m of overlap"
    assert split_speed == 0.0, f"split impulse gave the sphere {split_speed:.3e} m/s"
    assert split_depth < slop * 1.01, f"split impulse left {split_depth:.4f} m of overlap"


def test_no_contact_work_when_nothing_can_touch(monkeypatch):
    """A lone body (or bodies in different worlds with no shared ground) skips collision."""
    import importlib

    step_module = importlib.import_module("mini_engine.step")  # the module, not the function

    def forbidden(*args, **kwargs):
        raise AssertionError("collision detection ran for a scene where nothing can touch")

    monkeypatch.setattr(step_module, "detect_contacts", forbidden)
    model, state = build_model(
        [
            Body(Sphere(0.1), world=0),
            Body(Sphere(0.1), world=1),
            Body(Box((1, 1, 1)), fixed=True, world=2),
        ]
    )
    assert not model.can_touch
    state, report = step(model, state, Settings())
    assert report.contacts.count == 0


FLAT_BOX_SPIN = 1e-8
"""rad/s. A box dropped flat has four identical corner contacts; the converged sequential
impulses leave no spin (measured 5e-11 after 10 sweeps). PyBullet gives 20-48 rad/s here
(engines.md 2.4), MuJoCo exactly 0."""

FLAT_BOX_RESTITUTION = 1e-9
"""Absolute error of the centre-of-mass rebound ratio (measured 2e-12)."""


@pytest.mark.parametrize("e", [0.5, 1.0])
def test_box_dropped_flat_bounces_with_requested_e_and_no_spin(e):
    model, state = build_model(
        [Body(Plane(), fixed=True), Body(Box((0.1, 0.1, 0.1)), position=(0, 0, 0.6), restitution=e)]
    )
    impacts = 0
    for _ in range(1000):
        state, report = step(model, state, Settings(dt=1e-3))
        if report.contacts.count and report.normal_velocity_before.min() < -0.5:
            impacts += 1
            assert report.contacts.count == 4, f"{report.contacts.count} contacts"
            ratio = -state.vel[1, 2] / report.normal_velocity_before.mean()
            spin = np.abs(state.ang_vel[1]).max()
            assert abs(ratio - e) < FLAT_BOX_RESTITUTION, f"rebound ratio {ratio:.12f}"
            assert spin < FLAT_BOX_SPIN, f"spurious spin {spin:.3e} rad/s"
    assert impacts >= 1, "the box never hit the ground"


def test_split_impulse_pushes_a_box_out_of_a_box_upright_and_at_rest():
    """A cube started 4 cm inside another (on the ground) ends on top, upright, not sliding:
    the pseudo-velocity solve must converge, or the corner order tilts the box."""
    model, state = build_model(
        [
            Body(Plane(), fixed=True),
            Body(Box((0.1, 0.1, 0.1)), position=(0, 0, 0.1)),
            Body(Box((0.1, 0.1, 0.1)), position=(0, 0, 0.26)),
        ]
    )
    cfg = Settings(dt=1e-3, position_correction="split_impulse")
    for _ in range(2000):
        state, _ = step(model, state, cfg)
    slop = cfg.penetration_slop
    assert abs(state.pos[2, 2] - 0.3) <= slop * 1.01, f"upper box at z = {state.pos[2, 2]:.5f} m"
    assert np.abs(state.pos[2, :2]).max() < 1e-4, f"slid to {state.pos[2, :2]} m"
    assert np.abs(state.vel[2]).max() < 1e-4, f"still moving at {state.vel[2]} m/s"


def test_broadphase_padding_never_makes_bodies_hover():
    """Padding only widens the broad phase; a resting sphere sits where it would without it."""
    heights = {}
    for padding in (0.0, 0.05):
        model, state = build_model(
            [Body(Plane(), fixed=True), Body(Sphere(0.1), position=(0, 0, 0.3))]
        )
        for _ in range(1000):
            state, _ = step(model, state, Settings(dt=1e-3, broadphase_padding=padding))
        heights[padding] = state.pos[1, 2]
    assert heights[0.05] == heights[0.0], heights
