"""Scene authoring: load-time messages in the file's own words with the fix, every problem of a
file in one pass (``validation.scenario.load``, ``problems``)."""

from __future__ import annotations

from pathlib import Path

import pytest

from validation.scenario.load import check_scenario

GOOD_BODY = """\
  - name: ball
    shape: {type: sphere, radius: 0.1}
    mass: 1.0
    position: [0, 0, 1]
"""


def _problems(tmp_path: Path, text: str) -> list[str]:
    path = tmp_path / "scene.yaml"
    path.write_text(text)
    scenario, problems = check_scenario(path)
    assert scenario is None, "the scene should not load"
    return [str(p) for p in problems if not p.warning]


def test_a_shape_written_as_a_word_is_told_the_mapping_to_write(tmp_path):
    found = _problems(
        tmp_path,
        "dt: 1.0e-3\nduration: 1.0\nbodies:\n  - name: ball\n    shape: sphere\n    mass: 1.0\n",
    )
    assert len(found) == 1, found
    assert found[0].startswith(f"{tmp_path / 'scene.yaml'}:5:5: bodies[0].shape:"), found
    assert "{type: sphere, radius: 0.1}" in found[0] and "got 'sphere'" in found[0], found
    assert "dictionary" not in found[0] and "groundspec" not in found[0].lower(), found


def test_a_quoted_tolerance_is_one_message_with_the_fix(tmp_path):
    found = _problems(
        tmp_path,
        f"dt: 1.0e-3\nduration: 1.0\nbodies:\n{GOOD_BODY}checks:\n  energy_drift: \"1e-3\"\n",
    )
    assert len(found) == 1, found  # not one per member of the union
    assert "checks.energy_drift:" in found[0] and "without quotes" in found[0], found
    assert "constrained-float" not in found[0], found


def test_a_ground_that_is_not_a_mapping_says_what_a_ground_is(tmp_path):
    found = _problems(tmp_path, f"dt: 1.0e-3\nduration: 1.0\nground: yes\nbodies:\n{GOOD_BODY}")
    assert len(found) == 1 and "ground: expected a mapping such as {normal:" in found[0], found


def test_every_problem_of_a_file_in_one_pass(tmp_path):
    found = _problems(
        tmp_path,
        "dt: 1.0e-3\nduration: 1.0\nengines: [mini, mujuco]\n"
        f"bodies:\n{GOOD_BODY}    velocty: [1, 0, 0]\n",
    )
    assert len(found) == 2, found  # the unknown engine is not held back by the schema error
    assert "unknown engine 'mujuco'" in found[0] and "did you mean 'mujoco'" in found[0], found
    assert "unknown field 'velocty'; did you mean 'velocity'" in found[1], found


@pytest.mark.parametrize(
    ("spec", "suggestion"),
    [("mujoco(integrator=rk4)", "RK4"), ("mini(gyroscopic=explict)", "explicit")],
)
def test_an_engine_option_value_gets_a_did_you_mean_whatever_its_case(tmp_path, spec, suggestion):
    found = _problems(
        tmp_path, f'dt: 1.0e-3\nduration: 1.0\nengines: ["{spec}"]\nbodies:\n{GOOD_BODY}'
    )
    assert len(found) == 1 and f"did you mean {suggestion!r}" in found[0], found
