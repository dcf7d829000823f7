"""Joint friction in tier 1 (issue 36): physval's readers read a model file's joint dry
friction (URDF ``<dynamics friction>``, MJCF ``frictionloss``) into ``ModelLayout.frictions``
(the scene's joints have none), and ``model_fields`` compares each engine's with it: MuJoCo,
which reads it as ``frictionloss``, agrees; an engine that drops it shows "friction differs"."""

from __future__ import annotations

import dataclasses
from pathlib import Path

import numpy as np
import pybullet
import pytest
import yaml

from validation.engines.mujoco.adapter import MujocoAdapter
from validation.engines.mujoco.native import joint_friction
from validation.engines.pybullet.models import HELD_FRICTION
from validation.measure.tiers import model_fields, scene_joint_report
from validation.scenario.compiled import compile_scene
from validation.scenario.engine_spec import parse_engine_spec
from validation.scenario.load import load_scenario
from validation.scenario.urdf import model_path

PENDULUM = "pkg:pybullet_data/pendulum5.urdf"
FILE_FRICTION = 1.0
"""N·m: pendulum5.urdf's ``<dynamics friction>`` on each of its five joints."""

AGREEMENT = 1e-12
"""Relative: MuJoCo's ``dof_frictionloss`` is the file's number as written (1.0 exactly)."""

MJCF_FRICTION = """<mujoco>
  <default><joint frictionloss="0.25"/></default>
  <worldbody>
    <body name="arm" pos="0 0 1">
      <joint name="pin" type="hinge" axis="0 1 0"/>
      <geom type="capsule" fromto="0 0 0 0 0 -0.5" size="0.05"/>
      <body name="forearm" pos="0 0 -0.5">
        <joint name="elbow" type="hinge" axis="0 1 0" frictionloss="0.5"/>
        <geom type="sphere" pos="0 0 -0.2" size="0.05"/>
      </body>
    </body>
  </worldbody>
</mujoco>
"""


def pendulum_scene(folder: Path, file: str = PENDULUM, engines=("mujoco",)):
    document = {
        "dt": 0.001,
        "duration": 0.2,
        "engines": list(engines),
        "models": [{"name": "p", "file": file, "joint_positions": {}}],
    }
    path = folder / "pendulum.yaml"
    path.write_text(yaml.safe_dump(document, sort_keys=False))
    return compile_scene(load_scenario(path))


def test_the_urdf_reader_keeps_the_files_joint_friction_beside_the_frictionless_joints(tmp_path):
    scene = pendulum_scene(tmp_path)
    (layout,) = scene.models
    assert layout.frictions == (FILE_FRICTION,) * 5
    assert [layout.friction(name) for name in layout.joints] == [FILE_FRICTION] * 5
    assert "friction" not in scene.scenario.joints[0].model_dump()  # physval's joints have none
    assert scene_joint_report(scene).friction.tolist() == [FILE_FRICTION] * 5


def test_the_mjcf_reader_reads_frictionloss_with_its_defaults(tmp_path):
    (tmp_path / "arm.xml").write_text(MJCF_FRICTION)
    scene = pendulum_scene(tmp_path, file="arm.xml")
    (layout,) = scene.models
    assert dict(zip(layout.joints, layout.frictions, strict=True)) == {
        "p/pin": 0.25,
        "p/elbow": 0.5,
    }


def test_tier_one_names_a_dropped_friction_and_mujoco_agrees(tmp_path):
    scene = pendulum_scene(tmp_path)
    adapter = MujocoAdapter(parse_engine_spec("mujoco"))  # native: MuJoCo's URDF importer
    adapter.load(scene)
    model, joints = adapter.model_report(), adapter.joint_report()
    held = joint_friction(adapter.model, scene.scenario)
    assert held == pytest.approx([FILE_FRICTION] * 5, rel=AGREEMENT)
    agreed = model_fields(scene, model, dataclasses.replace(joints, friction=held))
    assert "friction" not in agreed.message, agreed
    dropped = model_fields(scene, model, dataclasses.replace(joints, friction=None))
    assert dropped.message.startswith("joint p/joint"), dropped.message
    assert "friction differs by 1.00e+00 (relative; engine 0, file 1)" in dropped.message


def _swing(file: str) -> list[float]:
    """PyBullet's joint angles after 1 s of a released swing of ``file``."""
    client = pybullet.connect(pybullet.DIRECT)
    try:
        body = pybullet.loadURDF(file, useFixedBase=True, physicsClientId=client)
        joints = list(range(pybullet.getNumJoints(body, physicsClientId=client)))
        pybullet.setJointMotorControlArray(
            body, joints, pybullet.VELOCITY_CONTROL, forces=[0.0] * len(joints),
            physicsClientId=client,
        )  # fmt: skip
        pybullet.setGravity(0, 0, -9.81, physicsClientId=client)
        pybullet.resetJointState(body, 0, 0.3, physicsClientId=client)
        for _ in range(240):
            pybullet.stepSimulation(physicsClientId=client)
        return [pybullet.getJointState(body, j, physicsClientId=client)[0] for j in joints]
    finally:
        pybullet.disconnect(client)


def test_pybullets_step_drops_the_files_joint_friction(tmp_path):
    """``HELD_FRICTION``'s measurement: the same swing with the file's friction and with none."""
    text = model_path(PENDULUM, tmp_path).read_text()
    frictionless = tmp_path / "pendulum0.urdf"
    frictionless.write_text(text.replace('friction="1.0"', 'friction="0"'))
    assert text.count('friction="1.0"') == 5
    assert HELD_FRICTION == 0.0
    assert np.array_equal(_swing(str(model_path(PENDULUM, tmp_path))), _swing(str(frictionless)))


def test_drakes_parser_drops_the_files_joint_friction(tmp_path):
    """``HELD_FRICTION``'s source: Drake's parser says it drops the friction (the provenance)."""
    from validation.engines.drake.adapter import DrakeAdapter
    from validation.engines.drake.models import HELD_FRICTION as DRAKE_FRICTION

    adapter = DrakeAdapter(parse_engine_spec("drake"))
    adapter.load(pendulum_scene(tmp_path, engines=("drake",)))
    (model,) = adapter.models
    dropped = [
        w for w in model.warnings if "does not currently support non-zero joint friction" in w
    ]
    assert len(dropped) == 5 and DRAKE_FRICTION == 0.0
