"""Restitution measured fairly: the discretization band (issue-10 finding 2)."""

from __future__ import annotations

import math

import numpy as np
import pytest

from validation.measure.restitution import restitution_band
from validation.measure.runner import run_engine
from validation.scenario import Scenario
from validation.scenario.compiled import compile_scene
from validation.scenario.engine_spec import parse_engine_spec

E = 0.5
G = 9.81
RADIUS = 0.1
HEIGHTS = (0.105, 0.12, 0.3, 0.6, 1.0)
"""m, centre heights of five balls dropped side by side: impacts at 0.31 to 4.2 m/s (at the
slowest, MuJoCo and PyBullet read e·A·h/v = 0.016 low: beyond the 0.01 tolerance alone)."""

CALIBRATION_TOLERANCE = 0.01
"""|Δe| beyond the band that a matched engine may show: engines.md 1.7 (MuJoCo's damper) and
2.4 (PyBullet's recipe) measured e within 1 % of the request."""

BAND_FIRST_ORDER = 0.1
"""Relative: the band is first order in dt, so four times the step gives four times the band
(to 10 %, the difference between carrying v by A·dt and the measured approach speed)."""


def test_the_band_is_the_widest_gap_between_the_conventions():
    """After the step's forces e reads exactly; before them, the contact absorbing the forces,
    it reads e V / (V + A h); before them, the forces acting on the rebound, (e V - A h) /
    (V + A h): the band is the widest gap, for any speed and step (module docstring)."""
    for speed, step in [(4.2, 1e-3), (0.07, 1e-3), (1.0, 1e-4)]:
        before = -(speed + G * step)  # carried to the impulse centroid, as ImpactEvent does
        band = restitution_band(E, -G, step, before)
        absorbed = E * speed / -before
        rebound_pulled = (E * speed - G * step) / -before
        assert E - rebound_pulled == pytest.approx(band, rel=1e-12), (speed, step)
        assert E - absorbed == pytest.approx(band * E / (1 + E), rel=1e-12), (speed, step)


def drops(dt: float) -> Scenario:
    return Scenario.model_validate(
        {
            "name": "drops",
            "dt": dt,
            "duration": 0.5,
            "ground": {"restitution": E},
            "bodies": [
                {
                    "name": f"ball_{i}",
                    "shape": {"type": "sphere", "radius": RADIUS},
                    "mass": 1.0,
                    "position": [2.0 * i, 0, height],
                    "restitution": E,
                }
                for i, height in enumerate(HEIGHTS)
            ],
        }
    )


def first_impacts(engine: str, dt: float) -> list[tuple[float, float, float]]:
    """(impact speed m/s, |Δe|, band) of each ball's first impact."""
    run = run_engine(compile_scene(drops(dt)), parse_engine_spec(engine))
    first: dict[str, object] = {}
    for event in run.recording.impacts:
        first.setdefault(event.body_b, event)
    return [
        (abs(e.normal_velocity_before), abs(e.restitution - E), e.band(E))
        for _, e in sorted(first.items())
    ]


@pytest.mark.parametrize("engine", ["mini", "mujoco", "pybullet"])
def test_matched_engines_pass_within_tolerance_plus_band(engine):
    found = first_impacts(engine, 1e-3)
    assert len(found) == len(HEIGHTS), found
    for speed, delta, band in found:
        assert delta <= CALIBRATION_TOLERANCE + band, (engine, speed, delta, band)


def test_pybullet_defaults_still_fail():
    """The defaults profile brakes balls before they touch (speculative contacts) and zeroes
    slow bounces (restitution threshold 0.2 m/s): far outside tolerance plus band."""
    found = first_impacts("pybullet(profile=defaults)", 1e-3)
    worst = max((delta - band for _, delta, band in found), default=math.inf)
    missing = len(HEIGHTS) - len(found)
    assert missing > 0 or worst > CALIBRATION_TOLERANCE, found


def test_the_band_shrinks_with_the_step():
    coarse = np.array([band for _, _, band in first_impacts("mujoco", 2e-3)])
    fine = np.array([band for _, _, band in first_impacts("mujoco", 5e-4)])
    assert np.allclose(coarse / fine, 4.0, rtol=BAND_FIRST_ORDER), coarse / fine
