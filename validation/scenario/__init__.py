"""The scenario format, independent of every engine.

``yaml_source`` reads YAML strictly with the position of every field; ``schema`` holds the
pydantic models of format v1; ``problems`` turns what is wrong into
``file:line:column: field: message``; ``checks`` are the whole-document rules;
``definability`` says which metrics a scene can define; ``load`` puts them together;
``engine_spec`` parses ``name(key=value)`` specs; ``physics`` is what a scenario implies for
every engine (inertias, pair values, rest lengths, the mini model); ``compiled`` is the scene
compiled once for every consumer.
"""

from validation.scenario.load import (
    BUNDLED_SCENARIOS,
    ScenarioWarning,
    check_scenario,
    default_scenario_paths,
    json_schema,
    load_scenario,
    scenario_files,
)
from validation.scenario.problems import Problem, ScenarioError
from validation.scenario.schema import MAX_STEPS, BodySpec, Scenario

__all__ = [
    "BUNDLED_SCENARIOS",
    "MAX_STEPS",
    "BodySpec",
    "Problem",
    "Scenario",
    "ScenarioError",
    "ScenarioWarning",
    "check_scenario",
    "default_scenario_paths",
    "json_schema",
    "load_scenario",
    "scenario_files",
]
