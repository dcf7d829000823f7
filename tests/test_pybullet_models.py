"""PyBullet's own loaders for a scene's ``models`` (``model_loader=native``, issue 36): the Kuka
iiwa, the cartpole and the A1 of pybullet_data (and a URDF whose every frame is turned) through
``loadURDF`` read back as the scene's bodies and joints, probed at random states against the
reference side, swung through ``physval run`` beside ``model_loader=physval``; what loadURDF
and loadMJCF make of a file differently from the file (docs/engines.md 2.6)."""

from __future__ import annotations

import csv
import math
from pathlib import Path

import numpy as np
import pybullet
import pytest
import yaml

from validation.cli import main
from validation.engines.joint_parity import compare_joints, expected_report
from validation.engines.parity import compare
from validation.engines.pybullet import models
from validation.engines.pybullet.adapter import PybulletAdapter
from validation.engines.reference import reference_report
from validation.measure.runner import run_engine
from validation.reference import articulated
from validation.reference.rotation import quat_to_matrix
from validation.scenario.compiled import CompiledScene, compile_scene
from validation.scenario.engine_spec import parse_engine_spec
from validation.scenario.load import load_scenario
from validation.scenario.urdf import Frame, ModelLayout, model_path

ROUND_OFF = 1e-12
"""Absolute, in SI units (m, kg, kg·m², J, rad/s): PyBullet's loader and physval's expansion
compose the same URDF transforms in double precision; measured <= 6e-14 (the Kuka's energy)."""

DIAGONALIZATION = 1e-8
"""Relative to a link's largest inertia entry: Bullet's URDF importer diagonalizes an inertia
with off-diagonal terms by Jacobi rotations stopping at a threshold of 1e-6 (BulletURDFImporter
getMassAndInertia2: ``diagonalize(basis, 1.0e-6, 30)``); measured 3.3e-9 on the A1's hips."""

PROBE_TOLERANCE = 1e-9
"""Relative to the largest entry of M or of the bias: calculateMassMatrix and
calculateInverseDynamics against the reference side's composite-rigid-body and Newton-Euler
sums, both double precision; measured <= 8e-16, 1.9e-13 on the A1 (``DIAGONALIZATION``)."""

SWING_AGREEMENT = 1e-9
"""m: the same btMultiBody dynamics built by loadURDF (URDF link frames) and by physval's
multibodies (centre-of-mass frames) differ by the round-off of the frames only; measured over
1 s: 3.2e-15 m (Kuka), 5.2e-16 m (cartpole)."""

TILT = (math.cos(0.3), math.sin(0.3), 0.0, 0.0)
"""The models' base turned 0.6 rad about x (w x y z): gravity then has a component along the
base's own y, which PyBullet's inverse dynamics ignores for a fixed base unless handed it in
the base's frame (``PybulletAdapter._gravity_in_base_frame``)."""

A1_STANCE = {f"a1/{leg}_lower_joint": -1.5 for leg in ("FR", "FL", "RR", "RL")}
"""The A1's knees inside their URDF limits [-2.70, -0.92] rad (0 is outside them)."""

TURNED = """<robot name="turned">
  <link name="base"><inertial><origin xyz="0.04 -0.02 0.12" rpy="0.25 -0.1 0"/><mass value="3"/>
    <inertia ixx="0.2" iyy="0.15" izz="0.1" ixy="0" ixz="0" iyz="0"/></inertial></link>
  <link name="upper"><inertial><origin xyz="0.18 0.01 0.04" rpy="0.1 0.6 0.2"/><mass value="1.2"/>
    <inertia ixx="0.012" iyy="0.021" izz="0.027" ixy="0.0012" ixz="0" iyz="0"/></inertial></link>
  <link name="slide"><inertial><origin xyz="0.02 0.08 0" rpy="0.35 0 0.1"/><mass value="0.6"/>
    <inertia ixx="0.0021" iyy="0.0032" izz="0.0043" ixy="0" ixz="0" iyz="0"/></inertial></link>
  <link name="wrist"><inertial><origin xyz="0 0 0.05" rpy="0 0.2 0"/><mass value="0.3"/>
    <inertia ixx="0.001" iyy="0.001" izz="0.0005" ixy="0" ixz="0" iyz="0"/></inertial></link>
  <joint name="pin" type="revolute"><parent link="base"/><child link="upper"/>
    <origin xyz="0 0.02 0.3" rpy="0.3 0.1 0.5"/><axis xyz="0 1 0"/>
    <limit lower="-1" upper="1"/><dynamics damping="0.2"/></joint>
  <joint name="rail" type="prismatic"><parent link="upper"/><child link="slide"/>
    <origin xyz="0.4 0 0" rpy="0 0 0.2"/><axis xyz="0.6 0 0.8"/>
    <limit lower="-0.5" upper="0.5"/></joint>
  <joint name="twist" type="continuous"><parent link="slide"/><child link="wrist"/>
    <origin xyz="0.1 0.05 0" rpy="-0.4 0 0"/><axis xyz="0 0.6 0.8"/></joint>
</robot>
"""
"""A hinge, an off-axis slider and a continuous joint, every origin and inertial frame turned,
a base with mass (held by the fixed base's weld) whose inertial frame is turned too (no
meshes)."""

MODELS = {
    "kuka": {
        "name": "arm",
        "file": "pkg:pybullet_data/kuka_iiwa/model.urdf",
        "joint_positions": {"arm/lbr_iiwa_joint_2": 0.5, "arm/lbr_iiwa_joint_4": -0.7},
        "joint_velocities": {"arm/lbr_iiwa_joint_1": 0.3, "arm/lbr_iiwa_joint_6": -0.4},
    },
    "cartpole": {
        "name": "cp",
        "file": "pkg:pybullet_data/cartpole.urdf",
        "joint_positions": {"cp/cart_to_pole": 0.4, "cp/slider_to_cart": 0.1},
        "joint_velocities": {"cp/slider_to_cart": 0.2},
    },
    "a1": {
        "name": "a1",
        "file": "pkg:pybullet_data/a1/a1.urdf",
        "joint_positions": {**A1_STANCE, "a1/FR_upper_joint": 0.7},
        "joint_velocities": {"a1/FL_hip_joint": 0.3},
    },
    "turned": {
        "name": "tw",
        "file": "turned.urdf",
        "joint_positions": {"tw/pin": 0.3, "tw/rail": 0.1, "tw/twist": 2.0},
        "joint_velocities": {"tw/pin": 0.5, "tw/rail": -0.2, "tw/twist": 1.5},
    },
}
"""Each model's ``models`` entry (a fixed base at ``TILT``, 1 m up)."""

LOADERS = ("pybullet", "pybullet(model_loader=physval)")


def write_scene(folder: Path, model: dict, engines=LOADERS, **fields) -> Path:
    """A scene file in ``folder`` holding ``model`` (a ``MODELS`` entry, fields overriding)."""
    (folder / "turned.urdf").write_text(TURNED)
    entry = {"position": [0.3, -0.2, 1.0], "orientation": list(TILT), "fixed_base": True}
    document = {
        "dt": 1e-3,
        "duration": 1.0,
        "engines": list(engines),
        "models": [{**entry, **model}],
        **fields,
    }
    path = folder / f"{model['name']}.yaml"
    path.write_text(yaml.safe_dump(document))
    return path


def scene_of(folder: Path, model: dict, **fields) -> CompiledScene:
    return compile_scene(load_scenario(write_scene(folder, model, **fields)))


def loaded(spec: str, scene: CompiledScene) -> PybulletAdapter:
    adapter = PybulletAdapter(parse_engine_spec(spec))
    adapter.load(scene)
    return adapter


def relative(a: np.ndarray, b: np.ndarray) -> float:
    return float(np.abs(a - b).max() / np.abs(b).max())


# --- tier-1 inputs: what the loader built ----------------------------------------------------


@pytest.mark.parametrize("name", sorted(MODELS))
def test_the_native_model_report_is_the_scenes(tmp_path, name):
    scene = scene_of(tmp_path, MODELS[name])
    with loaded("pybullet", scene) as adapter:
        got, want = adapter.model_report(), reference_report(scene)
    assert np.abs(got.mass - want.mass).max() <= ROUND_OFF
    assert np.abs(got.com - want.com).max() <= ROUND_OFF
    scale = np.abs(want.inertia_world).max(axis=(1, 2))
    inertia = (np.abs(got.inertia_world - want.inertia_world).max(axis=(1, 2)) / scale).max()
    if name == "a1":  # off-diagonal inertias: Bullet's diagonalization, a measured difference
        assert ROUND_OFF < inertia <= DIAGONALIZATION, inertia
    else:
        assert inertia <= ROUND_OFF, inertia
    assert abs(got.energy - want.energy) <= ROUND_OFF
    assert np.abs(got.linear_momentum - want.linear_momentum).max() <= ROUND_OFF
    assert np.abs(got.angular_momentum - want.angular_momentum).max() <= ROUND_OFF


@pytest.mark.parametrize("spec", LOADERS)
@pytest.mark.parametrize("name", sorted(MODELS))
def test_the_joints_are_the_scenes_with_limits_and_damping(tmp_path, name, spec):
    scene = scene_of(tmp_path, MODELS[name])
    with loaded(spec, scene) as adapter:
        assert compare_joints(adapter, scene, ROUND_OFF) == []
        report = adapter.joint_report()
    joints = scene.scenario.joints
    stated = np.array([j.limits if j.limits is not None else (np.nan, np.nan) for j in joints])
    assert np.array_equal(np.isnan(report.limits), np.isnan(stated))
    assert np.nanmax(np.abs(report.limits - stated), initial=0.0) <= ROUND_OFF
    assert np.abs(report.damping - [j.damping for j in joints]).max() <= ROUND_OFF
    assert not report.armature.any()
    assert report.mass_matrix.shape == expected_report(scene).mass_matrix.shape


@pytest.mark.parametrize("name", sorted(MODELS))
def test_observe_at_t0_is_the_scenes_start(tmp_path, name):
    scene = scene_of(tmp_path, MODELS[name])
    with loaded("pybullet", scene) as adapter:
        state = adapter.observe()
    start = scene.start
    assert np.abs(state.pos - start.pos[0]).max() <= ROUND_OFF
    assert np.abs(np.abs(np.sum(state.quat * start.quat[0], axis=1)) - 1.0).max() <= ROUND_OFF
    assert np.abs(state.vel - start.vel[0]).max() <= ROUND_OFF
    assert np.abs(state.ang_vel - start.ang_vel[0]).max() <= ROUND_OFF


def test_shapes_inertia_is_pybullets_default_and_differs_from_the_file(tmp_path):
    scene = scene_of(tmp_path, {**MODELS["kuka"], "joint_velocities": {}})  # at rest
    with loaded("pybullet(urdf_inertia=shapes)", scene) as adapter:
        got = adapter.model_report()
        settings = adapter.provenance().settings
    want = reference_report(scene)
    assert settings["urdf_inertia"] == "shapes" and settings["models"][0]["flags"] == "none"
    mismatches = compare(got, want, ROUND_OFF)
    assert {m.quantity for m in mismatches} == {"inertia_world"}
    assert len(mismatches) == 7  # every link: loadURDF recomputed it from the meshes
    # lbr_iiwa_link_1: the file's diag(0.1, 0.09, 0.02), PyBullet's (0.0451, 0.0412, 0.0247)
    link_1 = np.linalg.eigvalsh(got.inertia_world[0])
    assert link_1 == pytest.approx([0.024744, 0.041245, 0.045087], abs=1e-6)
    assert np.abs(got.mass - want.mass).max() == 0.0


# --- damping and motors ---------------------------------------------------------------------

WHEEL = """<robot name="wheel">
  <link name="base"/>
  <link name="wheel"><inertial><mass value="1"/>
    <inertia ixx="0.1" iyy="0.1" izz="0.1" ixy="0" ixz="0" iyz="0"/></inertial></link>
  <joint name="spin" type="continuous"><parent link="base"/><child link="wheel"/>
    <axis xyz="0 0 1"/><dynamics damping="0.5"/></joint>
</robot>
"""
"""A wheel on a vertical hinge through its centre (gravity exerts no torque), damping 0.5."""


def test_urdf_damping_decays_a_hinge_by_an_explicit_torque_and_nothing_else(tmp_path):
    (tmp_path / "wheel.urdf").write_text(WHEEL)
    model = {"name": "w", "file": "wheel.urdf", "joint_velocities": {"w/spin": 1.0}}
    scene = scene_of(tmp_path, {**model, "orientation": [1, 0, 0, 0]})
    steps, dt, damping, inertia = 1000, 1e-3, 0.5, 0.1
    with loaded("pybullet", scene) as adapter:
        adapter.advance(steps)
        spin = adapter.observe().ang_vel[0, 2]
    # jointDamping from the file, applied as -c·q̇ at each step's start velocity:
    # ω_n = ω_0 (1 - c dt / I)^n = 0.006654; the motor PyBullet puts on the joint would
    # hold it at 0, Bullet's default link damping 0.04 gave 0.006342 (docs/engines.md 2.6)
    assert spin == pytest.approx((1.0 - damping * dt / inertia) ** steps, rel=ROUND_OFF)


# --- tiers 2 and 3: probes ------------------------------------------------------------------

PROBES = 3
"""Seeded random joint states per model and loader."""


@pytest.mark.parametrize("spec", LOADERS)
@pytest.mark.parametrize("name", sorted(MODELS))
def test_model_probe_equals_the_reference_sides_kinematics_and_dynamics(tmp_path, name, spec):
    scene = scene_of(tmp_path, MODELS[name])
    tree = scene.joint_tree
    loads = articulated.Loads(
        np.asarray(scene.scenario.gravity, float), scene.springs, scene.force, scene.torque
    )
    rng = np.random.default_rng(36)
    with loaded(spec, scene) as adapter:
        for _ in range(PROBES):
            q = tree.zero() + rng.uniform(-0.5, 0.5, tree.nq)
            nu = rng.uniform(-1.0, 1.0, tree.nv)
            probe = adapter.model_probe(q, nu)
            pose = articulated.forward_kinematics(tree, q)
            assert np.abs(probe.pos - pose.pos).max() <= ROUND_OFF
            turn = np.einsum("nij,nij->n", quat_to_matrix(probe.quat), pose.rot)
            assert np.abs(turn - 3.0).max() <= ROUND_OFF  # trace(Rᵀ R') = 3: the same rotation
            mass_matrix = articulated.mass_matrix(tree, q)
            assert relative(probe.mass_matrix, mass_matrix) <= PROBE_TOLERANCE
            bias = articulated.bias_forces(tree, q, nu, loads)
            assert relative(probe.bias, bias) <= PROBE_TOLERANCE


# --- collisions -----------------------------------------------------------------------------


def test_collisions_false_leaves_every_link_out_of_contact(tmp_path):
    ground = {"ground": {}}  # the plane z = 0
    sunk = {**MODELS["a1"], "position": [0.0, 0.0, 0.1], "orientation": [1, 0, 0, 0]}
    scene = scene_of(tmp_path, sunk, **ground)  # the legs reach 0.4 m below the trunk
    with loaded("pybullet", scene) as adapter:
        adapter.advance(1)
        body = adapter.native[0].ids[0]
        touching = pybullet.getContactPoints(bodyA=body, physicsClientId=adapter.client)
        overlapping = pybullet.getClosestPoints(
            body, adapter.ground, 0.0, physicsClientId=adapter.client
        )
    assert overlapping  # the feet are inside the ground
    assert touching == ()


# --- a passive swing through physval run ----------------------------------------------------


def rows_of(out: Path) -> list[dict]:
    with open(out / "results.csv", newline="") as file:
        return list(csv.DictReader(file))


@pytest.mark.parametrize("name", ["cartpole", "kuka"])
def test_a_passive_swing_runs_in_both_loaders_and_they_agree(tmp_path, name):
    path = write_scene(tmp_path, MODELS[name])
    assert main(["run", str(path), "--out", str(tmp_path / "out"), "--jobs", "1"]) == 0
    rows = rows_of(tmp_path / "out")
    assert {(r["engine"], r["status"]) for r in rows} == {(spec, "ok") for spec in LOADERS}
    divergence = [r for r in rows if r["metric"] == "divergence"]
    assert [r["engine"] for r in divergence] == ["pybullet(model_loader=physval)"]
    assert float(divergence[0]["value"]) <= SWING_AGREEMENT


def test_the_a1_swings_and_differs_from_its_file_only_by_the_diagonalized_inertias(tmp_path):
    path = write_scene(tmp_path, MODELS["a1"])
    main(["run", str(path), "--out", str(tmp_path / "out"), "--jobs", "1"])
    rows = rows_of(tmp_path / "out")
    status = {r["engine"]: r["status"] for r in rows}
    assert status["pybullet(model_loader=physval)"] == "ok"
    native = [r for r in rows if r["engine"] == "pybullet"]
    if status["pybullet"] == "model_mismatch":  # the parity gate before the model tiers
        findings = native[0]["message"].split("; ")
        assert all(f.startswith("inertia_world") for f in findings), findings
    else:
        assert status["pybullet"] == "ok"


def test_a_file_pybullet_cannot_load_is_one_line(tmp_path):
    original = model_path(MODELS["kuka"]["file"], tmp_path / "x.yaml")
    (tmp_path / "meshes").symlink_to(original.parent / "meshes")
    (tmp_path / "kuka.urdf").write_text(original.read_text())
    scene = scene_of(tmp_path, {**MODELS["kuka"], "file": "kuka.urdf"})
    _ = scene.models  # read while the meshes are there (the scene's load checks them)
    (tmp_path / "meshes").unlink()  # then gone before the engine loads the file
    run = run_engine(scene, parse_engine_spec("pybullet"))
    assert run.status == "error"
    assert "loadURDF cannot load" in run.message and "mesh" in run.message
    assert "\n" not in run.message
    assert run_engine(scene, parse_engine_spec("pybullet(model_loader=physval)")).status == "ok"


# --- loadMJCF, through the loader's functions ------------------------------------------------

PENDULUM = "pkg:pybullet_data/mjcf/inverted_double_pendulum.xml"
MJCF_FLOATS = 1e-6
"""Relative (m for the metre-sized pendulum): loadMJCF parses the file's numbers as float32
(pole2's joint 0.30000001192 m from the pole's centre, ``getJointInfo``); measured 1.9e-8 m on
pole2's centre, 0.9 m from the cart, and 1.2e-7 of the pole's mass (its radius 0.045)."""

MJCF_DENSITY = 1000.0
"""kg/m³, MJCF's default geom density (the file's masses come from its capsules)."""


def capsule_mass(radius: float, half_length: float) -> float:
    return MJCF_DENSITY * math.pi * radius**2 * (2 * half_length + 4 / 3 * radius)


def pendulum_layout(tmp_path: Path) -> ModelLayout:
    """The double pendulum's layout as physval's MJCF reader gives it."""
    model = {
        "name": "dp",
        "file": PENDULUM,
        "position": [0.0, 0.0, 1.0],
        "orientation": list(TILT),
        "joint_positions": {"dp/slider": 0.2, "dp/hinge": 0.3},
        "joint_velocities": {"dp/hinge2": 0.5},
    }
    return scene_of(tmp_path, model).models[0]


def test_loadmjcf_places_the_pendulum_and_what_it_changes_is_measured(tmp_path):
    layout = pendulum_layout(tmp_path)
    client = pybullet.connect(pybullet.DIRECT)
    try:
        model = models.load_model(layout, "file", client)
        models.release_motors(model, client)
        assert model.removed == ("floor", "rail")  # worldbody geoms: static bodies of their own
        states = {name: models.scene_body_state(part, client) for name, part in model.parts.items()}
        held = {name: models.held_joint(joint, client) for name, joint in model.joints.items()}
        masses = {name: models.held_inertia(part, client)[0] for name, part in model.parts.items()}
    finally:
        pybullet.disconnect(client)
    base = Frame(quat_to_matrix(np.array(TILT)), np.array([0.0, 0.0, 1.0]))
    cart = base.translation + base.rotation @ [0.2, 0.0, 0.0]  # the slider's 0.2 m along x
    swing = np.array([math.sin(0.3), 0.0, math.cos(0.3)])  # the hinge's 0.3 rad about y
    expected = {
        "dp/cart": cart,
        "dp/pole": cart + base.rotation @ (0.3 * swing),
        "dp/pole2": cart + base.rotation @ (0.9 * swing),
    }
    for name, centre in expected.items():
        assert np.abs(np.array(states[name][:3]) - centre).max() <= MJCF_FLOATS, name
    # pole2 swings at 0.5 rad/s about the base's y through its joint, 0.6 m up the pole
    assert np.abs(states["dp/pole2"][10:13] - base.rotation @ [0.0, 0.5, 0.0]).max() <= ROUND_OFF
    # masses: the capsules' volumes x 1000 kg/m³, of float32 radii and lengths
    assert masses["dp/cart"] == pytest.approx(capsule_mass(0.1, 0.1), rel=MJCF_FLOATS)
    assert masses["dp/pole"] == pytest.approx(capsule_mass(0.045, 0.3), rel=MJCF_FLOATS)
    # the slider keeps its range (relative to its 0.2 m start); the hinges have none
    assert held["dp/slider"].limits == pytest.approx([-1.2, 0.8], abs=ROUND_OFF)
    assert np.isnan(held["dp/hinge"].limits).all()
    # the file's <default><joint damping="0.05"/> is dropped by loadMJCF
    assert [h.damping for h in held.values()] == [0.0, 0.0, 0.0]
