"""The per-model step workspace: its caches are optimisations only.

Reusing the colouring while the contact graph is unchanged, the rotation matrices while the
orientations are unchanged, and the broad phase's per-model plan must give bit-for-bit the
results of computing everything afresh every step.
"""

from __future__ import annotations

import numpy as np

from mini_engine import Body, Plane, Settings, Sphere, build_model, step
from mini_engine.scenes import sphere_pile, tumbling_box
from mini_engine.workspace import workspace


def _run(model, state, settings, steps, fresh):
    trace = []
    for _ in range(steps):
        if fresh:  # forget everything derived from the model, caches included
            model.forget_derived()
        state, report = step(model, state, settings)
        trace.append(
            np.concatenate(
                [state.pos.ravel(), state.quat.ravel(), state.vel.ravel(), report.normal_impulse]
            )
        )
    return trace


def test_cached_colouring_and_rotations_change_nothing():
    model, state = sphere_pile(100)
    settings = Settings(dt=2e-3)
    cached = _run(model, state, settings, 300, fresh=False)
    fresh = _run(model, state, settings, 300, fresh=True)
    assert all(np.array_equal(a, b) for a, b in zip(cached, fresh, strict=True))


def test_colouring_is_reused_while_the_contacts_stay_the_same():
    model, state = build_model(
        [Body(Plane(), fixed=True)]
        + [Body(Sphere(0.05), position=(0.2 * k, 0.0, 0.05)) for k in range(3)]
    )
    settings = Settings(dt=1e-3)
    for _ in range(3):
        state, _ = step(model, state, settings)
    batches = workspace(model).colour_cache["batches"]
    state, _ = step(model, state, settings)
    assert workspace(model).colour_cache["batches"] is batches


def test_rotations_are_rebuilt_when_bodies_turn_and_are_read_only():
    model, state = tumbling_box(2)
    settings = Settings(dt=1e-3)
    state, _ = step(model, state, settings)
    first = workspace(model).rotation_cache["rot"]
    assert not first.flags.writeable
    state, _ = step(model, state, settings)
    assert workspace(model).rotation_cache["rot"] is not first
