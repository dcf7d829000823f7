"""Cost bounded by what the user asked for: the memory estimate counts a scene's expectation
lists; an engine's message and the provenance values are capped in the report, whole in the
run folder."""

from __future__ import annotations

import pytest

from validation.jobs import memory
from validation.jobs.plan import BadInputError, Plan
from validation.scenario import Scenario
from validation.scenario.compiled import compile_scene
from validation.scenario.engine_spec import parse_engine_spec

HEIGHTS = 900_000
"""The issue's scene: 900,000 bounce heights took 1.8 GB of the command's process."""


def bouncing(heights: int) -> Scenario:
    return Scenario.model_validate(
        {
            "name": f"bounce_{heights}",
            "source": f"bounce_{heights}.yaml",
            "dt": 1e-3,
            "duration": 1.0,
            "engines": ["mini"],
            "ground": {"normal": [0, 0, 1], "restitution": 1.0},
            "bodies": [
                {
                    "name": "ball",
                    "shape": {"type": "sphere", "radius": 0.1},
                    "mass": 1.0,
                    "position": [0.0, 0.0, 0.5],
                }
            ],
            "expect": [{"kind": "bounce_heights", "body": "ball", "value": [0.5] * heights}],
        }
    )


def plan_of(heights: int) -> Plan:
    return Plan([(compile_scene(bouncing(heights)), [parse_engine_spec("mini")])])


AVAILABLE = 1_500 * memory.MB
"""Enough for the scene with one bounce height (about 300 MB), not for 900,000 (2 GB)."""


def test_the_memory_estimate_counts_expectation_lists(monkeypatch):
    monkeypatch.setattr(memory, "available_memory", lambda: AVAILABLE)
    memory.check_memory(plan_of(1), 1, lambda scene: 1)  # the control: it fits
    with pytest.raises(BadInputError) as refused:
        memory.check_memory(plan_of(HEIGHTS), 1, lambda scene: 1)
    line = str(refused.value)
    assert line.startswith(f"bounce_{HEIGHTS}.yaml: the run needs an estimated "), line
    assert "lists 900,000 expected values" in line and "\n" not in line, line
