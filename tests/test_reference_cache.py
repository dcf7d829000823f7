"""The DOP853 reference is integrated once per scene and end time, and sampling it from its dense
output gives what integrating for those samples gives."""

from __future__ import annotations

import numpy as np
import pytest

from validation.reference import newton_euler
from validation.reference.newton_euler import reference_motion
from validation.scenario import Scenario
from validation.scenario.compiled import compile_scene, rotations, world_inertia

DURATION = 0.5
"""s: a few tenths of a flip of the tumbling box below, a fraction of a second to integrate."""

ENGINE_ENDS = (0.49999999999998613, 0.5, 0.50000000000012963)
"""s: where engines that add up dt end a 0.5 s run (their last sample), all one integration."""


def tumbling_box() -> Scenario:
    return Scenario.model_validate(
        {
            "name": "tumbling",
            "dt": 1e-3,
            "duration": DURATION,
            "gravity": [0.0, 0.0, -9.81],
            "bodies": [
                {
                    "name": "box",
                    "shape": {"type": "box", "half_extents": [0.3, 0.2, 0.1]},
                    "mass": 1.0,
                    "angular_velocity": [0.05, 10.0, 0.05],
                }
            ],
        }
    )


@pytest.fixture
def integrations(monkeypatch):
    """Counts the integrations reference_motion runs, from an empty cache."""
    monkeypatch.setattr(newton_euler, "_integrations", type(newton_euler._integrations)())
    ends: list[float] = []
    integrate = newton_euler._integrate

    def counted(scene, end, times):
        ends.append(end)
        return integrate(scene, end, times)

    monkeypatch.setattr(newton_euler, "_integrate", counted)
    return ends


def samples(end: float, dt: float) -> np.ndarray:
    return np.append(np.arange(0.0, end - dt / 2, dt), end)


def test_every_dt_and_engine_end_is_sampled_from_one_integration(integrations):
    scene = compile_scene(tumbling_box())
    for end in ENGINE_ENDS:
        for dt in (1e-3, 2e-4):
            reference_motion(scene, samples(end, dt))
    assert len(integrations) == 1, f"integrations to {integrations}"


def test_the_samples_do_not_depend_on_what_was_sampled_before(integrations, monkeypatch):
    scene = compile_scene(tumbling_box())
    coarse, fine = samples(0.5, 1e-3), samples(0.5, 2e-4)
    first = reference_motion(scene, coarse)
    reference_motion(scene, fine)
    monkeypatch.setattr(newton_euler, "_integrations", type(newton_euler._integrations)())
    reference_motion(scene, fine)
    again = reference_motion(scene, coarse)
    for field in ("pos", "quat", "vel", "ang_vel"):
        assert np.array_equal(getattr(first, field), getattr(again, field)), field


def test_dense_output_samples_equal_an_integration_at_those_times(integrations):
    """The cached dense output against SciPy's t_eval run of the same problem to the same end:
    the same steps, sampled by the same interpolants, so the same numbers bit for bit."""
    scene = compile_scene(tumbling_box())
    times = samples(0.5, 1e-3)
    got = reference_motion(scene, times)
    (end,) = integrations
    direct = newton_euler._integrate(scene, end, times=times)
    want = newton_euler._unpack(direct.y.T, scene.count)
    assert np.array_equal(got.pos, want[0]), np.abs(got.pos - want[0]).max()
    assert np.array_equal(got.vel, want[2]), np.abs(got.vel - want[2]).max()
    assert np.array_equal(got.t, times)


def test_a_scene_that_differs_gets_its_own_integration(integrations):
    changed = tumbling_box().model_dump()
    changed["bodies"][0]["angular_velocity"] = [0.05, 10.0, 0.06]
    reference_motion(compile_scene(tumbling_box()), samples(0.5, 1e-3))
    reference_motion(compile_scene(Scenario.model_validate(changed)), samples(0.5, 1e-3))
    assert len(integrations) == 2, f"integrations to {integrations}"


def test_a_recorded_blocks_world_inertia_is_computed_once_and_anew_for_other_states():
    """The measurement side keeps the last block's ``R I Rᵀ`` (energy, angular momentum and
    the stability check read the same states): the same object for the same orientations,
    fresh products as soon as one quaternion differs."""
    scene = compile_scene(tumbling_box())
    rng = np.random.default_rng(3)
    quat = rng.normal(size=(5, 1, 4))
    quat /= np.linalg.norm(quat, axis=-1, keepdims=True)
    first = scene.inertia_world(quat)
    assert scene.inertia_world(quat.copy()) is first
    turned = quat.copy()
    turned[3, 0] = [np.cos(0.1), np.sin(0.1), 0.0, 0.0]
    expected = world_inertia(scene.inertia, rotations(turned))
    assert np.array_equal(scene.inertia_world(turned), expected), "stale R I Rᵀ after a turn"
    assert not np.array_equal(expected, first)
