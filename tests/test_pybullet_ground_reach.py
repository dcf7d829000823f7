"""PyBullet's matched ground is a box whose top face is the scene's plane (adapter
``ground_box``): it must reach as far as the scene's bodies can go, on a level or tilted
ground, or a body that travels past its edge falls off and the run is declared ``unstable``
(deep penetration of the plane every other engine has)."""

from __future__ import annotations

import numpy as np
import pytest

from validation.engines.pybullet.adapter import ground_box
from validation.measure.runner import run_engine
from validation.reference.rotation import quat_to_matrix
from validation.scenario import Scenario
from validation.scenario.compiled import compile_scene
from validation.scenario.engine_spec import parse_engine_spec
from validation.scenario.physics import ground_pose

LAUNCH = (400.0, 0.0, 30.0)
"""m/s. A shell fired at 400 m/s along the ground, 30 m/s up: it lands about 6.1 s and 2.4 km
later, beyond the 1 km half-width the matched ground had, and bounces (e = 1)."""

BOUNCE_TOLERANCE = 0.01
"""Relative error of e: the matched recipe's 1 % (test_engine_pybullet ``RESTITUTION_TOLERANCE``)."""


def shell_scene(normal=(0.0, 0.0, 1.0)) -> Scenario:
    return Scenario.model_validate(
        {
            "dt": 1e-3,
            "duration": 6.5,
            "ground": {"normal": list(normal), "restitution": 1.0, "friction": 0.0},
            "bodies": [
                {
                    "name": "shell",
                    "shape": {"type": "sphere", "radius": 0.1},
                    "mass": 1.0,
                    "position": [0.0, 0.0, 0.2],
                    "velocity": list(LAUNCH),
                    "restitution": 1.0,
                    "friction": 0.0,
                }
            ],
        }
    )


def test_a_kilometre_bounce_lands_on_the_ground():
    scene = compile_scene(shell_scene())
    run = run_engine(scene, parse_engine_spec("pybullet"), 1)
    recording = run.recording
    assert recording is not None, run.message
    assert recording.unstable is None, recording.unstable
    landed = [e for e in recording.impacts if e.body_a == "ground"]
    assert len(landed) == 1
    assert abs(landed[0].normal_velocity_before) > 25.0  # the real landing, not a graze
    assert landed[0].restitution == pytest.approx(1.0, rel=BOUNCE_TOLERANCE)
    assert abs(recording.trajectory.pos[-1, 0, 0]) > 2000.0


@pytest.mark.parametrize("normal", [(0.0, 0.0, 1.0), (0.3, -0.2, 1.0)])
def test_the_ground_box_covers_every_body_reach_under_its_top_face(normal):
    """The box's top face is the plane; every point a body can reach over the run (its start
    plus the speed scale times the duration, plus its radius) lies over the box's top face,
    and a body moving at the speed scale cannot cross the box in one step."""
    scene = compile_scene(shell_scene(normal))
    centre, half = ground_box(scene)
    point, quat = ground_pose(scene.scenario.ground)
    rot = quat_to_matrix(quat)
    up = rot[:, 2]
    top = centre + half[2] * up
    assert abs((top - point) @ up) < 1e-9  # the top face lies in the plane
    travel = scene.speed_scale * scene.scenario.duration
    start = scene.start.pos[0, 0]
    for direction in np.eye(3):
        far = start + direction * (travel + scene.bound_radius[0])
        local = rot.T @ (far - centre)
        assert np.all(np.abs(local[:2]) <= half[:2]), (local, half)
    assert 2.0 * half[2] >= scene.speed_scale * scene.scenario.dt
