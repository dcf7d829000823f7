"""The approach speed of an impact (``validation.measure.recording.ImpactDetector``) is the
contact points' velocity, ``v + ω × r``, the body's spin included."""

from __future__ import annotations

import numpy as np

from validation.engines.base import Trajectory
from validation.measure.recording import ImpactDetector
from validation.scenario import Scenario
from validation.scenario.compiled import compile_scene

SPIN = 3.0
"""rad/s about z, the box's; its contact point is ``ARM`` from its centre."""

ARM = np.array([0.2, 0.0, 0.0])
"""m: the contact point seen from the box's centre; ``ω × r = (0, 0.6, 0)`` m/s, along the
normal (0, 1, 0)."""

NORMAL = np.array([0.0, 1.0, 0.0])


def test_the_approach_speed_includes_the_spin_at_the_contact_point():
    """A box at rest whose spin sweeps its contact point along the normal approaches at
    ``(ω × r)·n``, though its centre does not move."""
    scene = compile_scene(
        Scenario.model_validate(
            {
                "name": "spinner",
                "dt": 0.001,
                "duration": 0.01,
                "gravity": [0, 0, 0],
                "bodies": [
                    {
                        "name": "box",
                        "shape": {"type": "box", "half_extents": [0.2, 0.1, 0.1]},
                        "mass": 1.0,
                        "position": [0, 0, 1],
                    }
                ],
            }
        )
    )
    states = Trajectory(
        np.zeros(1),
        np.zeros((1, 2, 3)),
        np.tile([1.0, 0, 0, 0], (1, 2, 1)),
        np.zeros((1, 2, 3)),
        np.array([[[0.0, 0.0, SPIN], [0.0, 0.0, 0.0]]]),
    )
    speed = ImpactDetector(scene)._relative_normal_velocity(
        states,
        np.zeros(1, int),
        np.ones(1, int),
        np.zeros(1, int),
        NORMAL[None],
        np.zeros((1, 3)),
        ARM[None],
    )
    np.testing.assert_allclose(speed, [np.cross([0.0, 0.0, SPIN], ARM) @ NORMAL], atol=1e-15)
    assert abs(speed[0]) > 0.5  # what the spin alone gives: not a zero test
