"""MuJoCo's native loader of a scene's ``models`` (issue 36, ``model_loader=native``): the
Kuka iiwa URDF and the MJCF inverted double pendulum of pybullet_data read by MuJoCo's own
compiler and attached at the model's pose hold the scene's masses, joints and start, and
their mass matrix and bias forces equal the reference side's at random states; a passive
swing agrees with MuJoCo built from physval's reading."""

from __future__ import annotations

import math
from pathlib import Path

import mujoco
import numpy as np
import pandas as pd
import pytest
import yaml
from test_models import CHAIN as TURNED_CHAIN

from validation.cli import main
from validation.engines.mujoco.adapter import MujocoAdapter
from validation.engines.mujoco.native import compile_with_models, set_joint_state
from validation.reference.articulated import Loads, bias_forces, forward_kinematics, mass_matrix
from validation.reference.rotation import quat_multiply, quat_to_matrix
from validation.scenario.compiled import compile_scene
from validation.scenario.engine_spec import parse_engine_spec
from validation.scenario.load import load_scenario
from validation.scenario.physics import body_inertia
from validation.scenario.urdf import model_path

KUKA = "pkg:pybullet_data/kuka_iiwa/model.urdf"
PENDULUM = "pkg:pybullet_data/mjcf/inverted_double_pendulum.xml"
BASE = (0.3, -0.2, 1.0)
BASE_TURN = (math.cos(0.2), 0.0, 0.0, math.sin(0.2))  # 0.4 rad about z
POSE = {"arm/lbr_iiwa_joint_2": 0.5, "arm/lbr_iiwa_joint_4": -0.7, "arm/lbr_iiwa_joint_6": 0.9}
RATES = {"arm/lbr_iiwa_joint_1": 0.3, "arm/lbr_iiwa_joint_5": -0.4}
NATIVE, PHYSVAL = "mujoco", "mujoco(model_loader=physval)"

CHAIN = TURNED_CHAIN.replace('iyy="0.1" izz="0.1"', 'iyy="0.12" izz="0.08"', 1)
"""test_models' chain (a hinge and a slider, every origin and inertial frame turned), its base's
inertia made unequal, on a free base whose inertial frame is off its link frame and turned:
MuJoCo's free joint then moves the link origin, not the centre (the probe's free-root terms)."""

FIELD_TOLERANCE = 1e-9
"""kg, m, kg·m², rad: MuJoCo's reading of the Kuka against physval's: both take the URDF's
numbers as written and compose the same transforms in double precision (measured: mass 0,
COM 4.4e-16 m, world inertia 1.2e-16 kg·m², joint anchors 2.2e-16 m)."""

STATE_TOLERANCE = 1e-12
"""m, m/s, rad/s: observe() at t = 0 against the scene's start (measured 4.4e-16; the native
model starts from the file's joint coordinates, the scene from physval's expansion of them)."""

DYNAMICS_TOLERANCE = 1e-12
"""Relative to the largest entry: M and the bias from MuJoCo (CRBA, RNE over its own body
frames) against the reference's (composite rigid body and Newton-Euler over the scene's bodies):
measured ≤ 1.1e-15 on the Kuka, the free chain and the pendulum; round-off of sums of ~10
products."""

SWING_TOLERANCE = 1e-9
"""m: ``divergence`` of a 1 s passive swing (no limit reached) between MuJoCo's native reading
and physval's (measured 3.0e-15 m for the hanging Kuka, 6.0e-15 m for the pendulum beside a
falling ball: the same equations in other body frames; a limit reached changes this:
docs/engines.md 1.4c)."""


def write_scene(folder: Path, model: dict, engines=(NATIVE,), duration: float = 0.2) -> Path:
    entry = {"name": "arm", "file": KUKA, **model}
    document = {"dt": 0.001, "duration": duration, "engines": list(engines), "models": [entry]}
    path = folder / "arm.yaml"
    path.write_text(yaml.safe_dump(document, sort_keys=False))
    return path


def kuka_scene(folder: Path, **fields):
    model = {
        "position": list(BASE),
        "orientation": list(BASE_TURN),
        "joint_positions": POSE,
        "joint_velocities": RATES,
        **fields,
    }
    return compile_scene(load_scenario(write_scene(folder, model)))


def free_chain_scene(folder: Path):
    (folder / "chain.urdf").write_text(CHAIN)
    return kuka_scene(
        folder,
        file="chain.urdf",
        fixed_base=False,
        joint_positions={"arm/pin": 0.4, "arm/rail": 0.15},
        joint_velocities={"arm/pin": -0.8, "arm/rail": 0.6},
    )


def loaded(scene, spec: str = NATIVE) -> MujocoAdapter:
    adapter = MujocoAdapter(parse_engine_spec(spec))
    adapter.load(scene)
    return adapter


def world_inertia(body) -> np.ndarray:
    rot = quat_to_matrix(np.array([body.orientation], dtype=float))[0]
    return rot @ body_inertia(body) @ rot.T


# --- the Kuka URDF ------------------------------------------------------------------------


def test_native_kuka_is_read_by_mujocos_compiler_with_the_scenes_names(tmp_path):
    adapter = loaded(kuka_scene(tmp_path))
    m = adapter.model
    bodies = [mujoco.mj_id2name(m, mujoco.mjtObj.mjOBJ_BODY, i) for i in range(m.nbody)]
    # link_0 (mass 0) is kept by MuJoCo (fusestatic off), folded into the world by physval
    assert bodies == ["world"] + [f"arm/lbr_iiwa_link_{i}" for i in range(8)]
    assert adapter.xml.count("<body") == 0  # the scene's own MJCF holds no model body
    assert "model_loader=native" in " ".join(adapter.provenance().notes)
    physval = loaded(adapter.scene, PHYSVAL)
    assert physval.model.nbody == 8  # world + the seven scene bodies, from physval's reading


def test_native_kuka_model_report_equals_the_scenes_bodies(tmp_path):
    scene = kuka_scene(tmp_path)
    report = loaded(scene).model_report()
    bodies = scene.scenario.bodies
    assert np.abs(report.mass - [b.mass for b in bodies]).max() <= FIELD_TOLERANCE
    assert np.abs(report.com - [b.position for b in bodies]).max() <= FIELD_TOLERANCE
    expected = np.array([world_inertia(b) for b in bodies])
    assert np.abs(report.inertia_world - expected).max() <= FIELD_TOLERANCE
    start = scene.start
    energy = scene.energy(start.pos, start.quat, start.vel, start.ang_vel)[0]
    assert report.energy == pytest.approx(energy, rel=FIELD_TOLERANCE)


def test_native_kuka_joint_report_holds_the_urdfs_limits_damping_and_axes(tmp_path):
    scene = kuka_scene(tmp_path)
    report = loaded(scene).joint_report()
    joints = scene.scenario.joints
    assert report.types == ("hinge",) * 7
    assert np.abs(report.anchors - [j.anchor for j in joints]).max() <= FIELD_TOLERANCE
    assert np.abs(report.axes - [j.axis for j in joints]).max() <= FIELD_TOLERANCE
    # relative to t = 0: joint_2's ±2.0944 rad less its initial 0.5 rad
    assert np.abs(report.limits - [j.limits for j in joints]).max() <= FIELD_TOLERANCE
    assert report.limits[1] == pytest.approx((-2.09439510239 - 0.5, 2.09439510239 - 0.5))
    assert report.damping.tolist() == [0.5] * 7  # <dynamics damping="0.5">
    assert report.armature.tolist() == [0.0] * 7
    tree = scene.joint_tree
    reference = mass_matrix(tree, tree.zero())
    assert (
        np.abs(report.mass_matrix - reference).max() <= DYNAMICS_TOLERANCE * np.abs(reference).max()
    )


def assert_starts_as_the_scene(adapter, scene) -> None:
    snap, start = adapter.observe(), scene.start
    assert np.abs(snap.pos - start.pos[0]).max() <= STATE_TOLERANCE
    signs = np.sign(np.einsum("ni,ni->n", snap.quat, start.quat[0]))[:, None]
    assert np.abs(snap.quat * signs - start.quat[0]).max() <= STATE_TOLERANCE
    assert np.abs(snap.vel - start.vel[0]).max() <= STATE_TOLERANCE
    assert np.abs(snap.ang_vel - start.ang_vel[0]).max() <= STATE_TOLERANCE


@pytest.mark.parametrize("case", ["kuka", "free chain"])
def test_native_model_starts_where_the_scene_starts(tmp_path, case):
    scene = kuka_scene(tmp_path) if case == "kuka" else free_chain_scene(tmp_path)
    assert_starts_as_the_scene(loaded(scene), scene)


def assert_probes_equal_the_reference(adapter, scene, states: int = 4, seed: int = 7) -> None:
    """model_probe at the start and at ``states`` seeded random states against the reference."""
    tree = scene.joint_tree
    loads = Loads(scene.gravity, scene.springs, scene.force, scene.torque)
    rng = np.random.default_rng(seed)
    for k in range(states + 1):
        q, nu = tree.zero(), np.zeros(tree.nv)
        if k:
            turns = [j for j in tree.joints if j.type in ("hinge", "slider")]
            for joint in turns:
                q[joint.q_slice] = rng.uniform(-0.8, 0.8)
            nu = rng.uniform(-1.5, 1.5, tree.nv)
        probe = adapter.model_probe(q, nu)
        pose = forward_kinematics(tree, q)
        assert np.abs(probe.pos - pose.pos).max() <= STATE_TOLERANCE, k
        axes = quat_to_matrix(probe.quat)
        assert np.abs(axes - pose.rot).max() <= STATE_TOLERANCE, k
        reference = mass_matrix(tree, q)
        scale = np.abs(reference).max()
        assert np.abs(probe.mass_matrix - reference).max() <= DYNAMICS_TOLERANCE * scale, k
        bias = bias_forces(tree, q, nu, loads)
        scale = np.abs(bias).max()
        assert np.abs(probe.bias - bias).max() <= DYNAMICS_TOLERANCE * scale, k


@pytest.mark.parametrize("spec", [NATIVE, PHYSVAL])
@pytest.mark.parametrize("case", ["kuka", "free chain"])
def test_model_probe_equals_the_reference_sides_dynamics(tmp_path, case, spec):
    scene = kuka_scene(tmp_path) if case == "kuka" else free_chain_scene(tmp_path)
    assert_probes_equal_the_reference(loaded(scene, spec), scene)


def test_probing_leaves_the_run_where_it_was(tmp_path):
    scene = kuka_scene(tmp_path)
    adapter = loaded(scene)
    before = adapter.observe()
    adapter.model_probe(scene.joint_tree.zero() + 0.3, np.ones(scene.joint_tree.nv))
    after = adapter.observe()
    assert np.array_equal(before.pos, after.pos) and np.array_equal(before.vel, after.vel)


def test_meshes_that_neither_collide_nor_weigh_are_not_read(tmp_path):
    """collisions: false: the links' geoms neither collide nor weigh (every link states its
    <inertial>), so MuJoCo is not asked to read their meshes: a copy of the URDF whose mesh
    files are empty (they exist, as physval's load checks; MuJoCo cannot parse them) loads."""
    (tmp_path / "kuka.urdf").write_text(model_path(KUKA, tmp_path / "x.yaml").read_text())
    (tmp_path / "meshes").mkdir()
    for name in model_path(KUKA, tmp_path / "x.yaml").parent.joinpath("meshes").iterdir():
        (tmp_path / "meshes" / name.name).write_bytes(b"")
    adapter = loaded(kuka_scene(tmp_path, file="kuka.urdf"))
    assert adapter.model.nmesh == 0 and adapter.model.ngeom == 0


def test_a_swing_through_physval_run_agrees_with_physvals_reading(tmp_path):
    """A 1 s passive swing of the Kuka hanging upside down (no joint reaches a limit), run by
    ``physval run`` in MuJoCo native and MuJoCo from physval's reading: both ok, one trajectory."""
    model = {
        "position": [0.3, -0.2, 1.5],
        "orientation": [0.0, 1.0, 0.0, 0.0],
        "joint_positions": POSE,
        "joint_velocities": RATES,
    }
    assert_loaders_agree(write_scene(tmp_path, model, engines=(NATIVE, PHYSVAL), duration=1.0))


def assert_loaders_agree(path: Path) -> None:
    """``physval run`` of the scene at ``path``: every row ok, the two loaders one trajectory."""
    out = path.parent / "out"
    assert main(["run", str(path), "--out", str(out)]) == 0
    results = pd.read_csv(out / "results.csv")
    assert set(results["engine"]) == {NATIVE, PHYSVAL}
    assert (results["status"] == "ok").all(), results.to_string()
    divergence = results.set_index(["engine", "metric"]).loc[(PHYSVAL, "divergence"), "value"]
    assert divergence <= SWING_TOLERANCE


# --- the MJCF inverted double pendulum ------------------------------------------------------

PENDULUM_JOINTS = {"dp/slider": 0.2, "dp/hinge": 0.3, "dp/hinge2": -0.4}
PENDULUM_RATES = {"dp/slider": -0.5, "dp/hinge": 1.0, "dp/hinge2": 0.7}
CAPSULES = {"cart": (0.1, 0.1), "pole": (0.045, 0.3), "pole2": (0.045, 0.3)}
"""The file's capsules: radius, half-length (m); ``inertiafromgeom="true"``, density 1000."""
WATER = 1000.0
"""kg/m³: MuJoCo's default geom density, the file sets none."""
BOB = {
    "name": "bob",
    "shape": {"type": "sphere", "radius": 0.05},
    "mass": 1.0,
    "position": [2.0, 0.0, 1.0],
    "velocity": [0.3, -0.2, 0.5],
    "angular_velocity": [1.0, 0.0, 0.0],
}
"""A body of the scene's own beside the model: its velocity is solved, the model's set."""


def pendulum_scene(folder: Path):
    """The pendulum at ``BASE``, its joints off zero and moving, beside ``BOB``."""
    entry = {
        "name": "dp",
        "file": PENDULUM,
        "position": list(BASE),
        "orientation": list(BASE_TURN),
        "joint_positions": PENDULUM_JOINTS,
        "joint_velocities": PENDULUM_RATES,
    }
    document = {"dt": 0.001, "duration": 0.2, "engines": [NATIVE], "models": [entry]}
    document["bodies"] = [BOB]
    (folder / "dp.yaml").write_text(yaml.safe_dump(document, sort_keys=False))
    return compile_scene(load_scenario(folder / "dp.yaml"))


def test_mjcf_pendulum_swing_through_physval_run_agrees_with_physvals_reading(tmp_path):
    """1 s of the pendulum from ``pendulum_scene``'s start (measured divergence 6.0e-15 m)."""
    pendulum_scene(tmp_path)
    document = yaml.safe_load((tmp_path / "dp.yaml").read_text())
    document.update(duration=1.0, engines=[NATIVE, PHYSVAL])
    (tmp_path / "dp.yaml").write_text(yaml.safe_dump(document, sort_keys=False))
    assert_loaders_agree(tmp_path / "dp.yaml")


def test_mjcf_pendulum_is_compiled_by_mujoco_under_the_scenes_options(tmp_path):
    layout = pendulum_scene(tmp_path).models[0]
    scene_xml = '<mujoco><option timestep="0.001" integrator="Euler"/><worldbody/></mujoco>'
    model, notes = compile_with_models(scene_xml, [layout])
    data = mujoco.MjData(model)
    set_joint_state(model, data, [layout])
    # the file's own <option timestep="0.01" integrator="RK4" gravity="1e-5 0 -9.81">: not used
    assert model.opt.timestep == 0.001
    assert model.opt.integrator == mujoco.mjtIntegrator.mjINT_EULER
    assert model.opt.gravity.tolist() == [0.0, 0.0, -9.81]
    assert any("timestep" in note for note in notes) and any("gravity" in note for note in notes)
    for link, (radius, half) in CAPSULES.items():  # inertiafromgeom="true", density 1000
        volume = math.pi * radius**2 * 2 * half + 4 / 3 * math.pi * radius**3
        assert model.body(f"dp/{link}").mass[0] == pytest.approx(WATER * volume, rel=1e-12)
    joints = [model.joint(name) for name in PENDULUM_JOINTS]
    assert [model.dof_damping[j.dofadr[0]] for j in joints] == [0.05] * 3  # <default><joint>
    assert [data.qpos[j.qposadr[0]] for j in joints] == list(PENDULUM_JOINTS.values())
    assert [data.qvel[j.dofadr[0]] for j in joints] == list(PENDULUM_RATES.values())
    assert model.nu == 0  # its motor removed: a passive model
    assert model.ngeom == 3  # the capsules weigh; the world's floor and rail are dropped
    assert not model.geom_contype.any() and not model.geom_conaffinity.any()


def test_mjcf_pendulum_natively_holds_physvals_reading_and_the_scenes_start(tmp_path):
    scene = pendulum_scene(tmp_path)
    adapter = loaded(scene)
    assert adapter.xml.count("<body") == 1  # BOB: the model's bodies are MuJoCo's reading
    assert_starts_as_the_scene(adapter, scene)
    report = adapter.model_report()
    bodies = scene.scenario.bodies
    assert np.abs(report.mass - [b.mass for b in bodies]).max() <= FIELD_TOLERANCE
    assert np.abs(report.com - [b.position for b in bodies]).max() <= FIELD_TOLERANCE
    expected = np.array([world_inertia(b) for b in bodies])
    assert np.abs(report.inertia_world - expected).max() <= FIELD_TOLERANCE
    joints = adapter.joint_report()
    assert joints.types == ("slider", "hinge", "hinge")
    assert joints.damping.tolist() == [0.05] * 3
    # the file's range [-1, 1] m less the slider's initial 0.2 m; the hinges are unlimited
    assert joints.limits[0] == pytest.approx((-1.2, 0.8))
    assert np.isnan(joints.limits[1:]).all()
    assert np.abs(joints.anchors - [j.anchor for j in scene.scenario.joints]).max() <= 1e-12
    assert_probes_equal_the_reference(adapter, scene)
    notes = " ".join(adapter.provenance().notes)
    assert "model file's option not used" in notes and "timestep" in notes


def unit(rng) -> np.ndarray:
    """A random unit quaternion w x y z, w > 0."""
    quat = rng.normal(size=4)
    return quat * np.sign(quat[0]) / np.linalg.norm(quat)


LIBRARY = Path(__file__).resolve().parent.parent / "scenarios" / "joints"

TURNED_BALLS = """dt: 0.001
duration: 0.1
engines: [mujoco]
bodies:
  - {name: a, shape: {type: box, half_extents: [0.1, 0.05, 0.02]}, mass: 1.0,
     position: [0.3, 0.1, 2.0], orientation: [0.9, 0.3, -0.2, 0.2449489742783178]}
  - {name: b, shape: {type: box, half_extents: [0.05, 0.1, 0.03]}, mass: 0.5,
     position: [0.5, 0.4, 1.8], orientation: [0.6, 0.0, 0.8, 0.0]}
  - {name: floating, shape: {type: box, half_extents: [0.1, 0.2, 0.3]}, mass: 2.0,
     position: [2.0, 0.0, 1.0], orientation: [0.8, 0.0, 0.0, 0.6], velocity: [0.1, 0.0, 0.0],
     angular_velocity: [0.5, 0.2, -0.4]}
joints:
  - {name: shoulder, type: ball, parent: world, child: a, anchor: [0.2, 0.0, 2.1]}
  - {name: elbow, type: ball, parent: a, child: b, anchor: [0.45, 0.25, 1.9]}
"""
"""Ball joints between bodies turned off the world's axes (so R0 and MuJoCo's body frames are
no identity), and a turned floating box (a free root)."""


@pytest.mark.parametrize(
    "name", ["turned balls", "conical_pendulum_ball_joint", "slider_on_spring", "chain_falling"]
)
def test_model_probe_of_scenes_without_models_equals_the_reference(tmp_path, name):
    """Scenes without models (every body written by ``mjcf``): a ball joint's quaternion and
    spin carried into MuJoCo's frames, a free root, a spring (a load the bias includes)."""
    path = LIBRARY / f"{name}.yaml"
    if name == "turned balls":
        path = tmp_path / "balls.yaml"
        path.write_text(TURNED_BALLS)
    scene = compile_scene(load_scenario(path))
    tree = scene.joint_tree
    adapter = loaded(scene)
    rng = np.random.default_rng(3)
    for _ in range(3):
        q, nu = tree.zero(), rng.uniform(-1.5, 1.5, tree.nv)
        for joint in tree.joints:
            if joint.type == "free":
                q[joint.q_slice][:3] += rng.uniform(-0.5, 0.5, 3)
                q[joint.q_slice][3:] = quat_multiply(q[joint.q_slice][3:], unit(rng))
            if joint.type == "ball":
                axis = rng.normal(size=3)
                turn = rng.uniform(0.1, 1.0)
                q[joint.q_slice] = [
                    math.cos(turn / 2),
                    *(math.sin(turn / 2) * axis / np.linalg.norm(axis)),
                ]
            elif joint.type in ("hinge", "slider"):
                q[joint.q_slice] = rng.uniform(-0.8, 0.8)
        probe = adapter.model_probe(q, nu)
        pose = forward_kinematics(tree, q)
        assert np.abs(probe.pos - pose.pos).max() <= STATE_TOLERANCE
        assert np.abs(quat_to_matrix(probe.quat) - pose.rot).max() <= STATE_TOLERANCE
        reference = mass_matrix(tree, q)
        assert (
            np.abs(probe.mass_matrix - reference).max()
            <= DYNAMICS_TOLERANCE * np.abs(reference).max()
        )
        loads = Loads(scene.gravity, scene.springs, scene.force, scene.torque)
        bias = bias_forces(tree, q, nu, loads)
        assert np.abs(probe.bias - bias).max() <= DYNAMICS_TOLERANCE * np.abs(bias).max()


def test_limit_softness_is_mujocos_at_its_own_reference_configuration(tmp_path):
    """A finding (docs/engines.md 1.4c): MuJoCo scales a joint limit's softness by the dof's
    inverse weight at qpos0 (``dof_invweight0``), the file's zero under native loading and the
    scene's start under physval's: the same Kuka, two different limit responses."""
    scene = kuka_scene(tmp_path)
    native, physval = (loaded(scene, spec).model.dof_invweight0 for spec in (NATIVE, PHYSVAL))
    assert native[0] == pytest.approx(20.59995719, rel=1e-6)  # measured
    assert physval[0] == pytest.approx(3.32926001, rel=1e-6)


def test_a_scene_joint_to_a_models_body_is_an_error_row_naming_the_way_out(tmp_path):
    """The native loader keeps a model whole: a scene body jointed to a model's link is an
    ``error`` row whose message names ``model_loader=physval``; physval's reading runs it."""
    from validation.measure.runner import run_engine

    path = write_scene(tmp_path, {"position": [0.0, 0.0, 1.0]})
    document = yaml.safe_load(path.read_text())
    document["bodies"] = [
        {"name": "bob", "shape": {"type": "sphere", "radius": 0.05}, "mass": 1.0,
         "position": [0.0, 0.0, 2.5]}
    ]  # fmt: skip
    document["joints"] = [
        {"name": "hook", "type": "ball", "parent": "arm/lbr_iiwa_link_7", "child": "bob",
         "anchor": [0.0, 0.0, 2.4]}
    ]  # fmt: skip
    path.write_text(yaml.safe_dump(document, sort_keys=False))
    scene = compile_scene(load_scenario(path))
    native = run_engine(scene, parse_engine_spec(NATIVE))
    assert native.status == "error"
    assert "model_loader=physval" in native.message and "hook" in native.message
    assert run_engine(scene, parse_engine_spec(PHYSVAL)).status == "ok"


def test_package_meshes_resolve_as_physvals_load_resolves_them(tmp_path):
    """``package://NAME/...`` (which MuJoCo's importer would read as a relative path) by the
    model file's folder tree, else ``--package-path``; other paths are left to MuJoCo."""
    from types import SimpleNamespace

    from validation.engines.mujoco.native import _resolve_meshes

    (tmp_path / "robot" / "meshes").mkdir(parents=True)
    (tmp_path / "robot" / "meshes" / "arm.stl").write_bytes(b"")
    (tmp_path / "elsewhere").mkdir()
    (tmp_path / "elsewhere" / "hand.stl").write_bytes(b"")
    spec = mujoco.MjSpec()
    for file in ("package://robot/meshes/arm.stl", "package://tools/hand.stl", "meshes/x.stl"):
        spec.add_mesh(file=file)
    layout = SimpleNamespace(
        path=tmp_path / "robot" / "robot.urdf",
        package_paths=(("tools", str(tmp_path / "elsewhere")),),
    )
    _resolve_meshes(spec, layout)
    assert [mesh.file for mesh in spec.meshes] == [
        str(tmp_path / "robot" / "meshes" / "arm.stl"),
        str(tmp_path / "elsewhere" / "hand.stl"),
        "meshes/x.stl",
    ]
