"""A row within its engine's declared precision passes, the bound shown as its band (issue 34,
item 10): a float32 engine's error that rounding alone reaches is not a failure needing a
hand-written ``known:`` entry; a float64 engine's same error, or one beyond the bound, fails."""

from __future__ import annotations

import importlib.util
from pathlib import Path

import pytest

from validation.measure import comparator
from validation.measure.measurement import Measurement
from validation.measure.resolution import (
    FLOAT32_DRIFT_FLOOR,
    FLOAT32_UNIT_ROUNDOFF,
    RESOLUTION_MARK,
    precision_band,
)
from validation.measure.runner import EngineRun
from validation.scenario import load_scenario
from validation.scenario.compiled import compile_scene

REPOSITORY = Path(__file__).resolve().parent.parent
PROJECTILE = REPOSITORY / "scenarios/formulas/projectile.yaml"
"""1,500 steps; ``velocity_at.ball`` and ``velocity_at.ball.end`` checked to 1e-9 m/s."""

RAPIER_SUBSTEPS = 4
"""Rapier's declared substeps per scene step (``Capabilities.substeps``)."""

needs_rapier = pytest.mark.skipif(
    importlib.util.find_spec("rapier3d") is None,
    reason='rapier3d is not installed (pip install "physval[rapier]")',
)


def test_the_band_is_the_float32_floor_and_nothing_for_float64():
    carried = precision_band("float32", "velocity_at.ball", 3.5, 3.5, 1500, 4)
    assert carried == pytest.approx(1500 * 4 * FLOAT32_UNIT_ROUNDOFF * 3.5)
    assert precision_band("float32", "linear_momentum_drift", 0.0, 0.0, 10, 4) == (
        FLOAT32_DRIFT_FLOOR
    )
    assert precision_band("float32", "restitution_error", 0.5, 0.5, 1500, 4) == 0.0
    assert precision_band("float64", "velocity_at.ball", 3.5, 3.5, 1500, 4) == 0.0


def row(engine: str, error: float, band: float = 0.0) -> dict:
    scene = compile_scene(load_scenario(PROJECTILE))
    run = EngineRun(scene.name, engine, "ok")
    result = Measurement("velocity_at.ball", 3.5 + error, 3.5, "analytic", error, "", band)
    return comparator._row(scene, run, result, "ok")


@needs_rapier
def test_a_float32_row_within_its_bound_passes_with_the_bound_as_its_band():
    bound = 1500 * RAPIER_SUBSTEPS * FLOAT32_UNIT_ROUNDOFF * 3.5001
    within = row("rapier", 1e-4)
    assert within["passed"] is True and within["status"] == "ok", within
    assert within["band"] == pytest.approx(bound, rel=1e-3)
    assert within["message"].startswith(RESOLUTION_MARK), within["message"]
    beyond = row("rapier", 1e-2)
    assert beyond["passed"] is False and beyond["status"] == "failed", beyond
    assert not beyond["message"].startswith(RESOLUTION_MARK)


@needs_rapier
def test_the_precision_band_adds_to_the_rows_own_band():
    both = row("rapier", 1e-4, band=0.25)
    assert both["band"] == pytest.approx(0.25 + 1500 * 4 * FLOAT32_UNIT_ROUNDOFF * 3.5001)


def test_a_float64_engine_gets_no_precision_band():
    same = row("mini", 1e-4)
    assert same["passed"] is False and same["status"] == "failed", same
    assert same["band"] == 0.0 and not same["message"].startswith(RESOLUTION_MARK)
