"""Drake's native loader for a scene's ``models`` (issue 36; docs/engines-drake.md 10): the
Kuka iiwa, the cartpole, the A1 quadruped and the five-link pendulum of pybullet_data (URDF)
and its inverted double pendulum (MJCF, at the origin and placed) read by Drake's own
``Parser`` hold the masses, inertias, joints and start state physval's reading of the same
files states, and their mass matrix, bias forces and link poses equal the reference side's at
random states; so do a URDF chain and an MJCF with a floating root, and the Kuka beside bodies
and a joint of the scene's own; both profiles. A 1 s passive swing runs through ``physval
run`` with both loaders. The loader function itself: collisions, MJCF details (gravity,
masses from geoms, armature), ``package://`` and reflected inertia. One adapter per scene and
spec for the whole module (it runs in about 5 s). pydrake is a test dependency
(``tests/test_engine_drake.py``)."""

from __future__ import annotations

import dataclasses
import math
from pathlib import Path

import numpy as np
import pytest
from test_models import CHAIN  # every origin and inertial frame turned

from validation.cli import main
from validation.engines import joint_parity
from validation.engines.drake.models import add_models
from validation.engines.parity import compare
from validation.engines.reference import reference_report
from validation.engines.registry import create_adapter
from validation.reference.articulated import (
    Loads,
    bias_forces,
    forward_kinematics,
    mass_matrix,
)
from validation.scenario.compiled import compile_scene
from validation.scenario.engine_spec import parse_engine_spec
from validation.scenario.load import load_scenario
from validation.scenario.urdf import Frame

KUKA = "pkg:pybullet_data/kuka_iiwa/model.urdf"
CARTPOLE = "pkg:pybullet_data/cartpole.urdf"
A1 = "pkg:pybullet_data/a1/a1.urdf"
PENDULUM5 = "pkg:pybullet_data/pendulum5.urdf"
PENDULUM = "pkg:pybullet_data/mjcf/inverted_double_pendulum.xml"

NATIVE = "drake"
PHYSVAL = "drake(model_loader=physval)"
CONTINUOUS = "drake(profile=continuous)"

TURN = (math.cos(0.2), 0.0, 0.0, math.sin(0.2))  # 0.4 rad about z
PENDULUM_START = {"pend/slider": 0.2, "pend/hinge": 0.3, "pend/hinge2": -0.4}
PENDULUM_RATES = {"pend/slider": -0.1, "pend/hinge": 0.6}

FREE_MJCF = """<mujoco model="free"><worldbody>
  <body name="torso" pos="0 0 1" euler="10 20 30"><freejoint name="root"/>
    <geom type="box" size="0.1 0.2 0.3"/>
    <body name="arm" pos="0.2 0 0"><joint name="shoulder" axis="0 1 0" damping="0.1"/>
      <geom type="capsule" fromto="0 0 0 0.3 0 0" size="0.03"/>
      <body name="hand" pos="0.3 0 0" quat="0.9 0.1 0.2 0">
        <geom type="box" size="0.05 0.02 0.03"/></body></body></body></worldbody></mujoco>
"""
"""An MJCF rooted at one free top-level body (its own pose in the file is not the model's),
a hinge, and a jointless body (welded: the scene joint ``f/hand.weld`` the file does not
name)."""
TILT = (math.cos(0.1), 0.0, math.sin(0.1), 0.0)  # 0.2 rad about y

FREE_ENTRY = {
    "name": "f",
    "file": "free.xml",
    "position": [0.5, 0.0, 2.0],
    "orientation": list(TILT),
    "joint_positions": {"f/shoulder": 0.4},
    "joint_velocities": {"f/shoulder": -0.7},
}
"""The free-rooted MJCF's entry (``FREE_MJCF``), welded at its pose unless it floats."""

MODELS = {
    "kuka": {
        "name": "arm",
        "file": KUKA,
        "position": [0.3, -0.2, 1.0],
        "orientation": list(TURN),
        "joint_positions": {"arm/lbr_iiwa_joint_2": 0.5, "arm/lbr_iiwa_joint_4": -0.7},
        "joint_velocities": {"arm/lbr_iiwa_joint_1": 0.3, "arm/lbr_iiwa_joint_5": -0.4},
    },
    "cartpole": {
        "name": "cp",
        "file": CARTPOLE,
        "position": [0.0, 0.0, 1.0],
        "joint_positions": {"cp/cart_to_pole": 0.4},
        "joint_velocities": {"cp/slider_to_cart": 0.2, "cp/cart_to_pole": -0.3},
    },
    "a1": {
        "name": "a1",
        "file": A1,
        "position": [0.0, 0.0, 1.0],
        "joint_positions": {
            "a1/FR_upper_joint": 0.5,
            **{f"a1/{leg}_lower_joint": -1.5 for leg in ("FR", "FL", "RR", "RL")},
        },
        "joint_velocities": {"a1/FL_hip_joint": 0.4, "a1/RR_upper_joint": -1.2},
    },
    "pendulum5": {
        "name": "p",
        "file": PENDULUM5,
        "position": [0.0, 0.5, 2.0],
        "orientation": list(TILT),
        "joint_positions": {"p/joint1": 0.6, "p/joint3": -0.4},
        "joint_velocities": {"p/joint0": 0.5},
    },
    "pendulum": {
        "name": "pend",
        "file": PENDULUM,
        "joint_positions": PENDULUM_START,
        "joint_velocities": PENDULUM_RATES,
    },
    "pendulum_placed": {
        "name": "pend",
        "file": PENDULUM,
        "position": [1.0, 2.0, 3.0],
        "orientation": list(TURN),
        "joint_positions": PENDULUM_START,
        "joint_velocities": PENDULUM_RATES,
    },
    "free_mjcf": {**FREE_ENTRY, "fixed_base": False},
    "welded_mjcf": FREE_ENTRY,
    "floating_chain": {
        "name": "c",
        "file": "chain.urdf",
        "position": [0.1, 0.2, 1.0],
        "orientation": list(TILT),
        "fixed_base": False,
        "joint_positions": {"c/pin": 0.3, "c/rail": 0.1},
        "joint_velocities": {"c/pin": 0.5, "c/rail": -0.2},
    },
}
"""The scenes (one model each): the Kuka on a turned base at a pose with joint rates, the
cartpole (a massless root link: its slider hangs from the world) swinging, the A1 quadruped
(a trunk with mass welded to the world, massive links on fixed joints; its knees' limits do
not hold 0, so they start bent), the five-link pendulum (its root link is named ``world``,
which Drake's parser would take for its own world), the MJCF inverted double pendulum at the
origin and away from it (Drake's MJCF parser hangs its bodies from Drake's world), an MJCF with
a free root floating and welded, the chain floating from a tilted pose."""

SAME_MODEL = 1e-9
"""Relative (the parity gate's ``PARITY_TOLERANCE``): Drake's reading of a model file against
physval's. Measured 2.2e-16 m (COM), 4.4e-16 kg·m² (inertia) and 0 kg (mass) over the scenes
here: both read the same decimal numbers and compose the same transforms."""

ROUND_OFF = 1e-12
"""Relative or m: Drake's M, bias and link poses at one state against the reference side's
(composite rigid body, Newton-Euler, forward kinematics in double precision): measured at
most 1.2e-15 (M), 1.0e-15 (bias) and 1.3e-15 m (poses) over the scenes here; physval-built,
8.5e-12 (``SAME_MODEL`` bounds those)."""

STATES = 4
"""Random joint states probed per model (seeded)."""

SWUNG = ("kuka", "cartpole", "pendulum_placed")
"""The scenes of the passive swing through ``physval run``."""

SWING_AGREEMENT = 1e-9
"""m: the native and the physval-built models over a 1 s swing at dt = 1 ms (the run's
``divergence``): measured 4.7e-12 m on the Kuka (4.0e-16 the cartpole, 5.6e-15 the placed
pendulum), the round-off of two equal models' floats (physval's bodies carry the file's
frames through a quaternion and back) grown over 1000 steps."""


def write_scene(folder: Path, key: str, engines=(NATIVE,), duration: float = 1.0) -> Path:
    """A scene of one model (``MODELS[key]``) in ``folder``, 1 s at dt = 1 ms."""
    import yaml

    (folder / "chain.urdf").write_text(CHAIN)
    (folder / "free.xml").write_text(FREE_MJCF)
    path = folder / f"{key}.yaml"
    document = {"dt": 1e-3, "duration": duration, "engines": list(engines)}
    path.write_text(yaml.safe_dump({**document, "models": [MODELS[key]]}, sort_keys=False))
    return path


def write_mixed_scene(folder: Path, kuka) -> Path:
    """The Kuka scene (``kuka``, its loaded scenario) with two bodies of the scene's own: a
    ball thrown free, and a bob hinged below the arm's last link (a scene joint whose parent
    is a model's body), moving with it at t = 0."""
    import yaml

    tip = next(b for b in kuka.bodies if b.name == "arm/lbr_iiwa_link_7")
    anchor, spin = np.array(tip.position), np.array(tip.angular_velocity)
    bob = anchor - [0.0, 0.0, 0.3]
    document = yaml.safe_load(write_scene(folder, "kuka").read_text())
    document["bodies"] = [
        {"name": "ball", "shape": {"type": "sphere", "radius": 0.05}, "mass": 0.5,
         "position": [2.0, 0.0, 1.0], "velocity": [0.1, 0.2, 0.3],
         "angular_velocity": [0.5, 0.0, 0.0]},
        {"name": "bob", "shape": {"type": "sphere", "radius": 0.03}, "mass": 0.3,
         "position": bob.tolist(), "angular_velocity": spin.tolist(),
         "velocity": (np.array(tip.velocity) + np.cross(spin, bob - anchor)).tolist()},
    ]  # fmt: skip
    document["joints"] = [{"name": "swing", "type": "hinge", "parent": tip.name,
                           "child": "bob", "anchor": anchor.tolist(), "axis": [1, 0, 0]}]  # fmt: skip
    path = folder / "mixed.yaml"
    path.write_text(yaml.safe_dump(document, sort_keys=False))
    return path


MIXED = "kuka_and_bodies"
SCENES = (*MODELS, MIXED)
"""Every scene tested: one per model, and the Kuka with bodies and a joint of the scene's
own (``write_mixed_scene``)."""


@pytest.fixture(scope="module")
def scenes(tmp_path_factory) -> dict:
    folder = tmp_path_factory.mktemp("drake_models")
    found = {key: compile_scene(load_scenario(write_scene(folder, key))) for key in MODELS}
    mixed = write_mixed_scene(folder, found["kuka"].scenario)
    return {**found, MIXED: compile_scene(load_scenario(mixed))}


@pytest.fixture(scope="module")
def loaded(scenes):
    """(model, spec) -> an adapter loaded with that scene: one per pair for the module."""
    adapters = {}

    def get(key: str, spec: str = NATIVE):
        if (key, spec) not in adapters:
            adapter = create_adapter(parse_engine_spec(spec))
            adapter.load(scenes[key])
            adapters[key, spec] = adapter
        return adapters[key, spec]

    yield get
    for adapter in adapters.values():
        adapter.close()


PROFILES = (NATIVE, CONTINUOUS)
CASES = [(key, spec) for key in SCENES for spec in PROFILES]


@pytest.mark.parametrize(("key", "spec"), CASES)
def test_native_model_report_is_the_scenes(scenes, loaded, key, spec):
    """Mass, centre of mass and world inertia of every body, the energy and momenta: Drake's
    reading of the file is physval's (the parity gate's comparison finds nothing)."""
    adapter, scene = loaded(key, spec), scenes[key]
    report, expected = adapter.model_report(), reference_report(scene)
    assert compare(report, expected) == []
    assert np.abs(report.com - expected.com).max() <= SAME_MODEL
    assert (
        np.abs(report.inertia_world - expected.inertia_world).max()
        <= SAME_MODEL * np.abs(expected.inertia_world).max()
    )
    settings = adapter.provenance().settings
    assert settings["model_loader"] == "native"
    assert list(settings["models"]) == [layout.name for layout in scene.models]


@pytest.mark.parametrize(("key", "spec"), CASES)
def test_native_joint_report_is_the_scenes(scenes, loaded, key, spec):
    """Types, anchors, axes and M(q0) as the joint parity gate checks them, and the limits
    (relative to t = 0), damping and armature as the scene states them."""
    adapter, scene = loaded(key, spec), scenes[key]
    assert joint_parity.compare_joints(adapter, scene) == []
    report = adapter.joint_report()
    stated = scene.scenario.joints
    limits = np.array([j.limits if j.limits else (np.nan, np.nan) for j in stated])
    np.testing.assert_allclose(report.limits, limits, rtol=0, atol=SAME_MODEL)
    np.testing.assert_array_equal(report.damping, [j.damping for j in stated])
    np.testing.assert_array_equal(report.armature, np.zeros(len(stated)))


def test_the_kukas_limits_move_with_its_start_and_its_damping_is_the_urdfs(loaded):
    report = loaded("kuka").joint_report()
    # joint_2's URDF limits ±2.09439510239 rad, its start 0.5 rad (MODELS)
    assert report.limits[1] == pytest.approx((-2.09439510239 - 0.5, 2.09439510239 - 0.5))
    assert np.all(report.damping == 0.5)  # model.urdf: <dynamics damping="0.5"/>


@pytest.mark.parametrize(("key", "spec"), CASES)
def test_native_start_is_the_scenes(scenes, loaded, key, spec):
    """observe() at t = 0: every model body's centre, axes, velocity and spin as the scene
    states them (a link's pose carried to its inertial frame, the joints' rates set)."""
    start, stated = loaded(key, spec).observe(), scenes[key].start
    assert np.abs(start.pos - stated.pos[0]).max() <= ROUND_OFF
    same_axes = np.abs(np.einsum("ni,ni->n", start.quat, stated.quat[0]))
    assert np.abs(same_axes - 1.0).max() <= ROUND_OFF
    assert np.abs(start.vel - stated.vel[0]).max() <= ROUND_OFF
    assert np.abs(start.ang_vel - stated.ang_vel[0]).max() <= ROUND_OFF
    assert np.abs(stated.ang_vel[0]).max() >= 0.3  # the rates are really there to get wrong


@pytest.mark.parametrize("spec", [NATIVE, CONTINUOUS, PHYSVAL])
@pytest.mark.parametrize("key", SCENES)
def test_model_probe_is_the_reference_sides(scenes, loaded, key, spec):
    """M(q), the bias C(q, ν)ν + g(q) and every body's pose at seeded random states (tree
    coordinates, relative to t = 0) against the reference side's."""
    adapter, scene = loaded(key, spec), scenes[key]
    tree = scene.joint_tree
    loads = Loads(scene.gravity, scene.springs, scene.force, scene.torque)
    rng = np.random.default_rng(36)
    for _ in range(STATES):
        q = tree.zero() + rng.uniform(-1.0, 1.0, tree.nq)
        for joint in tree.joints:
            if joint.type == "free":
                q[joint.q_slice][3:] /= np.linalg.norm(q[joint.q_slice][3:])
        nu = rng.uniform(-2.0, 2.0, tree.nv)
        probe = adapter.model_probe(q, nu)
        want_m, want_b = mass_matrix(tree, q), bias_forces(tree, q, nu, loads)
        pose = forward_kinematics(tree, q)
        tolerance = ROUND_OFF if spec != PHYSVAL else SAME_MODEL
        assert np.abs(probe.mass_matrix - want_m).max() <= tolerance * np.abs(want_m).max()
        assert np.abs(probe.bias - want_b).max() <= tolerance * np.abs(want_b).max()
        assert np.abs(probe.pos - pose.pos).max() <= tolerance
        turned = np.einsum("nij,nik->njk", pose.rot, _matrices(probe.quat))
        assert np.abs(turned - np.eye(3)).max() <= tolerance


def _matrices(quat: np.ndarray) -> np.ndarray:
    from validation.reference.rotation import quat_to_matrix

    return np.array([quat_to_matrix(q) for q in quat])


def test_the_probe_leaves_the_simulation_where_it_was(loaded):
    adapter = loaded("cartpole")
    before = adapter.observe()
    tree = adapter.tree
    adapter.model_probe(tree.zero() + 0.5, np.ones(tree.nv))
    after = adapter.observe()
    np.testing.assert_array_equal(after.pos, before.pos)
    np.testing.assert_array_equal(after.vel, before.vel)


def test_physval_loading_builds_the_expanded_bodies(loaded):
    settings = loaded("kuka", PHYSVAL).provenance().settings
    assert settings["model_loader"] == "physval"
    assert "models" not in settings
    assert "arm/lbr_iiwa_joint_2" in settings["joints"]  # physval's joint, by its scene name


def test_the_parsers_warnings_are_in_the_provenance(loaded):
    """Kuka's lbr_iiwa_link_0 states mass 0 with an inertia: Drake's parser says it cannot
    make that a central inertia (docs/engines-drake.md 10)."""
    notes = loaded("kuka").provenance().notes
    assert any("model arm: Drake's parser" in note and "mass > 0" in note for note in notes)
    assert any("without its <collision> and <visual>" in note for note in notes)


def test_a_passive_swing_runs_with_both_loaders(tmp_path):
    """``physval run`` of the Kuka, the cartpole and the MJCF pendulum (placed) for 1 s in
    Drake with its own parser and with physval's bodies: every row ``ok``, and the two swings
    agree (``divergence``)."""
    import pandas as pd

    paths = [str(write_scene(tmp_path, key, engines=(NATIVE, PHYSVAL))) for key in SWUNG]
    out = tmp_path / "run"
    history = f"sqlite:///{tmp_path / 'history.sqlite'}"
    assert main(["run", *paths, "--out", str(out), "--history", history, "--jobs", "1"]) == 0
    rows = pd.read_csv(out / "results.csv")
    assert set(rows["status"]) == {"ok"}
    assert set(rows["engine"]) == {NATIVE, PHYSVAL}
    divergence = rows[rows["metric"] == "divergence"]
    assert len(divergence) == len(SWUNG)
    assert divergence["value"].max() <= SWING_AGREEMENT
    assert rows[rows["metric"] == "joint_violation"]["value"].max() <= ROUND_OFF


# --- the loader itself: collisions, MJCF details, package://, armature -------------------


def _plant():
    from pydrake.multibody.plant import AddMultibodyPlantSceneGraph
    from pydrake.systems.framework import DiagramBuilder

    return AddMultibodyPlantSceneGraph(DiagramBuilder(), 1e-3)


def _proximity(scene_graph) -> list:
    from pydrake.geometry import Role

    return scene_graph.model_inspector().GetAllGeometryIds(Role.kProximity)


def test_collisions_true_keeps_the_files_shapes_and_false_registers_none(scenes):
    """The cartpole's two ``<collision>`` boxes: registered and colliding with collisions:
    true, not registered with false (the URDF is parsed without them)."""
    from validation.engines.drake.models import add_models, filter_model_geometry

    layout = scenes["cartpole"].models[0]
    for collides, count in ((True, 2), (False, 0)):
        plant, scene_graph = _plant()
        spec = layout.spec.model_copy(update={"collisions": collides})
        add_models(plant, scene_graph, [dataclasses.replace(layout, spec=spec)], (0, 0, -9.81))
        plant.Finalize()
        assert filter_model_geometry(scene_graph, []) == 0
        assert len(_proximity(scene_graph)) == count


def test_drake_refuses_the_kukas_stl_collision_meshes(scenes):
    """With collisions: true Drake must make a convex hull of each collision mesh, and its
    hull reads .obj, .vtk and .gltf only: the Kuka's .stl meshes are an error (a result row,
    under the runner), named."""
    from validation.engines.drake.models import add_models

    layout = scenes["kuka"].models[0]
    spec = layout.spec.model_copy(update={"collisions": True})
    plant, scene_graph = _plant()
    with pytest.raises(RuntimeError, match=r"unsupported extension '\.stl'"):
        add_models(plant, scene_graph, [dataclasses.replace(layout, spec=spec)], (0, 0, -9.81))


@pytest.fixture(scope="module")
def pendulum(scenes):
    """(plant, scene_graph, model, context, filtered) of the MJCF pendulum's layout (physval's
    reading) loaded by ``add_models`` alone, under a gravity the file does not state."""
    from validation.engines.drake.models import filter_model_geometry, model_velocities

    plant, scene_graph = _plant()
    layout = scenes["pendulum"].models[0]
    (model,) = add_models(plant, scene_graph, [layout], (0.0, 0.0, -9.0))
    plant.Finalize()
    filtered = filter_model_geometry(scene_graph, [model])
    context = plant.CreateDefaultContext()
    model_velocities(plant, context, [model])
    return plant, scene_graph, model, context, filtered


def test_an_mjcf_models_joints_and_state_are_the_files_and_the_scenes(pendulum):
    from validation.engines.drake.joints import Placement, body_states

    plant, _, model, context, _ = pendulum
    types = {name: joint.type_name() for name, joint in model.joints.items()}
    assert types == {"pend/slider": "prismatic", "pend/hinge": "revolute",
                     "pend/hinge2": "revolute"}  # fmt: skip
    for name, joint in model.joints.items():
        assert joint.GetOnePosition(context) == PENDULUM_START[name]
        assert joint.GetOneVelocity(context) == PENDULUM_RATES.get(name, 0.0)
        assert joint.default_damping_vector()[0] == 0.05  # <default><joint damping="0.05"/>
    # the pole's centre: on the cart at the slider's 0.2 m, 0.3 m up the pole turned 0.3 rad
    # about y (x = 0.2 + 0.3 sin 0.3, z = 0.3 cos 0.3)
    placement = Placement(list(model.links), list(model.in_link), model.joints)
    pos, _, vel, _ = body_states(plant, context, placement, [0, 1, 2], (np.zeros((3, 3)),
                                 np.tile([1.0, 0, 0, 0], (3, 1))))  # fmt: skip
    assert pos[1] == pytest.approx([0.2 + 0.3 * math.sin(0.3), 0.0, 0.3 * math.cos(0.3)])
    # its velocity: the cart's -0.1 m/s plus 0.6 rad/s about y at 0.3 m
    assert vel[1] == pytest.approx([-0.1 + 0.3 * 0.6 * math.cos(0.3), 0.0,
                                    -0.3 * 0.6 * math.sin(0.3)])  # fmt: skip


def test_an_mjcf_models_masses_are_mujocos_inertia_from_its_geoms(pendulum):
    """inertiafromgeom: Drake's MJCF parser gives each body the mass and inertia of its
    capsules at density 1000, as MuJoCo's own compiler does (principal moments compared)."""
    import mujoco

    _, _, model, _, _ = pendulum
    compiled = mujoco.MjModel.from_xml_path(str(model.layout.path))
    for link in model.links:
        body = compiled.body(link.name())
        inertia = link.default_spatial_inertia()
        central = inertia.Shift(inertia.get_com()).CalcRotationalInertia().CopyToFullMatrix3()
        assert link.default_mass() == pytest.approx(body.mass[0], rel=1e-12)
        assert inertia.get_com() == pytest.approx(body.ipos, abs=1e-12)
        assert np.sort(np.linalg.eigvalsh(central)) == pytest.approx(
            np.sort(body.inertia), rel=1e-9
        )


def test_an_mjcf_files_gravity_does_not_replace_the_scenes(pendulum):
    """The file's <option gravity="1e-5 0 -9.81">: Drake's parser sets it on the plant; the
    loader sets the scene's again."""
    plant = pendulum[0]
    assert plant.gravity_field().gravity_vector() == pytest.approx([0.0, 0.0, -9.0], abs=0)


def test_an_mjcf_model_that_must_not_collide_is_filtered_from_everything(pendulum):
    """The file's floor, rail and three capsules stay registered (Drake computed the inertia
    from them) but no pair with one of them is ever checked."""
    _, scene_graph, model, _, filtered = pendulum
    every = _proximity(scene_graph)
    assert filtered == len(model.geometry) == 5
    inspector = scene_graph.model_inspector()
    assert all(inspector.CollisionFiltered(a, b) for a in model.geometry for b in every if a != b)


MESHED_MJCF = """<mujoco model="meshed"><compiler meshdir="parts"/>
  <asset><mesh name="cube" file="cube.obj"/></asset>
  <worldbody><body name="box" pos="0 0 1"><joint name="j" axis="0 1 0"/>
    <geom type="mesh" mesh="cube" mass="1"/></body></worldbody></mujoco>
"""


def test_a_placed_mjcf_finds_its_meshes(scenes, tmp_path):
    """Parsed from text (moved into a base body), the file's mesh folder is made absolute.
    A layout of the pendulum's with this file's names (physval's reader computes no mass of
    a mesh geom)."""
    (tmp_path / "parts").mkdir()
    (tmp_path / "parts" / "cube.obj").write_text(CUBE)
    path = tmp_path / "meshed.xml"
    path.write_text(MESHED_MJCF)
    layout = scenes["pendulum_placed"].models[0]
    layout = dataclasses.replace(
        layout, spec=layout.spec.model_copy(update={"collisions": True}), path=path,
        bodies=("pend/box",), links=("box",), body_in_link=(Frame(np.eye(3), np.zeros(3)),),
        joints=("pend/j",), file_joints=("j",), starts=(),
    )  # fmt: skip
    plant, scene_graph = _plant()
    (model,) = add_models(plant, scene_graph, [layout], (0.0, 0.0, -9.81))
    assert len(model.geometry) == 1
    assert model.links[0].default_mass() == 1.0


WORLD_ROOTED = """<robot name="rooted"><link name="world"/>
  <link name="box"><inertial><mass value="1"/>
    <inertia ixx="0.1" iyy="0.1" izz="0.1" ixy="0" ixz="0" iyz="0"/></inertial>
    <collision><geometry><mesh filename="cube.obj"/></geometry></collision></link>
  <joint name="pin" type="revolute"><parent link="world"/><child link="box"/>
    <origin xyz="0 0 0.5"/><axis xyz="0 1 0"/><limit lower="-1" upper="1"/></joint>
</robot>
"""
"""A root link named ``world`` and a collision mesh by a path relative to the file."""


def test_a_world_rooted_urdf_that_collides_is_placed_and_finds_its_mesh(tmp_path):
    """Read as text (its root renamed), the file's relative mesh path is made absolute, and
    the box hangs from the model's pose, not from Drake's world at the origin."""
    import yaml

    (tmp_path / "cube.obj").write_text(CUBE)
    (tmp_path / "rooted.urdf").write_text(WORLD_ROOTED)
    document = {"dt": 1e-3, "duration": 0.1, "engines": [NATIVE],
                "models": [{"name": "r", "file": "rooted.urdf", "position": [1.0, 0.0, 2.0]}]}  # fmt: skip
    (tmp_path / "rooted.yaml").write_text(yaml.safe_dump(document))
    layout = compile_scene(load_scenario(tmp_path / "rooted.yaml")).models[0]
    layout = dataclasses.replace(layout, spec=layout.spec.model_copy(update={"collisions": True}))
    plant, scene_graph = _plant()
    (model,) = add_models(plant, scene_graph, [layout], (0.0, 0.0, -9.81))
    plant.Finalize()
    assert len(model.geometry) == 1
    where = plant.EvalBodyPoseInWorld(plant.CreateDefaultContext(), model.links[0])
    assert where.translation() == pytest.approx([1.0, 0.0, 2.5], abs=1e-15)


GEARED = """<robot name="geared" xmlns:drake="http://drake.mit.edu">
  <link name="base"><inertial><mass value="2"/>
    <inertia ixx="0.1" iyy="0.1" izz="0.1" ixy="0" ixz="0" iyz="0"/></inertial></link>
  <link name="arm"><inertial><origin xyz="0.3 0 0"/><mass value="1"/>
    <inertia ixx="0.01" iyy="0.02" izz="0.02" ixy="0" ixz="0" iyz="0"/></inertial></link>
  <joint name="pin" type="continuous"><parent link="base"/><child link="arm"/>
    <axis xyz="0 1 0"/><dynamics damping="0.3" friction="0.4"/></joint>
  <transmission type="SimpleTransmission" name="drive">
    <actuator name="motor"><drake:rotor_inertia value="0.01"/>
      <drake:gear_ratio value="3"/></actuator>
    <joint name="pin"/><mechanicalReduction>1</mechanicalReduction></transmission>
</robot>
"""
"""A hinge with a motor of rotor inertia 0.01 kg·m² behind a 3:1 gear (Drake's
``drake:rotor_inertia`` and ``drake:gear_ratio``), and a joint friction Drake cannot take."""

REFLECTED = 0.01 * 3.0**2
"""kg·m²: the geared hinge's reflected inertia, rotor inertia × gear ratio²."""


def test_a_motors_reflected_inertia_is_the_joints_armature_and_is_in_m(tmp_path):
    """physval's reader knows no transmission, so the scene's M(q0) lacks what Drake adds
    to the hinge's diagonal: the difference model tier 1 is to find, reported as armature;
    the ignored friction is in the parser's notes."""
    (tmp_path / "geared.urdf").write_text(GEARED)
    document = {"dt": 1e-3, "duration": 0.1, "engines": [NATIVE],
                "models": [{"name": "g", "file": "geared.urdf"}]}  # fmt: skip
    import yaml

    (tmp_path / "geared.yaml").write_text(yaml.safe_dump(document))
    scene = compile_scene(load_scenario(tmp_path / "geared.yaml"))
    adapter = create_adapter(parse_engine_spec(NATIVE))
    adapter.load(scene)
    try:
        report = adapter.joint_report()
        assert report.armature == pytest.approx([0.0, REFLECTED], rel=1e-15)  # weld, pin
        stated = mass_matrix(scene.joint_tree, scene.joint_tree.zero())
        assert (report.mass_matrix - stated).ravel() == pytest.approx([REFLECTED], rel=1e-12)
        assert report.damping == pytest.approx([0.0, 0.3])
        notes = adapter.provenance().notes
        assert any("does not currently support non-zero joint friction" in n for n in notes)
    finally:
        adapter.close()


def test_drakes_mjcf_parser_drops_an_armature_without_an_actuator(scenes, tmp_path):
    """MuJoCo adds a joint's ``armature`` to M's diagonal; Drake's MJCF parser keeps it only
    as the reflected inertia of an actuator on the joint, and silently drops it otherwise
    (docs/engines-drake.md 10): 1.064 kg·m² against MuJoCo's 1.164 here."""
    import mujoco

    from validation.engines.drake.joints import joint_armature

    bodies = """<worldbody><body name="a" pos="0 0 1">
      <joint name="j" type="hinge" axis="0 1 0" armature="0.1"/>
      <geom type="sphere" size="0.1" pos="0 0 -0.5"/></body></worldbody>"""
    found = {}
    for label, extra in (
        ("bare", ""),
        ("driven", '<actuator><motor joint="j" gear="2"/></actuator>'),
    ):
        path = tmp_path / f"{label}.xml"
        path.write_text(f'<mujoco model="{label}">{bodies}{extra}</mujoco>')
        plant, scene_graph = _plant()
        layout = dataclasses.replace(  # physval's reader refuses an armature
            scenes["pendulum"].models[0], path=path, bodies=("pend/a",), links=("a",),
            body_in_link=(Frame(np.eye(3), np.zeros(3)),), joints=("pend/j",),
            file_joints=("j",), starts=(),
        )  # fmt: skip
        add_models(plant, scene_graph, [layout], (0.0, 0.0, -9.81))
        plant.Finalize()
        mass = plant.CalcMassMatrix(plant.CreateDefaultContext())[0, 0]
        model = mujoco.MjModel.from_xml_path(str(path))
        data = mujoco.MjData(model)
        mujoco.mj_forward(model, data)
        full = np.zeros((1, 1))
        mujoco.mj_fullM(model, data, full)
        found[label] = (mass, full[0, 0], sum(joint_armature(plant).values()))
    bare, driven = found["bare"], found["driven"]
    assert bare[1] - bare[0] == pytest.approx(0.1, rel=1e-9)  # Drake lacks the armature
    assert bare[2] == 0.0
    assert driven[1] - driven[0] == pytest.approx(0.0, abs=1e-12)  # kept as reflected inertia
    assert driven[2] == pytest.approx(0.1, rel=1e-12)


CUBE = "v -1 -1 -1\nv 1 -1 -1\nv 1 1 -1\nv -1 1 -1\nv -1 -1 1\nv 1 -1 1\nv 1 1 1\nv -1 1 1\n" + (
    "f 1 3 2\nf 1 4 3\nf 5 6 7\nf 5 7 8\nf 1 2 6\nf 1 6 5\nf 2 3 7\nf 2 7 6\n"
    "f 3 4 8\nf 3 8 7\nf 4 1 5\nf 4 5 8\n"
)
"""A 2 m cube as a Wavefront OBJ (a format Drake's convex hull reads)."""

MESHED = """<robot name="meshed"><link name="box"><inertial><mass value="1"/>
  <inertia ixx="0.1" iyy="0.1" izz="0.1" ixy="0" ixz="0" iyz="0"/></inertial>
  <collision><geometry><mesh filename="package://robots/cube.obj"/></geometry></collision>
  <collision><geometry><mesh filename="package://parts/cube.obj"/></geometry></collision>
</link></robot>
"""
"""Two collision meshes by ``package://`` URL: one in the file's own folder (``robots``), one
in a package only ``--package-path parts=DIR`` names."""


def test_package_urls_resolve_in_the_files_folder_and_the_package_paths(tmp_path, monkeypatch):
    """By the load's own rule (``validation.scenario.packages``): ``package://robots/...``
    in the file's own folder tree, ``package://parts/...`` only through ``--package-path``
    (``PACKAGE_PATHS`` at load, carried in the layout)."""
    import yaml

    from validation.scenario.urdf import PACKAGE_PATHS

    robots, parts = tmp_path / "robots", tmp_path / "elsewhere"
    for folder in (robots, parts):
        folder.mkdir()
        (folder / "cube.obj").write_text(CUBE)
    (robots / "meshed.urdf").write_text(MESHED)
    document = {"dt": 1e-3, "duration": 0.1, "engines": [NATIVE],
                "models": [{"name": "m", "file": "robots/meshed.urdf"}]}  # fmt: skip
    (tmp_path / "meshed.yaml").write_text(yaml.safe_dump(document))
    monkeypatch.setitem(PACKAGE_PATHS, "parts", str(parts))
    layout = compile_scene(load_scenario(tmp_path / "meshed.yaml")).models[0]
    spec = layout.spec.model_copy(update={"collisions": True})
    plant, scene_graph = _plant()
    (model,) = add_models(
        plant, scene_graph, [dataclasses.replace(layout, spec=spec)], (0, 0, -9.81)
    )
    assert len(model.geometry) == 2
    plant, scene_graph = _plant()
    without = dataclasses.replace(layout, spec=spec, package_paths=())
    with pytest.raises(RuntimeError, match="unknown package 'parts'"):
        add_models(plant, scene_graph, [without], (0.0, 0.0, -9.81))
