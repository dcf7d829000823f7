"""Joints in the scene format: what the loader accepts, what it refuses (each problem at its
joint's line, naming the field), and the one tree built from a scene.
"""

from __future__ import annotations

import textwrap
from pathlib import Path

import numpy as np
import pytest

from validation.engine_api import Capabilities
from validation.reference.articulated import WORLD, forward_kinematics
from validation.scenario import ScenarioError, load_scenario
from validation.scenario.joints import JOINT_STATE_TOLERANCE, joint_tree
from validation.scenario.needs import missing

PENDULUM = """\
dt: 0.001
duration: 1.0
bodies:
  - {name: upper, shape: {type: box, half_extents: [0.02, 0.02, 0.25]}, mass: 1.0, position: [0, 0, 1.75]}
  - {name: lower, shape: {type: sphere, radius: 0.05}, mass: 2.0, position: [0, 0, 1.3]}
joints:
  - {name: shoulder, type: hinge, parent: world, child: upper, anchor: [0, 0, 2.0], axis: [0, 1, 0]}
  - {name: elbow, type: ball, parent: upper, child: lower, anchor: [0, 0, 1.5]}
"""


def write(tmp_path: Path, text: str) -> Path:
    path = tmp_path / "scene.yaml"
    path.write_text(textwrap.dedent(text))
    return path


def problems(tmp_path: Path, text: str) -> list[str]:
    with pytest.raises(ScenarioError) as caught:
        load_scenario(write(tmp_path, text))
    return [str(problem) for problem in caught.value.problems]


def test_a_double_pendulum_loads_and_builds_its_tree(tmp_path):
    scenario = load_scenario(write(tmp_path, PENDULUM))
    assert [j.name for j in scenario.joints] == ["shoulder", "elbow"]
    assert scenario.joints[0].damping == 0.0 and scenario.joints[1].axis is None
    tree = joint_tree(scenario)
    assert [(j.type, j.parent, j.child) for j in tree.joints] == [
        ("hinge", WORLD, 0),
        ("ball", 0, 1),
    ]
    assert tree.nq == 1 + 4 and tree.nv == 1 + 3
    pose = forward_kinematics(tree, tree.zero())
    stated = np.array([b.position for b in scenario.bodies])
    assert np.allclose(pose.pos, stated, atol=1e-15), pose.pos


def test_a_scene_without_joints_has_no_tree(tmp_path):
    text = PENDULUM.split("joints:")[0]
    assert joint_tree(load_scenario(write(tmp_path, text))) is None


CASES = {
    "duplicate name": (
        ("name: elbow,", "name: shoulder,"),
        "joints[1].name: expected a unique joint name; 'shoulder' is taken",
    ),
    "unknown parent": (
        ("parent: upper,", "parent: uper,"),
        "joints[1].parent: expected one of ['lower', 'upper', 'world']; got 'uper'",
    ),
    "unknown child": (("child: lower,", "child: lowr,"), "joints[1].child: expected one of"),
    "child is its parent": (("child: lower,", "child: upper,"), "expected a body other than"),
    "two parents": (
        ("parent: upper, child: lower", "parent: world, child: upper"),
        "'upper' already hangs from 'world'",
    ),
    "hinge without axis": (("axis: [0, 1, 0]}", "}"), "joints[0].axis: expected a unit axis"),
    "ball with axis": (
        ("anchor: [0, 0, 1.5]}", "anchor: [0, 0, 1.5], axis: [1, 0, 0]}"),
        "joints[1].axis: expected no axis for a ball joint",
    ),
    "axis not unit": (("axis: [0, 1, 0]", "axis: [0, 2, 0]"), "expected a unit axis [x, y, z]"),
    "limits not bracketing 0": (
        ("axis: [0, 1, 0]}", "axis: [0, 1, 0], limits: [0.1, 0.5]}"),
        "lower <= 0 <= upper",
    ),
    "limits on a ball": (
        ("anchor: [0, 0, 1.5]}", "anchor: [0, 0, 1.5], limits: [-1, 1]}"),
        "expected no limits for a ball joint",
    ),
    "a moving anchor": (
        ("position: [0, 0, 1.3]}", "position: [0, 0, 1.3], velocity: [0, 0.5, 0]}"),
        "joints[1]: expected the bodies' stated velocities to keep the ball joint at t = 0; "
        "the anchor's slip (m/s) is 0.5",
    ),
    "a spin off the hinge's axis": (
        ("position: [0, 0, 1.75]}", "position: [0, 0, 1.75], angular_velocity: [0.1, 0, 0]}"),
        "the spin off the axis (rad/s) is 0.1",
    ),
}
"""Case -> (text replaced in ``PENDULUM``, the problem it must raise)."""


@pytest.mark.parametrize("case", sorted(CASES))
def test_a_broken_joint_is_one_problem_at_its_field(case, tmp_path):
    (old, new), expected = CASES[case]
    assert old in PENDULUM, case
    found = problems(tmp_path, PENDULUM.replace(old, new, 1))
    assert any(expected in problem for problem in found), found
    assert all("scene.yaml:" in problem for problem in found), found


def test_a_loop_of_joints_is_refused_with_its_cycle(tmp_path):
    text = PENDULUM.replace("parent: world, child: upper", "parent: lower, child: upper")
    found = problems(tmp_path, text)
    assert any("close a loop upper -> lower -> upper" in p for p in found), found


def test_velocities_the_joints_allow_load(tmp_path):
    """The shoulder turning at 2 rad/s about y: the upper bar's centre 0.25 m below the pivot
    moves at ω × r, and the lower ball (on the ball joint, turning with it) at ω × r too."""
    text = PENDULUM.replace(
        "position: [0, 0, 1.75]}",
        "position: [0, 0, 1.75], velocity: [-0.5, 0, 0], angular_velocity: [0, 2, 0]}",
    ).replace(
        "position: [0, 0, 1.3]}",
        "position: [0, 0, 1.3], velocity: [-1.4, 0, 0], angular_velocity: [0, 2, 0]}",
    )
    load_scenario(write(tmp_path, text))
    off = text.replace(
        "velocity: [-1.4, 0, 0]", f"velocity: [-1.4, 0, {20 * JOINT_STATE_TOLERANCE}]"
    )
    assert any("anchor's slip" in p for p in problems(tmp_path, off))


def test_an_engine_without_joints_is_told_so(tmp_path):
    scenario = load_scenario(write(tmp_path, PENDULUM))
    lacking = missing(Capabilities(), scenario)
    assert lacking == {"joints": "2 joint(s), the first 'shoulder' (hinge)"}, lacking
