"""The shortcuts of the per-step work (mini_engine) give exactly what the long way gives.

Each shortcut skips or reorganises work on the promise of the same result bit for bit:
sphere rotations are not gathered for the narrow phase, principal-axis inertia is applied
as (g, 3) products, short sums are whole-array additions, the broad phase skips the
admissible test for pairs it knows admissible, the pose update masks the fixed bodies, and
per-model results live in the model (and stay out of its pickles).
"""

from __future__ import annotations

import pickle

import numpy as np
import pytest
from random_scenes import random_spring_scene

from mini_engine import Body, Plane, Settings, Sphere, build_model, forces, rotation, step
from mini_engine.broadphase import _grid_pairs, broadphase_plan, candidate_pairs
from mini_engine.collision import detect_contacts
from mini_engine.integrate import GYROSCOPIC_RULES, BodyInertia, body_inertia
from mini_engine.model import PER_MODEL_PREFIX, State
from mini_engine.narrowphase import NARROW_PHASE
from mini_engine.rotation import last_axis_sum, quat_to_matrix, rotation_quat
from mini_engine.scenes import sphere_pile, tumbling_box
from mini_engine.shapes import Box, ShapeType

PAIRS = 200
"""Random configurations per shape pair: enough to reach every branch of the sphere tests."""

DT = 0.37
"""s. A long, irregular step (with irregular boxes below): the gyroscopic increment is then
as large as ω itself, so any reordering of its products shows in the last bits of ω."""


def _random_rotations(rng: np.random.Generator, k: int) -> np.ndarray:
    return quat_to_matrix(rotation_quat(rng.normal(size=(k, 3))))


def _sizes(shape: ShapeType, rng: np.random.Generator, k: int) -> np.ndarray:
    """``body_size`` rows: radius for spheres, (radius, half length) for capsules, half
    extents for boxes, nothing for planes."""
    size = rng.uniform(0.05, 0.3, size=(k, 3))
    if shape == ShapeType.CAPSULE:
        size[:, 2] = 0.0
    return size


@pytest.mark.parametrize("key", [key for key in NARROW_PHASE if ShapeType.SPHERE in key])
def test_sphere_contacts_do_not_depend_on_the_sphere_rotation(key):
    """Why collision.SPHERE_ROTATIONS may hand spheres identities instead of their rotations."""
    rng = np.random.default_rng(14)
    shape_a, shape_b = key
    pos_a = rng.uniform(-0.3, 0.3, size=(PAIRS, 3))
    pos_b = pos_a + rng.uniform(-0.3, 0.3, size=(PAIRS, 3))
    pos_b[::10] = pos_a[::10]  # coincident centres: the fallback directions
    rot_a, rot_b = _random_rotations(rng, PAIRS), _random_rotations(rng, PAIRS)
    size_a, size_b = _sizes(shape_a, rng, PAIRS), _sizes(shape_b, rng, PAIRS)
    identity = np.broadcast_to(np.eye(3), (PAIRS, 3, 3))
    collide = NARROW_PHASE[key]
    turned = collide(pos_a, rot_a, size_a, pos_b, rot_b, size_b, 0.01)
    unturned = collide(
        pos_a,
        identity if shape_a == ShapeType.SPHERE else rot_a,
        size_a,
        pos_b,
        identity if shape_b == ShapeType.SPHERE else rot_b,
        size_b,
        0.01,
    )
    assert turned.pair.size > 0
    for got, expected in zip(unturned, turned, strict=True):
        assert got.tobytes() == expected.tobytes()


def test_principal_axis_inertia_gives_the_tensor_rule_bit_for_bit():
    rng = np.random.default_rng(7)
    boxes = [
        Body(Box(tuple(rng.uniform(0.05, 0.5, 3))), mass=rng.uniform(1, 10)) for _ in range(50)
    ]
    model, _ = build_model(boxes)
    bodies = model.gyroscopic_bodies
    principal = body_inertia(model.body_inertia, model.body_inv_inertia, bodies)
    assert principal.diagonal is not None, "solid boxes have principal body axes"
    tensor_only = BodyInertia(principal.tensor, principal.inv_tensor, None, None)
    rot = _random_rotations(rng, model.n_bodies)
    ang_vel = rng.normal(scale=5.0, size=(model.n_bodies, 3))
    ang_vel[0, 1:] = 0.0  # spinning about one axis: the zero components
    fast, slow = ang_vel.copy(), ang_vel.copy()
    GYROSCOPIC_RULES["explicit"](fast, rot, principal, bodies, DT)
    GYROSCOPIC_RULES["explicit"](slow, rot, tensor_only, bodies, DT)
    assert not np.array_equal(fast, ang_vel)
    assert fast.tobytes() == slow.tobytes()


def test_off_diagonal_inertia_keeps_the_tensor_path():
    model, _ = build_model(
        [Body(Sphere(0.1), inertia=[[1.0, 0.1, 0.0], [0.1, 2.0, 0.0], [0.0, 0.0, 3.0]])]
    )
    inertia = body_inertia(model.body_inertia, model.body_inv_inertia, model.gyroscopic_bodies)
    assert inertia.diagonal is None and inertia.inv_diagonal is None


@pytest.mark.parametrize("shape", [(1, 3), (5, 3), (3000, 3), (64, 4), (10, 8, 3)])
def test_last_axis_sum_is_numpy_sum_bit_for_bit(shape):
    rng = np.random.default_rng(3)
    values = rng.normal(size=shape) * rng.choice([1.0, 1e-9, 1e9, 0.0, -0.0], size=shape)
    values[0] = -0.0  # all negative zeros: the sum starts from +0
    assert last_axis_sum(values).tobytes() == values.sum(axis=-1).tobytes()


def _awkward_quaternions(rng: np.random.Generator, rows: int) -> np.ndarray:
    """``rows`` quaternions w x y z: random ones, unnormalised ones, and in larger batches
    signed zeros in every place (a -0.0 entry must stay -0.0)."""
    quat = rng.normal(size=(rows, 4))
    quat[: rows // 2] /= np.linalg.norm(quat[: rows // 2], axis=1, keepdims=True)
    signed_zeros = np.array([[1.0, 0.0, 0.0, 0.0], [1.0, -0.0, 0.0, -0.0], [-0.0, 1.0, -0.0, 0.0]])
    if rows > 2 * len(signed_zeros):  # small batches stay random (a zero row hides a change)
        quat[: len(signed_zeros)] = signed_zeros
    quat[3::5, 1:3] = -0.0
    return quat


@pytest.mark.parametrize("rows", [1, 3, 32, 33, 64, 65, 300])
def test_small_batches_from_the_product_table_are_the_formulas_bit_for_bit(rows, monkeypatch):
    """Why rotation.QUAT_PRODUCT_ROWS and CROSS_TABLE_ROWS may switch small batches to the
    table of products: matrices, Hamilton products and cross products equal the written-out
    formulas' in every bit (signed zeros included), on either side of the switch."""
    rng = np.random.default_rng(rows)
    quat, other = _awkward_quaternions(rng, rows), _awkward_quaternions(rng, rows)[::-1].copy()

    def results() -> dict[str, np.ndarray]:
        return {
            "matrix": quat_to_matrix(quat),
            "product": rotation.quat_multiply(quat, other),
            "cross": rotation.cross(quat[:, 1:], other[:, :3]),
        }

    table = results()
    monkeypatch.setattr(rotation, "QUAT_PRODUCT_ROWS", -1)  # the written-out formulas only
    monkeypatch.setattr(rotation, "CROSS_TABLE_ROWS", -1)
    for name, slow in results().items():
        differing = int(np.count_nonzero(table[name].view(np.uint64) != slow.view(np.uint64)))
        assert differing == 0, f"{rows} rows: {differing} {name} entries differ in their bits"


SPRING_SEEDS = (20, 22, 67, 5, 3)
"""``random_spring_scene`` seeds that take each shortcut and each long way: every end distinct
and no world end or fixed body (20); ends shared at A and B (22); shared at B only, a fixed
body (67); shared at A and B with a world end and a fixed body (5); distinct with both (3)."""


@pytest.mark.parametrize("seed", SPRING_SEEDS)
def test_spring_forces_of_distinct_ends_are_the_accumulated_forces_bit_for_bit(seed, monkeypatch):
    """Why forces.SpringEnds may skip ``np.add.at`` for springs whose ends share no body, the
    world masks without world ends and the zeroing without fixed bodies: the same forces and
    torques, bit for bit, as the long way (add.at, masks and zeroing always)."""
    model, state, _ = random_spring_scene(seed)
    rot = quat_to_matrix(state.quat)
    short = forces.spring_forces(model, state, rot)
    long_way = forces.spring_ends(model)._replace(
        any_to_world=True, distinct_a=False, distinct_b=False, any_fixed=True
    )
    monkeypatch.setattr(forces, "spring_ends", lambda _model: long_way)
    for name, fast, slow in zip(
        ("force", "torque"), short, forces.spring_forces(model, state, rot), strict=True
    ):
        differing = int(np.count_nonzero(fast.view(np.uint64) != slow.view(np.uint64)))
        assert differing == 0, f"seed {seed}: {differing} {name} entries differ in their bits"


def test_fixed_bodies_touching_each_other_are_never_candidates():
    """The grid skips the admissible test only when no small body is fixed."""
    bodies = [
        Body(Sphere(0.1), fixed=True, position=(0.0, 0.0, 0.0)),
        Body(Sphere(0.1), fixed=True, position=(0.15, 0.0, 0.0)),
        Body(Sphere(0.1), position=(0.075, 0.1, 0.0)),
    ]
    model, state = build_model(bodies)
    a, b = candidate_pairs(model, state.pos, quat_to_matrix(state.quat), 0.0)
    assert set(zip(a.tolist(), b.tolist(), strict=True)) == {(0, 2), (1, 2)}


def test_fixed_bodies_keep_their_pose_whatever_velocity_a_state_gives_them():
    model, state = build_model(
        [Body(Plane(), fixed=True), Body(Sphere(0.05), position=(0.0, 0.0, 1.0))]
    )
    vel, ang_vel = state.vel.copy(), state.ang_vel.copy()
    vel[0], ang_vel[0] = (1.0, 2.0, 3.0), (0.5, 0.0, 0.0)
    ang_vel[1] = (0.0, 0.0, 1.0)
    moved = step(model, State(state.pos, state.quat, vel, ang_vel), Settings(dt=1e-2)).state
    assert moved.pos[0].tobytes() == state.pos[0].tobytes()
    assert moved.quat[0].tobytes() == state.quat[0].tobytes()
    assert not np.array_equal(moved.pos[1], state.pos[1])
    assert not np.array_equal(moved.quat[1], state.quat[1])


def test_a_pickled_model_leaves_its_per_model_results_behind_and_steps_alike():
    model, state = tumbling_box(3)
    settings = Settings(dt=1e-3, gyroscopic="explicit")
    after = step(model, state, settings).state
    assert any(key.startswith(PER_MODEL_PREFIX) for key in vars(model))
    copy = pickle.loads(pickle.dumps(model))
    assert not any(key.startswith(PER_MODEL_PREFIX) for key in vars(copy))
    again = step(copy, state, settings).state
    for got, expected in zip(
        (again.pos, again.quat, again.vel, again.ang_vel),
        (after.pos, after.quat, after.vel, after.ang_vel),
        strict=True,
    ):
        assert got.tobytes() == expected.tobytes()


def test_contacts_are_reused_only_while_the_poses_are_unchanged():
    """A resting sphere keeps its pose bit for bit: its contacts are the last step's
    (read-only); a moved pose or another margin detects them again, as the long way does."""
    model, state = build_model(
        [Body(Plane(), fixed=True), Body(Sphere(0.05), position=(0.0, 0.0, 0.05))]
    )
    settings = Settings(dt=2e-3)
    for _ in range(50):
        state = step(model, state, settings).state
    first = step(model, state, settings).contacts.contacts
    again = step(model, state, settings).contacts.contacts
    assert again.body_a is first.body_a and not again.depth.flags.writeable
    lifted = State(state.pos + np.array([0.0, 0.0, 1e-4]), state.quat, state.vel, state.ang_vel)
    rot = quat_to_matrix(lifted.quat)
    margins = settings.contact_margin, settings.broadphase_padding
    expected = detect_contacts(model, lifted.pos, rot, *margins)
    moved = step(model, lifted, settings).contacts.contacts
    assert moved.depth.tobytes() == expected.depth.tobytes()
    wider = step(model, state, Settings(dt=2e-3, contact_margin=0.01)).contacts.contacts
    assert wider.depth is not first.depth


def test_grid_pairs_of_kept_cells_are_the_pairs_found_afresh():
    """A settling pile's small bodies mostly keep their cells: the cached grid pairs are then
    those a fresh grid finds, and a changed cell finds them again."""
    model, state = sphere_pile(200)
    settings = Settings(dt=2e-3)
    plan = broadphase_plan(model)
    reused = 0
    for _ in range(300):
        state = step(model, state, settings).state
        centre = state.pos.take(plan.small, axis=0)
        radius = plan.small_radius + settings.contact_margin + settings.broadphase_padding
        last = plan.grid_cache.get("pairs")
        kept = _grid_pairs(centre, radius, plan.small, plan.small_world, plan.grid_cache)
        fresh = _grid_pairs(centre, radius, plan.small, plan.small_world, {})
        reused += kept is last
        assert [kept[0].tobytes(), kept[1].tobytes()] == [fresh[0].tobytes(), fresh[1].tobytes()]
    assert 0 < reused < 300


@pytest.mark.parametrize("spread", [1.0, 40.0], ids=["packed_table", "spread_search"])
def test_grid_pairs_by_table_or_search_are_the_pairs_of_neighbouring_cells(spread, monkeypatch):
    """The cell-start table (a packed grid) and the binary search (a grid with more than
    CELL_TABLE_CELLS_PER_BODY cells a body) find, in the same order, the pairs whose cells are
    within one of each other, and each of those pairs once."""
    rng = np.random.default_rng(7)
    count = 300
    centre = rng.uniform(0.0, spread, (count, 3)) * np.array([1.0, 1.0, 0.2])
    radius = np.full(count, 0.1)
    body, world = np.arange(count), np.zeros(count, np.int64)
    found = _grid_pairs(centre, radius, body, world, {})
    cell = np.floor((centre - centre.min(axis=0)) / 0.2).astype(np.int64)
    first, second = np.triu_indices(count, k=1)
    near = np.abs(cell[first] - cell[second]).max(axis=1) <= 1
    want = {(int(a), int(b)) for a, b in zip(first[near], second[near], strict=True)}
    got = [tuple(sorted((int(a), int(b)))) for a, b in zip(*found, strict=True)]
    assert len(got) == len(set(got)), f"{len(got) - len(set(got))} pairs found twice"
    assert set(got) == want, f"{len(want - set(got))} missed, {len(set(got) - want)} extra"
    other_path = 10**9 if spread > 1.0 else 0  # force the table, or the search
    monkeypatch.setattr("mini_engine.broadphase.CELL_TABLE_CELLS_PER_BODY", other_path)
    again = _grid_pairs(centre, radius, body, world, {})
    assert [a.tobytes() for a in again] == [a.tobytes() for a in found]


def test_integer_quaternions_take_the_product_table_as_the_formulas_do(monkeypatch):
    """An integer array (a quaternion written [1, 0, 0, 0]) gives the written-out formulas'
    float matrices and cross products on the table's path too, not a casting error."""
    quat = np.array([[1, 0, 0, 0], [0, 1, 0, 0], [0, 0, 0, -1]])
    table = (quat_to_matrix(quat), rotation.cross(quat[:, 1:], quat[:, :3]))
    monkeypatch.setattr(rotation, "QUAT_PRODUCT_ROWS", -1)
    monkeypatch.setattr(rotation, "CROSS_TABLE_ROWS", -1)
    formulas = (quat_to_matrix(quat), rotation.cross(quat[:, 1:], quat[:, :3]))
    for fast, slow in zip(table, formulas, strict=True):
        assert fast.dtype == slow.dtype == np.float64 and np.array_equal(fast, slow), (fast, slow)
