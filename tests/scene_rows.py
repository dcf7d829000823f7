"""One scene in one engine, measured as ``physval run`` measures it: rows by metric."""

from __future__ import annotations

from validation.jobs.run import run_job
from validation.measure.comparator import compare_scene
from validation.scenario import Scenario
from validation.scenario.compiled import compile_scene
from validation.scenario.engine_spec import parse_engine_spec


def rows(data: dict, engine: str) -> dict[str, dict]:
    """The result rows, keyed by metric, of the scene ``data`` (a scenario as a dict) run in
    the engine spec ``engine``."""
    scene = compile_scene(Scenario.model_validate(data))
    run, measured = run_job((scene, parse_engine_spec(engine)))
    return {r["metric"]: r for r in compare_scene(scene, [run], [measured])}
