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


LONG = 1 << 20
"""1 MiB: an engine's message and a setting of this length (the issue's was 20 MiB, and made
a 105 MB report)."""

REPORT_BYTES = 400_000
"""The report of one scene in one engine is about 80 KB; a text shown whole would add 1 MiB
per place it is shown."""

SCENE = """dt: 1.0e-3
duration: 0.05
engines: [mini]
bodies:
  - {name: ball, shape: {type: sphere, radius: 0.1}, mass: 1.0, position: [0, 0, 1]}
"""


@pytest.fixture
def long_texts(monkeypatch):
    """mini raises with a 1 MiB message and reports a 1 MiB setting and note."""
    from dataclasses import replace

    from validation.engines.mini.adapter import MiniAdapter

    def raises(self, steps):
        raise RuntimeError("engine says " + "x" * LONG)

    provenance = MiniAdapter.provenance
    long_provenance = lambda self: replace(  # noqa: E731
        provenance(self),
        settings={**provenance(self).settings, "blob": "y" * LONG},
        notes=["z" * LONG],
    )
    monkeypatch.setattr(MiniAdapter, "advance", raises)
    monkeypatch.setattr(MiniAdapter, "advance_observed", raises)
    monkeypatch.setattr(MiniAdapter, "provenance", long_provenance)


def test_engine_texts_are_capped_in_the_report_and_whole_in_the_run_folder(
    long_texts, tmp_path, monkeypatch
):
    import pandas as pd

    from validation.jobs.run import run_main

    path = tmp_path / "ball.yaml"
    path.write_text(SCENE)
    monkeypatch.chdir(tmp_path)
    out = tmp_path / "out"
    assert run_main([path], "mini", out, None, None, ["run", str(path)]) == 1
    report = (out / "report.html").read_text()
    assert len(report.encode()) < REPORT_BYTES, len(report.encode())
    assert "more characters in results.csv" in report
    assert "more characters in provenance.json" in report
    rows = pd.read_csv(out / "results.csv", keep_default_na=False)
    status = rows[rows["metric"] == "status"].iloc[0]
    assert status["status"] == "error" and len(status["message"]) > LONG, len(status["message"])
    assert "y" * LONG in (out / "provenance.json").read_text()
