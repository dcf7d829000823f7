"""``physval check`` in one pass: every problem of a file in one run, whatever stage finds it
(the schema, the whole-document rules, definability), and suggestions ("did you mean") that
name something that exists, never the input's own typo (``validation.scenario.load``,
``checks``, ``problems``, ``suggest``; issue 37, item 6)."""

from __future__ import annotations

import re
from pathlib import Path

import pytest

from validation.cli import main
from validation.contract import EXIT_BAD_INPUT
from validation.engine_api import declarations
from validation.scenario.load import check_scenario
from validation.scenario.schema import EXPECTATION_MODELS, METRIC_NAMES, BodySpec

SCENE = """\
dt: 1.0e-3
duration: 1.0
engines: [{engine}]
ground: {{restitution: 0.0, friction: 0.0}}
bodies:
  - name: ball
    shape: {{type: {shape}, radius: 0.1}}
    mass: 1.0
    position: [0, 0, 1]
  - name: link
    shape: {{type: sphere, radius: 0.1}}
    mass: 1.0
    position: [1, 0, 1]
    {field}: [0, 0, 0]
joints:
  - {{name: hinge, type: hinge, parent: world, child: link, anchor: [1, 0, 1], axis: [0, 1, 0]}}
expect:
  - {{kind: {kind}, body: {body}, time: 0.5, value: [0, 0, 0]}}
  - {{kind: joint_position_at, joint: {joint}, time: 0.5, value: 0.0}}
checks:
  {metric}: 1.0e-3
known:
  - {{engine: mini, metric: {known}, reason: measured}}
"""
"""A scene with one slot per kind of name a typo can hit; each is correct by default."""

CORRECT = {
    "engine": "mini",
    "shape": "sphere",
    "field": "velocity",
    "kind": "velocity_at",
    "body": "ball",
    "joint": "hinge",
    "metric": "velocity_at.ball",
    "known": "velocity_at.ball",
}

EXPECTATION_KINDS = [m.model_fields["kind"].annotation.__args__[0] for m in EXPECTATION_MODELS]
DECLARED = declarations()
OPTIONS = {o.name for d in DECLARED.values() for o in d.options}
VALUES = {
    v
    for d in DECLARED.values()
    for o in d.options
    if isinstance(o.accepted, tuple)
    for v in o.accepted
}

EXISTING = {
    "engine": set(DECLARED) | OPTIONS | VALUES,
    "shape": {"sphere", "box", "capsule", "cylinder"},
    "field": set(BodySpec.model_fields),
    "kind": set(EXPECTATION_KINDS),
    "body": {"ball", "link", "world", "ground"},
    "joint": {"hinge"},
    "metric": {*METRIC_NAMES, "velocity_at.ball", "joint_position_at.hinge"},
    "known": {*METRIC_NAMES, "velocity_at.ball", "joint_position_at.hinge", "status"},
}
"""Slot -> the names a suggestion for a typo in it may name: what the scene and physval have."""

TYPOS = [
    ("engine", "mujuco"),
    ("engine", "mini(gyroscopc=implicit)"),
    ("engine", "mini(gyroscopic=implict)"),
    ("shape", "sphre"),
    ("field", "velocty"),
    ("kind", "velocty_at"),
    ("body", "bal"),
    ("joint", "hinje"),
    ("metric", "velocty_at.ball"),
    ("metric", "enrgy_drift"),
    ("known", "enrgy_drift"),
]
"""(slot, typo): one of each kind of name physval suggests for."""

SUGGESTION = re.compile(r"did you mean '([^']*)'\?")


def _problems(tmp_path: Path, **slots: str) -> list[str]:
    path = tmp_path / "scene.yaml"
    path.write_text(SCENE.format(**{**CORRECT, **slots}))
    _, problems = check_scenario(path)
    return [str(p) for p in problems if not p.warning]


def test_the_scene_is_valid_as_written(tmp_path):
    assert _problems(tmp_path) == []


@pytest.mark.parametrize(("slot", "typo"), TYPOS)
def test_a_typo_is_told_an_existing_name_not_itself(tmp_path, slot, typo):
    found = _problems(tmp_path, **{slot: typo})
    suggested = [s for line in found for s in SUGGESTION.findall(line)]
    assert suggested, found
    for name in suggested:
        assert name in EXISTING[slot], (name, found)
        assert name not in typo, (name, found)


def test_a_check_after_a_mistyped_body_is_not_told_the_typo(tmp_path):
    """The issue's case: ``body: bal`` names the expectation ``velocity_at.bal``; the check
    ``velocity_at.ball`` must not be told ``did you mean 'velocity_at.bal'?``."""
    found = _problems(tmp_path, body="bal")
    assert any("expect[0].body" in line and "did you mean 'ball'?" in line for line in found)
    check = [line for line in found if "checks.velocity_at.ball" in line]
    assert check and "did you mean 'velocity_at.bal'" not in check[0], found
    assert "expect[0]'s metric is 'velocity_at.bal'" in check[0], found


ONE_OF_EACH = """\
dt: 1.0e-3
duration: 1.0
engines: [mini]
description: 3
ground: {restitution: 0.0, friction: 0.0}
bodies:
  - name: ball
    shape: {type: sphere, radius: 0.1}
    mass: 1.0
    position: [0, 0, 1]
expect:
  - {kind: velocity_at, body: bal, time: 0.5, value: [0, 0, -3.9]}
  - {kind: position_at, body: ball, time: 0.5, value: fast}
checks:
  angular_momentum_drift: 1.0e-6
  position_at.ball: 1.0e-3
"""
"""A file with one problem of each stage: the schema (a description that is a number, an
expectation's value that is a word), a whole-document rule (an expectation of an unknown
body) and definability (a check on a metric this scene cannot define: the ground pushes)."""

EACH_STAGE = [
    "4:1: description: expected a valid string; got 3",
    "13:",  # expect[1].value: the schema
    "12:25: expect[0].body: expected a body name; got 'bal'; did you mean 'ball'?",
    "15:3: checks.angular_momentum_drift: expected a metric this scene can define",
]


def _one_of_each(tmp_path: Path) -> Path:
    path = tmp_path / "scene.yaml"
    path.write_text(ONE_OF_EACH)
    return path


def _assert_every_stage(err: str) -> None:
    lines = err.splitlines()
    for expected in EACH_STAGE:
        assert sum(expected in line for line in lines) == 1, (expected, lines)
    assert "expect[1].value:" in err, err
    # the check of the left-out expectation's metric is its entry's problem, not another one
    assert "checks.position_at.ball" not in err, err


def test_check_prints_every_stage_in_one_pass(tmp_path, capsys):
    assert main(["check", str(_one_of_each(tmp_path))]) == EXIT_BAD_INPUT
    _assert_every_stage(capsys.readouterr().err)


def test_run_refuses_with_every_stage_up_front(tmp_path, capsys):
    out = tmp_path / "out"
    code = main(["run", str(_one_of_each(tmp_path)), "--engines", "mini", "--out", str(out)])
    assert code == EXIT_BAD_INPUT
    _assert_every_stage(capsys.readouterr().err)
    assert not out.exists()


def test_a_left_out_body_is_no_unknown_name(tmp_path):
    """A body that fails the schema is left out of the rules, but its name still exists: the
    expectation and the spring naming it are not reported, the other typo is."""
    found = _problems(tmp_path, shape="sphre")
    assert any("bodies[0].shape.type" in line for line in found), found
    assert not any("got 'ball'" in line for line in found), found


@pytest.mark.parametrize(
    ("slot", "typo", "reported"),
    [
        ("shape", "sphre", "expect[1].joint"),  # a scene part left out; the names still judged
        ("kind", "velocty_at", "expect[1].joint"),
        ("field", "velocty", "expect[1].joint"),
    ],
)
def test_a_schema_problem_does_not_hold_back_a_name_problem(tmp_path, slot, typo, reported):
    found = _problems(tmp_path, **{slot: typo, "joint": "hinje"})
    assert any(f"{reported}: expected a joint name; got 'hinje'" in line for line in found), found


def test_a_model_that_fails_does_not_hold_back_the_rest(tmp_path):
    """A model file that cannot be read leaves its bodies unknown (no reference is judged),
    but the rest of the file is: a duplicate engine here."""
    path = tmp_path / "scene.yaml"
    path.write_text(
        "dt: 1.0e-3\nduration: 1.0\nengines: [mini, mini]\n"
        "models:\n  - {name: arm, file: missing.urdf}\n"
        "expect:\n  - {kind: velocity_at, body: link1, time: 0.5, value: [0, 0, 0]}\n"
    )
    _, problems = check_scenario(path)
    found = [str(p) for p in problems]
    assert any("models[0]" in line for line in found), found
    assert any("engine 'mini' is listed twice" in line for line in found), found
    assert not any("expect[0].body" in line for line in found), found


def test_the_scene_rules_wait_for_a_whole_scene(tmp_path, capsys):
    """With a body left out the scene is another one: its definability is not judged (it
    would be of a scene without the ball), the names still are."""
    path = tmp_path / "scene.yaml"
    path.write_text(ONE_OF_EACH.replace("radius: 0.1", "radius: -0.1"))
    assert main(["check", str(path)]) == EXIT_BAD_INPUT
    err = capsys.readouterr().err
    assert "bodies[0].shape.radius: expected greater than 0" in err, err
    assert "expect[0].body: expected a body name; got 'bal'" in err, err
    assert "angular_momentum_drift" not in err, err
