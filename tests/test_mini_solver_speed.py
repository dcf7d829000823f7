"""The contact solver's reuse of work from step to step (issue 14) changes no result.

The contact graph (colouring, index work, pair values) is reused while the contacts join
the same bodies in the same order, and the rows of a constraint direction while the
direction, the arms and the inverse inertias are bit for bit the last step's. Both must
give exactly what computing everything afresh every step gives, and the reuse must happen
where it should (a body at rest) and not where it must not (a body turning in place).
"""

from __future__ import annotations

import numpy as np

from mini_engine import Body, Plane, Settings, Sphere, build_model, step
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
        if fresh:  # forget everything the solver keeps from the last step
            workspace(model).colour_cache.clear()
            workspace(model).solver_rows.clear()
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
