"""``physval check`` in one pass: every problem of a file in one run, whatever stage finds it
(the schema, the whole-document rules, definability), and suggestions ("did you mean") that
name something that exists, never the input's own typo (``validation.scenario.load``,
``checks``, ``problems``, ``suggest``; issue 37, item 6)."""

from __future__ import annotations

import re
from pathlib import Path

import pytest

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
