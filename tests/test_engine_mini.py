"""The mini adapter and the parity gate (the same gate the MuJoCo and PyBullet adapters pass)."""

from __future__ import annotations

import numpy as np
import pytest

from validation.cli import BUNDLED_SCENARIOS
from validation.engines.parity import PARITY_TOLERANCE, compare
from validation.engines.reference import reference_report
from validation.engines.registry import create_adapter
from validation.scenario import Scenario, load_scenario, scenario_files
from validation.scenario.compiled import compile_scene
from validation.scenario.engine_spec import parse_engine_spec

ROTATED_OFFSET_SPINNING = {
    "dt": 0.001,
    "duration": 0.01,
    "gravity": [0, 0, 0],
    "ground": {"restitution": 0.5},
    "bodies": [
        {
            "name": "box",
            "shape": {"type": "box", "half_extents": [0.1, 0.2, 0.3]},
            "mass": 2.0,
            "inertia": [[0.3, 0.02, 0.0], [0.02, 0.25, 0.0], [0.0, 0.0, 0.1]],
            "position": [1.0, -2.0, 3.0],
            "orientation": [0.8775826, 0.4794255, 0.0, 0.0],
            "velocity": [0.5, -0.25, 1.0],
            "angular_velocity": [1.0, 2.0, -3.0],
        },
        {
            "name": "post",
            "shape": {"type": "sphere", "radius": 0.1},
            "mass": 1.0,
            "fixed": True,
            "position": [5, 5, 5],
        },
    ],
}


def scenario_from(data: dict) -> Scenario:
    return Scenario.model_validate({"name": "test", **data})


def test_snapshot_is_the_scenario_state_in_scenario_order_without_the_ground():
    scenario = scenario_from(ROTATED_OFFSET_SPINNING)
    adapter = create_adapter(parse_engine_spec("mini"))
    adapter.load(compile_scene(scenario))
    snap = adapter.observe()
    box = scenario.bodies[0]
    assert snap.pos.shape == (2, 3), "the ground must not be a body of the snapshot"
    assert np.allclose(snap.pos[0], box.position) and np.allclose(snap.quat[0], box.orientation)
    assert np.allclose(snap.vel[0], box.velocity) and np.allclose(
        snap.ang_vel[0], box.angular_velocity
    )
    adapter.advance(1)
    moved = adapter.observe().pos[0] - np.asarray(box.position)
    assert np.allclose(moved, np.asarray(box.velocity) * scenario.dt, atol=1e-15), moved


@pytest.mark.parametrize("path", scenario_files([BUNDLED_SCENARIOS]), ids=lambda p: p.stem)
def test_parity_gate_passes_on_every_bundled_scene(path):
    scenario = load_scenario(path)
    adapter = create_adapter(parse_engine_spec("mini"))
    adapter.load(compile_scene(scenario))
    mismatches = compare(adapter.model_report(), reference_report(compile_scene(scenario)))
    assert mismatches == [], [str(m) for m in mismatches]


def test_parity_gate_names_a_wrong_inertia(monkeypatch):
    scenario = scenario_from(ROTATED_OFFSET_SPINNING)
    adapter = create_adapter(parse_engine_spec("mini"))
    adapter.load(compile_scene(scenario))
    wrong = adapter.model.body_inertia.copy()
    wrong[0] *= 1.0 + 1e-6  # a millionth: far below anything a plot would show
    object.__setattr__(adapter.model, "body_inertia", wrong)
    mismatches = compare(adapter.model_report(), reference_report(compile_scene(scenario)))
    quantities = {m.quantity for m in mismatches}
    assert "inertia_world" in quantities, quantities
    message = str(next(m for m in mismatches if m.quantity == "inertia_world"))
    assert "body 0" in message and str(PARITY_TOLERANCE) in message, message


def test_provenance_records_every_setting():
    adapter = create_adapter(parse_engine_spec("mini(gyroscopic=implicit, solver_iterations=20)"))
    adapter.load(compile_scene(scenario_from(ROTATED_OFFSET_SPINNING)))
    settings = adapter.provenance().settings
    assert settings["gyroscopic"] == "implicit" and settings["solver_iterations"] == 20
    assert settings["dt"] == 0.001 and "restitution_threshold" in settings
