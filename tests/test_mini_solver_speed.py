"""The contact solver's reuse of work from step to step changes no result.

The contact graph (colouring, index work, pair values) is reused while the contacts join
the same bodies in the same order, and the rows of a constraint direction while the
direction, the arms and the inverse inertias are bit for bit the last step's (and the 2x2
tangent block of the friction rows while both tangents' rows are kept). Both must
give exactly what computing everything afresh every step gives, and the reuse must happen
where it should (a body at rest) and not where it must not (a body turning in place).
"""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from mini_engine import Body, Plane, Settings, Sphere, build_model, solver, step
from mini_engine.shapes import Box
from mini_engine.workspace import workspace

SETTINGS = Settings(dt=1e-3)


def _spinning_box():
    """A 10 cm box on the ground turning about the vertical at 3 rad/s, with friction: the
    contact normals stay the plane's while the arms turn with the box."""
    return build_model(
        [
            Body(Plane(), fixed=True, friction=0.3),
            Body(
                Box((0.05, 0.05, 0.05)),
                mass=1.0,
                position=(0.0, 0.0, 0.05),
                angular_velocity=(0.0, 0.0, 3.0),
                friction=0.3,
            ),
        ]
    )


def _resting_sphere():
    return build_model([Body(Plane(), fixed=True), Body(Sphere(0.05), position=(0, 0, 0.05))])


def _trace(model, state, steps, fresh):
    trace = []
    for _ in range(steps):
        if fresh:  # forget everything derived from the model, the solver's caches included
            model.forget_derived()
        state, report = step(model, state, SETTINGS)
        trace.append(
            np.concatenate(
                [
                    state.pos.ravel(),
                    state.quat.ravel(),
                    state.vel.ravel(),
                    state.ang_vel.ravel(),
                    report.normal_impulse,
                    report.friction_impulse.ravel(),
                    report.normal_velocity_after,
                ]
            )
        )
    return trace


def _normal_rows(model):
    return workspace(model).solver_rows["normal"]["rows"]


def test_reused_graph_and_rows_change_nothing_for_a_box_turning_on_the_ground():
    model, state = _spinning_box()
    kept = _trace(model, state, 200, fresh=False)
    fresh = _trace(model, state, 200, fresh=True)
    assert all(np.array_equal(a, b) for a, b in zip(kept, fresh, strict=True))


def test_rows_of_a_sphere_at_rest_are_reused():
    model, state = _resting_sphere()
    for _ in range(3):
        state, _ = step(model, state, SETTINGS)
    rows = _normal_rows(model)
    state, report = step(model, state, SETTINGS)
    assert _normal_rows(model) is rows
    assert report.normal_velocity_after[0] == 0.0


def test_rows_are_rebuilt_while_the_body_turns_under_fixed_normals():
    model, state = _spinning_box()
    for _ in range(3):
        state, _ = step(model, state, SETTINGS)
    rows = _normal_rows(model)
    state, _ = step(model, state, SETTINGS)
    assert _normal_rows(model) is not rows


def _resting_ball_with_friction():
    """A ball at rest on the ground with μ = 0.4: its contact, arms and inertia are the same
    bit for bit every step, so its tangent rows and block can be kept. (A resting box is not
    still to the bit: its corners leave it turning at ~1e-14 rad/s, so its rows are rebuilt.)"""
    return build_model(
        [
            Body(Plane(), fixed=True, friction=0.4),
            Body(Sphere(0.05), position=(0.0, 0.0, 0.05), friction=0.4),
        ]
    )


def _tangent_block(model):
    return workspace(model).solver_rows["tangent block"]["block"]


def test_the_tangent_block_of_a_resting_ball_is_reused_and_changes_nothing():
    model, state = _resting_ball_with_friction()
    kept = _trace(model, state, 200, fresh=False)
    fresh = _trace(model, state, 200, fresh=True)
    assert all(np.array_equal(a, b) for a, b in zip(kept, fresh, strict=True))
    model, state = _resting_ball_with_friction()
    for _ in range(3):
        state, _ = step(model, state, SETTINGS)
    block = _tangent_block(model)
    state, _ = step(model, state, SETTINGS)
    assert _tangent_block(model) is block


def test_the_tangent_block_is_rebuilt_while_the_box_turns():
    model, state = _spinning_box()
    for _ in range(3):
        state, _ = step(model, state, SETTINGS)
    block = _tangent_block(model)
    state, _ = step(model, state, SETTINGS)
    assert _tangent_block(model) is not block


def _bouncing_sphere():
    """A sphere (e = 0.8) thrown down and sideways at the ground: first impacts, bounces,
    then warm-started resting contact."""
    return build_model(
        [
            Body(Plane(), fixed=True, restitution=0.8),
            Body(
                Sphere(0.05),
                position=(0.0, 0.0, 0.2),
                velocity=(0.3, 0.0, -2.0),
                angular_velocity=(0.0, 4.0, 0.0),
                restitution=0.8,
            ),
        ]
    )


@pytest.mark.parametrize("scene", [_resting_sphere, _bouncing_sphere])
def test_gathered_single_contact_solve_matches_the_colour_by_colour_solve(scene, monkeypatch):
    """A single frictionless contact is solved on its gathered twists (``gathered``); the
    colour-by-colour solve, forced, gives the same bits step after step."""
    model, state = scene()
    gathered = _trace(model, state, 400, fresh=False)
    assert workspace(model).colour_cache["graph"].gathered

    build = solver._build_contact_graph
    monkeypatch.setattr(
        solver,
        "_build_contact_graph",
        lambda *args: dataclasses.replace(build(*args), gathered=False),
    )
    model, state = scene()
    coloured = _trace(model, state, 400, fresh=False)
    assert not workspace(model).colour_cache["graph"].gathered
    assert all(np.array_equal(a, b) for a, b in zip(gathered, coloured, strict=True))


def _colours_with_used_rows(row_a, row_b, static_row):
    """The colouring as first formulated (a ``used`` array of rows per colour), kept as the
    reference the faster ``colour_contacts`` must match contact for contact."""
    count = row_a.size
    private = static_row + np.arange(count)
    pair_rows = np.stack(
        [
            np.where(row_a == static_row, private, row_a),
            np.where(row_b == static_row, private, row_b),
        ],
        axis=1,
    )
    colour = np.full(count, -1, dtype=np.int64)
    claim = np.empty(static_row + count, dtype=np.int64)
    remaining = solver._lowest_priority_first(count).copy()
    current = 0
    while remaining.size:
        used = np.zeros(static_row + count, dtype=bool)
        candidates = remaining
        for _ in range(solver.COLOUR_ROUNDS):
            if not candidates.size:
                break
            rows = pair_rows.take(candidates, axis=0)
            claim[rows.ravel()] = np.repeat(candidates, 2)
            wins = (claim[rows[:, 0]] == candidates) & (claim[rows[:, 1]] == candidates)
            colour[candidates[wins]] = current
            used[rows[wins].ravel()] = True
            rows = rows[~wins]
            candidates = candidates[~wins][~(used[rows[:, 0]] | used[rows[:, 1]])]
        remaining = remaining[colour[remaining] < 0]
        current += 1
    return colour


def test_colouring_matches_its_first_formulation_on_random_graphs():
    rng = np.random.default_rng(7)
    for _ in range(100):
        bodies = int(rng.integers(2, 200))
        count = int(rng.integers(1, 1200))
        row_a = rng.integers(0, bodies + 1, count)  # row ``bodies`` is the static row
        row_b = rng.integers(0, bodies + 1, count)
        row_b = np.where(row_a == row_b, (row_b + 1) % (bodies + 1), row_b)
        assert np.array_equal(
            solver.colour_contacts(row_a, row_b, bodies),
            _colours_with_used_rows(row_a, row_b, bodies),
        )
