"""The comparator's own lines (``validation.measure.comparator``): the pass test of a row and
the judgement of a ``divergence`` row against its pair of engines."""

from __future__ import annotations

from validation.measure.comparator import _row
from validation.measure.measurement import Measurement
from validation.measure.runner import EngineRun
from validation.scenario import Scenario
from validation.scenario.compiled import compile_scene

TOLERANCE = 0.01
"""The restitution tolerance of the test scene (any number: the rows below sit around it)."""

BAND = 0.02
"""The row's discretization band (``Measurement.band``): larger than the tolerance, so a row
inside the band alone passes only when the pass test adds it."""


def bouncing_scene() -> Scenario:
    return Scenario.model_validate(
        {
            "name": "bounce",
            "dt": 0.001,
            "duration": 0.1,
            "ground": {"restitution": 0.5},
            "bodies": [
                {
                    "name": "ball",
                    "shape": {"type": "sphere", "radius": 0.1},
                    "mass": 1.0,
                    "position": [0, 0, 0.5],
                    "restitution": 0.5,
                }
            ],
            "checks": {"restitution_error": TOLERANCE},
        }
    )


def restitution_row(error: float) -> dict:
    scene = compile_scene(bouncing_scene())
    result = Measurement("restitution_error", 0.5 + error, 0.5, "analytic", error, band=BAND)
    return _row(scene, EngineRun("bounce", "mini", "ok"), result, "ok")


def test_a_row_within_its_restitution_band_passes():
    """``error <= tolerance + band``: the band is the physics' O(dt) allowance (derived, never
    a tolerance), so an error beyond the tolerance but within tolerance + band passes."""
    row = restitution_row(TOLERANCE + 0.5 * BAND)
    assert row["band"] == BAND
    assert row["passed"] is True and row["status"] == "ok"


def test_a_row_beyond_tolerance_and_band_fails():
    row = restitution_row(TOLERANCE + 1.5 * BAND)
    assert row["passed"] is False and row["status"] == "failed"
