"""Mesh files a model names (``validation/scenario/packages.py``): ``package://NAME/path``
found in the model file's folder tree or through ``--package-path NAME=DIR``
(``urdf.PACKAGE_PATHS``), relative paths against the model's folder, MJCF's ``meshdir``; a
mesh that is nowhere is one line at ``models[i].file`` naming it and where it was looked for."""

from __future__ import annotations

from pathlib import Path

import pytest
from test_models import write_scene

from validation.scenario import urdf
from validation.scenario.compiled import compile_scene
from validation.scenario.load import load_scenario
from validation.scenario.packages import resolve
from validation.scenario.problems import ScenarioError
from validation.scenario.urdf import model_path, read_urdf

ROBOT = """<robot name="r">
  <link name="base"><inertial><mass value="1"/>
    <inertia ixx="0.1" iyy="0.1" izz="0.1" ixy="0" ixz="0" iyz="0"/></inertial>
    <visual><geometry><mesh filename="MESH"/></geometry></visual></link>
</robot>
"""
"""One link whose visual mesh is ``MESH``."""


def robot(folder: Path, mesh: str) -> Path:
    """The one-link URDF naming ``mesh``, at ``folder/robot_description/urdf/r.urdf``."""
    path = folder / "robot_description" / "urdf" / "r.urdf"
    path.parent.mkdir(parents=True)
    path.write_text(ROBOT.replace("MESH", mesh))
    return path


def touch(path: Path) -> Path:
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text("solid mesh\nendsolid mesh\n")
    return path


def load(folder: Path, file: Path):
    return load_scenario(write_scene(folder, {"file": file.relative_to(folder).as_posix()}))


def refusal(folder: Path, file: Path) -> str:
    with pytest.raises(ScenarioError) as raised:
        load(folder, file)
    (problem,) = raised.value.problems
    assert problem.path == "models[0].file", str(problem)
    assert "\n" not in str(problem)
    return problem.message


def message_end(message: str) -> str:
    return message.rpartition(", ")[2]


def test_a_package_uri_resolves_in_the_model_files_folder_tree(tmp_path):
    file = robot(tmp_path, "package://robot_description/meshes/base.stl")
    assert "mesh 'package://robot_description/meshes/base.stl' not found" in refusal(tmp_path, file)
    mesh = touch(tmp_path / "robot_description" / "meshes" / "base.stl")
    load(tmp_path, file)
    assert resolve("package://robot_description/meshes/base.stl", file) == mesh.resolve()


def test_a_package_beside_the_model_resolves_as_its_subfolder():
    """pybullet_data's xArm names ``package://xarm_description/...``, a folder beside it."""
    file = model_path("pkg:pybullet_data/xarm/xarm6_robot.urdf", Path("x.yaml"))
    meshes = read_urdf(file).meshes
    assert len(meshes) == 14 and all(m.startswith("package://xarm_description/") for m in meshes)
    for mesh in meshes:
        found = resolve(mesh, file)
        assert found == file.parent / "xarm_description" / mesh.partition("xarm_description/")[2]


def test_a_package_path_flag_resolves_a_package_elsewhere(tmp_path, monkeypatch):
    file = robot(tmp_path, "package://gripper_parts/meshes/finger.stl")
    mesh = touch(tmp_path / "elsewhere" / "meshes" / "finger.stl")
    message = refusal(tmp_path, file)
    assert f"looked for gripper_parts/meshes/finger.stl in {file.parent} and each folder" in message
    assert message.endswith("; give --package-path gripper_parts=DIR")
    monkeypatch.setitem(urdf.PACKAGE_PATHS, "gripper_parts", str(tmp_path / "wrong"))
    wrong = tmp_path / "wrong" / "meshes" / "finger.stl"
    assert message_end(refusal(tmp_path, file)) == f"and at {wrong} (--package-path gripper_parts)"
    monkeypatch.setitem(urdf.PACKAGE_PATHS, "gripper_parts", str(tmp_path / "elsewhere"))
    (layout,) = compile_scene(load(tmp_path, file)).models
    assert layout.package_paths == (("gripper_parts", str(tmp_path / "elsewhere")),)
    assert resolve("package://gripper_parts/meshes/finger.stl", file, layout.package_paths) == mesh


def test_a_relative_mesh_resolves_against_the_model_files_folder(tmp_path):
    file = robot(tmp_path, "../meshes/base.obj")
    message = refusal(tmp_path, file)
    assert f"looked at {file.parent / '../meshes/base.obj'}" in message
    touch(tmp_path / "robot_description" / "meshes" / "base.obj")
    load(tmp_path, file)


SHELL = """<mujoco>
  <compiler meshdir="assets"/>
  <asset><mesh name="hull" file="hull.stl"/></asset>
  <worldbody><body name="hull"><inertial pos="0 0 0" mass="1" diaginertia="1 1 1"/>
    <joint name="turn"/><geom type="mesh" mesh="hull"/></body></worldbody>
</mujoco>
"""
"""An MJCF body with a mesh geom (its mass from the <inertial>), the mesh under ``meshdir``."""


def test_an_mjcf_mesh_resolves_under_its_meshdir(tmp_path):
    (tmp_path / "shell.xml").write_text(SHELL)
    assert "mesh 'assets/hull.stl' not found" in refusal(tmp_path, tmp_path / "shell.xml")
    touch(tmp_path / "assets" / "hull.stl")
    assert [j.name for j in load(tmp_path, tmp_path / "shell.xml").joints] == ["arm/turn"]


def test_a_loaded_scene_is_read_again_without_its_package_paths(tmp_path, monkeypatch):
    """A worker process reads the model again (``CompiledScene.models``, ``with_joint_state``)
    where ``--package-path`` was never set: the meshes were checked when the scene loaded."""
    file = robot(tmp_path, "package://gripper_parts/meshes/finger.stl")
    touch(tmp_path / "elsewhere" / "meshes" / "finger.stl")
    monkeypatch.setitem(urdf.PACKAGE_PATHS, "gripper_parts", str(tmp_path / "elsewhere"))
    scenario = load(tmp_path, file)
    monkeypatch.delitem(urdf.PACKAGE_PATHS, "gripper_parts")
    (layout,) = compile_scene(scenario).models
    assert layout.bodies == ("arm/base",) and layout.package_paths == ()
    moved = urdf.with_joint_state(scenario, {}, {})
    assert [b.name for b in moved.bodies] == ["arm/base"]
