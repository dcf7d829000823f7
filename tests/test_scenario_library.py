"""The bundled scenario library: every scene loads, says what it stresses, and fits the schema."""

from __future__ import annotations

import jsonschema
import pytest

from validation.cli import BUNDLED_SCENARIOS, main
from validation.scenario import check_scenario, json_schema, scenario_files
from validation.scenario.yaml_source import read_yaml

SCENES = scenario_files([BUNDLED_SCENARIOS])
MINIMUM_SCENES = 24
"""The library holds at least 24 scenes."""

THEMES = ("formulas", "benchmarks", "rotation", "contact", "stiff")


def test_library_is_complete():
    assert len(SCENES) >= MINIMUM_SCENES, f"{len(SCENES)} scenes"
    themes = {path.parent.name for path in SCENES}
    assert set(THEMES) <= themes, f"themes present: {sorted(themes)}"


@pytest.mark.parametrize("path", SCENES, ids=lambda p: f"{p.parent.name}/{p.stem}")
def test_bundled_scene_loads_with_description_and_checks(path):
    scenario, problems = check_scenario(path)
    errors = [str(p) for p in problems if not p.warning]
    assert scenario is not None and not errors, errors
    assert scenario.description.strip(), "no description"
    assert scenario.checks, "no checks"
    warnings = [p for p in problems if p.warning]
    overlaps = [p for p in warnings if "overlap by" in p.message]
    assert warnings == overlaps, [str(p) for p in warnings if p not in overlaps]
    if overlaps:
        assert (
            "penetration" in scenario.description.lower()
            or "overlap" in scenario.description.lower()
        ), f"overlaps at t = 0 in a scene that does not say it means them: {overlaps}"


@pytest.mark.parametrize("path", SCENES, ids=lambda p: f"{p.parent.name}/{p.stem}")
def test_bundled_scene_passes_the_published_json_schema(path):
    document, _ = read_yaml(path)  # the loader's YAML reading (1e6 is a number, as in YAML 1.2)
    jsonschema.validate(document, json_schema())


def test_json_schema_rejects_what_the_loader_rejects():
    schema = json_schema()
    bad = {
        "dt": 0.001,
        "duration": 1.0,
        "bodies": [{"name": "b", "shape": {"type": "sphere", "radius": -1}, "mass": 1}],
    }
    with pytest.raises(jsonschema.ValidationError):
        jsonschema.validate(bad, schema)
    typo = {"dt": 0.001, "duration": 1.0, "gravty": [0, 0, 0], "bodies": []}
    with pytest.raises(jsonschema.ValidationError):
        jsonschema.validate(typo, schema)


def test_physval_check_passes_on_the_library(capsys):
    assert main(["check", str(BUNDLED_SCENARIOS)]) == 0, capsys.readouterr().err
