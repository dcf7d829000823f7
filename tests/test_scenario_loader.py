"""The scenario loader: defaults, every rejection the format promises, and no tracebacks."""

from __future__ import annotations

import textwrap
from pathlib import Path

import pytest
import yaml
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from validation.cli import main
from validation.scenario import (
    MAX_STEPS,
    ScenarioError,
    check_scenario,
    load_scenario,
)

MINIMAL = """\
dt: 0.001
duration: 1.0
bodies:
  - name: ball
    shape: {type: sphere, radius: 0.1}
    mass: 1.0
"""


def write(tmp_path: Path, text: str, name: str = "scene.yaml") -> Path:
    path = tmp_path / name
    path.write_text(textwrap.dedent(text))
    return path


def test_minimal_scene_gets_documented_defaults(tmp_path):
    scenario = load_scenario(write(tmp_path, MINIMAL, "drop_test.yaml"))
    assert scenario.name == "drop_test"
    assert scenario.gravity == (0.0, 0.0, -9.81)
    assert scenario.engines == ["mini", "mujoco", "pybullet"]
    assert scenario.ground is None and scenario.springs == [] and scenario.checks == {}
    body = scenario.bodies[0]
    assert body.orientation == (1.0, 0.0, 0.0, 0.0) and body.restitution == 0.0
    assert body.friction == 0.0 and body.fixed is False
    assert scenario.steps == 1000


def test_near_unit_quaternion_is_normalised(tmp_path):
    text = MINIMAL + "    orientation: [1.0000005, 0, 0, 0]\n"
    scenario = load_scenario(write(tmp_path, text))
    assert abs(sum(q * q for q in scenario.bodies[0].orientation) - 1.0) < 1e-15


def test_per_engine_tolerances_apply_to_exactly_that_spec(tmp_path):
    text = MINIMAL + textwrap.dedent("""\
        engines: [mini, "mini(gyroscopic=implicit)", pybullet]
        checks:
          energy_drift: {default: 0.01, pybullet: 0.03, "mini(gyroscopic=implicit)": 0.002}
        """)
    scenario = load_scenario(write(tmp_path, text))
    assert scenario.tolerance("energy_drift", "pybullet") == 0.03
    assert scenario.tolerance("energy_drift", "mini(gyroscopic=implicit)") == 0.002
    assert scenario.tolerance("energy_drift", "mini") == 0.01
    assert scenario.tolerance("position_error", "mini") is None


BAD_BODY = {
    "zero mass": ("mass: 0.0", "bodies[0].mass", "greater than 0"),
    "negative mass": ("mass: -1.0", "bodies[0].mass", "greater than 0"),
    "NaN mass": ("mass: .nan", "bodies[0].mass", "finite"),
    "infinite mass": ("mass: .inf", "bodies[0].mass", "finite"),
    "text mass": ("mass: heavy", "bodies[0].mass", "got 'heavy'"),
    "boolean mass": ("mass: true", "bodies[0].mass", "number"),
    "zero radius": ("shape: {type: sphere, radius: 0}", "bodies[0].shape.radius", "greater than 0"),
    "negative half extent": (
        "shape: {type: box, half_extents: [0.1, -0.1, 0.1]}",
        "bodies[0].shape.half_extents[1]",
        "greater than 0",
    ),
    "two half extents": (
        "shape: {type: box, half_extents: [0.1, 0.1]}",
        "bodies[0].shape.half_extents[2]",
        "missing",
    ),
    "unknown shape": (
        "shape: {type: cone, radius: 1}",
        "bodies[0].shape.type",
        "'sphere', 'box', 'capsule'",
    ),
    "misspelt field": (
        "shape: {type: sphere, radious: 0.1}",
        "bodies[0].shape.radious",
        "did you mean 'radius'",
    ),
    "non-unit quaternion": (
        "orientation: [1, 0.1, 0, 0]",
        "bodies[0].orientation",
        "unit quaternion",
    ),
    "inertia not symmetric": (
        "inertia: [[1, 0.5, 0], [0, 1, 0], [0, 0, 1]]",
        "bodies[0].inertia",
        "symmetric",
    ),
    "inertia not positive definite": (
        "inertia: [1, -1, 1]",
        "bodies[0].inertia",
        "positive definite",
    ),
    "inertia breaks triangle inequality": (
        "inertia: [1, 1, 5]",
        "bodies[0].inertia",
        "triangle inequality",
    ),
    "restitution above one": (
        "restitution: 1.5",
        "bodies[0].restitution",
        "less than or equal to 1",
    ),
}


def body_with(line: str) -> str:
    """The minimal scene with one field of its body replaced (or added)."""
    key = line.split(":", 1)[0]
    lines = [row for row in MINIMAL.splitlines() if not row.strip().startswith(f"{key}:")]
    return "\n".join(lines) + f"\n    {line}\n"


@pytest.mark.parametrize("case", sorted(BAD_BODY))
def test_bad_body_fields_are_rejected_naming_the_field(tmp_path, case):
    line, field, expected = BAD_BODY[case]
    path = write(tmp_path, body_with(line))
    with pytest.raises(ScenarioError) as caught:
        load_scenario(path)
    messages = [str(p) for p in caught.value.problems]
    assert any(f" {field}:" in m and expected in m for m in messages), messages
    assert all(m.startswith(str(path) + ":") for m in messages), messages


BAD_DOCUMENT = {
    "zero dt": (MINIMAL.replace("dt: 0.001", "dt: 0"), "dt", "greater than 0"),
    "NaN dt": (MINIMAL.replace("dt: 0.001", "dt: .nan"), "dt", "finite"),
    "negative duration": (
        MINIMAL.replace("duration: 1.0", "duration: -1"),
        "duration",
        "greater than 0",
    ),
    "duration below dt": (
        MINIMAL.replace("duration: 1.0", "duration: 0.0001"),
        "duration",
        ">= dt",
    ),
    "too many steps": (MINIMAL.replace("dt: 0.001", "dt: 1.0e-9"), "duration", str(MAX_STEPS)),
    "missing dt": (MINIMAL.replace("dt: 0.001\n", ""), "dt", "missing"),
    "missing bodies": ("dt: 0.001\nduration: 1.0\n", "bodies", "missing"),
    "unknown top-level key": (
        MINIMAL + "gravty: [0, 0, -9.8]\n",
        "gravty",
        "did you mean 'gravity'",
    ),
    "duplicate body names": (
        MINIMAL
        + "  - {name: ball, shape: {type: sphere, radius: 0.1}, mass: 1.0, position: [1, 0, 0]}\n",
        "bodies[1].name",
        "duplicate body name 'ball'",
    ),
    "unknown engine": (
        MINIMAL + "engines: [mini, mujocoo]\n",
        "engines[1]",
        "did you mean 'mujoco'",
    ),
    "unknown engine setting": (
        MINIMAL + 'engines: ["mini(gyroscopik=explicit)"]\n',
        "engines[0]",
        "did you mean 'gyroscopic'",
    ),
    "bad engine setting value": (
        MINIMAL + 'engines: ["mujoco(integrator=euler)"]\n',
        "engines[0]",
        "did you mean 'Euler'",
    ),
    "unknown metric": (
        MINIMAL + "checks: {energy_drif: 0.1}\n",
        "checks.energy_drif",
        "did you mean 'energy_drift'",
    ),
    "spring to unknown body": (
        MINIMAL + "springs: [{a: ball, b: wrld, stiffness: 10}]\n",
        "springs[0].b",
        "did you mean 'world'",
    ),
}


@pytest.mark.parametrize("case", sorted(BAD_DOCUMENT))
def test_bad_documents_are_rejected_naming_the_field(tmp_path, case):
    text, field, expected = BAD_DOCUMENT[case]
    path = write(tmp_path, text)
    with pytest.raises(ScenarioError) as caught:
        load_scenario(path)
    messages = [str(p) for p in caught.value.problems]
    assert any(f" {field}:" in m and expected in m for m in messages), messages


UNSAFE_YAML = {
    "not YAML": ("dt: [0.001\nduration: 1\n", "not valid YAML"),
    "not a mapping": ("- 1\n- 2\n", "expected a mapping"),
    "python tag": ("dt: !!python/object/apply:os.system ['echo owned']\n", "not allowed"),
    "custom tag": ("dt: !metres 0.001\n", "not allowed"),
    "duplicate key": (MINIMAL + "dt: 0.002\n", "duplicate key 'dt'"),
    "billion laughs": (
        "a: &a [x, x, x, x, x, x, x, x, x, x]\n"
        + "".join(
            f"{chr(98 + i)}: &{chr(98 + i)} [{', '.join(['*' + chr(97 + i)] * 10)}]\n"
            for i in range(8)
        ),
        "1000000 values, the cap on a scenario's size (MAX_VALUES",
    ),
}


@pytest.mark.parametrize("case", sorted(UNSAFE_YAML))
def test_unsafe_or_broken_yaml_is_rejected_with_a_position(tmp_path, case):
    text, expected = UNSAFE_YAML[case]
    path = write(tmp_path, text)
    with pytest.raises(ScenarioError) as caught:
        load_scenario(path)
    (problem,) = caught.value.problems
    assert expected in problem.message, problem.message
    assert problem.line is not None, f"no line for {problem}"


def test_overlapping_bodies_give_a_warning_not_an_error(tmp_path):
    text = (
        MINIMAL
        + "  - {name: other, shape: {type: sphere, radius: 0.1}, mass: 1.0, position: [0.05, 0, 0]}\n"
    )
    scenario, problems = check_scenario(write(tmp_path, text))
    assert scenario is not None
    assert len(problems) == 1 and problems[0].warning, problems
    assert "overlap by" in problems[0].message and "'ball' and 'other'" in problems[0].message


def test_check_command_exit_codes_and_messages(tmp_path, capsys):
    good = write(tmp_path, MINIMAL, "good.yaml")
    bad = write(tmp_path, MINIMAL.replace("mass: 1.0", "mass: -1"), "bad.yaml")
    assert main(["check", str(good)]) == 0
    assert main(["check", str(good), str(bad)]) == 2
    err = capsys.readouterr().err
    assert f"{bad}:6:5: bodies[0].mass: expected greater than 0; got -1" in err, err
    assert main(["check", str(tmp_path / "missing.yaml")]) == 2
    assert main(["check", str(tmp_path)]) == 2  # the folder holds bad.yaml


def test_bad_flags_exit_2_without_traceback(capsys):
    with pytest.raises(SystemExit) as caught:
        main(["check", "--no-such-flag"])
    assert caught.value.code == 2
    assert "Traceback" not in capsys.readouterr().err


# --- documents from hypothesis never produce a traceback --------------------------------

scalars = st.one_of(
    st.none(), st.booleans(), st.integers(-10, 10), st.floats(allow_nan=True), st.text(max_size=5)
)
KEYS = [
    "dt",
    "duration",
    "bodies",
    "name",
    "shape",
    "type",
    "radius",
    "mass",
    "inertia",
    "orientation",
    "engines",
    "checks",
    "springs",
    "a",
    "b",
    "ground",
    "expect",
    "kind",
    "x",
]
documents = st.recursive(
    scalars,
    lambda children: st.one_of(
        st.lists(children, max_size=4),
        st.dictionaries(st.sampled_from(KEYS), children, max_size=6),
    ),
    max_leaves=30,
)


@settings(
    max_examples=300, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture]
)
@given(document=documents)
def test_random_documents_never_raise_anything_but_problems(tmp_path, document):
    path = tmp_path / "random.yaml"
    path.write_text(yaml.safe_dump(document))
    scenario, problems = check_scenario(path)
    assert scenario is not None or problems, "rejected without a reason"
    for problem in problems:
        assert str(problem).startswith(str(path)), str(problem)


def test_readme_first_scenario_is_valid(tmp_path):
    """The "write your first scenario" example in README.md loads as printed."""
    readme = (Path(__file__).parent.parent / "README.md").read_text()
    block = readme.split("```yaml\n", 1)[1].split("```", 1)[0]
    scenario = load_scenario(write(tmp_path, block, "first_bounce.yaml"))
    assert scenario.expect[0].metric == "bounce_heights.ball"
    assert scenario.tolerance("bounce_heights.ball", "mini") == 0.005


@pytest.mark.parametrize("case", ["billion laughs", "python tag", "not YAML"])
def test_physval_check_as_a_process_exits_2_without_traceback(tmp_path, case):
    """The installed command, as a user runs it: one line per problem, exit code 2."""
    import subprocess
    import sys

    path = write(tmp_path, UNSAFE_YAML[case][0])
    result = subprocess.run(
        [sys.executable, "-m", "validation.cli", "check", str(path)],
        capture_output=True,
        text=True,
        timeout=60,
        check=False,
    )
    assert result.returncode == 2, result
    assert "Traceback" not in result.stderr and str(path) in result.stderr, result.stderr
    assert UNSAFE_YAML[case][1] in result.stderr, result.stderr


def test_engine_lists_split_at_top_level_commas():
    from validation.scenario.engine_spec import split_engine_list

    text = "mini(gyroscopic=implicit, solver_iterations=20), mujoco(integrator=RK4),pybullet"
    assert split_engine_list(text) == [
        "mini(gyroscopic=implicit, solver_iterations=20)",
        "mujoco(integrator=RK4)",
        "pybullet",
    ]


def test_round_off_asymmetric_inertia_is_accepted_and_symmetrised(tmp_path):
    text = MINIMAL + "    inertia: [[0.004, 1.0e-12, 0], [0, 0.004, 0], [0, 0, 0.004]]\n"
    scenario = load_scenario(write(tmp_path, text))
    inertia = scenario.bodies[0].inertia_matrix
    assert (inertia == inertia.T).all()
    from validation.engines.mini.model import build_mini_model

    build_mini_model(scenario)  # the engine accepts what the loader accepted
