"""physval's own MJCF reader (``validation/scenario/mjcf.py``): the inverted double pendulum
of pybullet_data read into a slider and two hinges whose capsule masses and inertias equal the
hand-computed ones and MuJoCo's compiled model; a richer file (default classes, childclass,
every orientation form, off-centre pivots, a weld, an explicit and a full inertia) whose
masses and poses equal MuJoCo's; every refusal one line at ``models[i].file``."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest
from scipy.spatial.transform import Rotation
from test_models import ENGINES, assert_energy_kept, assert_refused_at_file, write_scene

from validation.scenario.compiled import compile_scene
from validation.scenario.engine_spec import not_installed
from validation.scenario.load import load_scenario
from validation.scenario.problems import ScenarioError
from validation.scenario.urdf import model_path

PENDULUM = "pkg:pybullet_data/mjcf/inverted_double_pendulum.xml"

DENSITY = 1000.0
"""kg/m³: MJCF's default geom density (the pendulum's geoms state none)."""

MASS_TOLERANCE = 1e-12
"""Relative: the same closed forms in double precision on both sides. Measured against MuJoCo
4.0.1: masses 1.7e-16, inertias 7.8e-15 of the largest moment (the rich file's turned
geoms), centres 1.1e-16 m: MuJoCo's capsule (and other solid) formulas are the exact ones."""

POSE_TOLERANCE = 1e-9
"""m and unit-quaternion components: physval's forward kinematics against MuJoCo's for links
within a metre: both compose the same transforms in double precision (~1e-15); the file's
degrees are converted by both as x · π / 180."""


def capsule_by_hand(radius: float, half_length: float) -> tuple[float, float, float]:
    """Mass, axial and transverse moment of a capsule of DENSITY, written out here: the
    cylinder of length ℓ and the two hemispheres (one ball) each about the capsule's centre,
    a cap's centroid 3r/8 from its flat face (parallel axes):
    I_t = m_c (r²/4 + ℓ²/12) + m_s (2r²/5 + ℓ²/4 + 3ℓr/8), I_a = m_c r²/2 + 2 m_s r²/5."""
    length = 2 * half_length
    cylinder = DENSITY * math.pi * radius**2 * length
    ball = DENSITY * 4 / 3 * math.pi * radius**3
    axial = cylinder * radius**2 / 2 + ball * 2 * radius**2 / 5
    transverse = cylinder * (radius**2 / 4 + length**2 / 12) + ball * (
        2 * radius**2 / 5 + length**2 / 4 + 3 * length * radius / 8
    )
    return cylinder + ball, axial, transverse


def pendulum(folder: Path, **fields):
    return load_scenario(write_scene(folder, {"file": PENDULUM, **fields}))


def test_the_double_pendulum_is_a_slider_and_two_hinges_from_the_world(tmp_path):
    scenario = pendulum(tmp_path)
    assert [(j.name, j.type, j.parent) for j in scenario.joints] == [
        ("arm/slider", "slider", "world"),
        ("arm/hinge", "hinge", "arm/cart"),
        ("arm/hinge2", "hinge", "arm/pole"),
    ]
    assert [j.damping for j in scenario.joints] == [0.05] * 3  # <default><joint damping>
    assert scenario.joints[0].limits == (-1.0, 1.0)  # limited="true" range="-1 1", metres
    assert scenario.joints[1].limits is None  # no range: unlimited
    assert np.allclose(scenario.joints[2].anchor, [0, 0, 0.6])  # pole2's origin, its pivot
    (layout,) = compile_scene(scenario).models
    assert layout.format == "mjcf" and layout.root_link == "world"
    assert layout.file_joints == ("slider", "hinge", "hinge2")


def test_the_pendulums_masses_and_inertias_are_the_hand_computed_capsules(tmp_path):
    bodies = {b.name: b for b in pendulum(tmp_path).bodies}
    # the cart: size="0.1 0.1", turned by quat="0.707 0 0.707 0" (normalized: 90° about y)
    # so its axis is the body's x; each pole: fromto 0.6 long, radius 0.045, centre z = 0.3
    mass, axial, transverse = capsule_by_hand(0.1, 0.1)
    cart = bodies["arm/cart"]
    assert cart.mass == pytest.approx(mass, rel=MASS_TOLERANCE)
    assert np.allclose(cart.inertia_matrix, np.diag([axial, transverse, transverse]), rtol=1e-12)
    mass, axial, transverse = capsule_by_hand(0.045, 0.3)
    for name, height in (("arm/pole", 0.3), ("arm/pole2", 0.9)):
        assert bodies[name].mass == pytest.approx(mass, rel=MASS_TOLERANCE)
        assert np.allclose(bodies[name].inertia_matrix, np.diag([transverse, transverse, axial]))
        assert np.allclose(bodies[name].position, [0, 0, height])


RICH = """<mujoco model="rich">
  <compiler eulerseq="zYx"/>
  <option gravity="0 0 -9.81"/>
  <default>
    <joint damping="0.2"/>
    <geom density="500"/>
    <default class="heavy">
      <geom density="2000" type="box" size="0.05 0.1 0.02"/>
      <joint type="slide" axis="1 0 0"/>
    </default>
  </default>
  <worldbody>
    <geom type="plane" size="1 1 0.1"/>
    <light pos="0 0 3"/>
    <body name="base" pos="0.1 0.2 1.0" euler="10 20 30">
      <joint name="swing" type="hinge" pos="0 0 0.1" axis="0 1 0.2" range="-60 45"/>
      <geom type="capsule" fromto="0 0 0 0.3 0 -0.2" size="0.03"/>
      <geom type="sphere" pos="0.3 0 -0.2" size="0.06" mass="0.8"/>
      <site name="mark" pos="0 0 0"/>
      <body name="mid" pos="0.3 0 -0.2" axisangle="1 1 0 40" childclass="heavy">
        <joint name="rail" pos="0.02 0 0" range="-0.1 0.2"/>
        <geom pos="0 0.05 0" euler="0 0 15"/>
        <geom type="cylinder" size="0.02 0.1" pos="0 0 -0.1" xyaxes="0 1 0 -1 0 0"/>
        <body name="bracket" pos="0 0 -0.2" quat="0.9 0.1 0.3 0.2">
          <geom type="ellipsoid" size="0.03 0.05 0.07" class="main"/>
          <body name="tip" pos="0.05 0 -0.05" zaxis="1 0 1">
            <inertial pos="0.01 0.02 0.03" quat="0.8 0.2 0.1 0.3" mass="0.4"
                      diaginertia="0.002 0.003 0.004"/>
            <joint name="wrist" type="hinge" axis="0 0 1" pos="0 0.01 0" class="main"/>
            <geom type="box" size="0.1 0.1 0.1"/>
          </body>
        </body>
      </body>
    </body>
    <body name="other" pos="0.5 0 0.5">
      <inertial pos="0.1 0 0" mass="1" fullinertia="0.01 0.02 0.025 0.001 0.002 0.003"/>
      <joint name="spin" axis="0 0 1" pos="0 0.1 0"/>
    </body>
  </worldbody>
</mujoco>
"""
"""Default classes (nested, childclass, class), every orientation form, a mixed-case euler
sequence, pivots off the bodies' origins, a welded body, geom masses by density and by
``mass``, an explicit and a full inertia, two top-level bodies."""

RICH_POSE = {"arm/swing": 0.3, "arm/rail": 0.05, "arm/wrist": -0.7, "arm/spin": 1.0}
RICH_RATES = {"arm/swing": -0.4, "arm/rail": 0.3, "arm/wrist": 1.1, "arm/spin": 0.2}


def rich(folder: Path, **fields):
    (folder / "rich.xml").write_text(RICH)
    return load_scenario(
        write_scene(
            folder,
            {"file": "rich.xml", "joint_positions": RICH_POSE, "joint_velocities": RICH_RATES}
            | fields,
        )
    )


def test_the_rich_file_reads_its_classes_welds_and_units(tmp_path):
    joints = {j.name: j for j in rich(tmp_path).joints}
    assert [(n, j.type) for n, j in joints.items()] == [
        ("arm/swing", "hinge"),
        ("arm/rail", "slider"),  # the class "heavy" (childclass of mid)
        ("arm/bracket.weld", "fixed"),  # no joint: welded to mid
        ("arm/wrist", "hinge"),  # class="main" on the element beats the childclass
        ("arm/spin", "hinge"),
    ]
    assert joints["arm/rail"].damping == 0.2  # "heavy" inherits main's joint damping
    # range="-60 45" in degrees (MJCF's default angle unit), relative to the initial 0.3 rad
    assert joints["arm/swing"].limits == pytest.approx(
        (math.radians(-60) - 0.3, math.radians(45) - 0.3)
    )


def mujoco_model(path: Path, pose: dict, rates: dict):
    mujoco = pytest.importorskip("mujoco")
    model = mujoco.MjModel.from_xml_path(str(path))
    data = mujoco.MjData(model)
    for name, value in pose.items():
        data.qpos[model.joint(name.removeprefix("arm/")).qposadr[0]] = value
    for name, value in rates.items():
        data.qvel[model.joint(name.removeprefix("arm/")).dofadr[0]] = value
    mujoco.mj_forward(model, data)
    return mujoco, model, data


CASES = {
    "pendulum": (PENDULUM, {"arm/slider": 0.2, "arm/hinge": 0.5, "arm/hinge2": -0.8}, {
        "arm/slider": 0.3, "arm/hinge": -1.0, "arm/hinge2": 0.7}),
    "rich": ("rich.xml", RICH_POSE, RICH_RATES),
}  # fmt: skip


@pytest.mark.parametrize("case", sorted(CASES))
def test_masses_inertias_and_poses_equal_mujocos_compiled_model(tmp_path, case):
    """MuJoCo's ``body_mass``, ``body_ipos``, ``body_inertia`` (principal, turned by
    ``body_iquat``), link frames (``xpos``/``xmat``), centres (``xipos``) and centre
    velocities at a pose, against physval's reading: MuJoCo's capsule, cylinder, box and
    ellipsoid formulas are the exact solids', so they agree to round-off."""
    file, pose, rates = CASES[case]
    (tmp_path / "rich.xml").write_text(RICH)
    scenario = load_scenario(
        write_scene(tmp_path, {"file": file, "joint_positions": pose, "joint_velocities": rates})
    )
    (layout,) = compile_scene(scenario).models
    mujoco, model, data = mujoco_model(model_path(file, tmp_path / "x.yaml"), pose, rates)
    bodies = {b.name: b for b in scenario.bodies}
    for body, link, in_link in zip(layout.bodies, layout.links, layout.body_in_link, strict=True):
        index = model.body(link).id
        mine = bodies[body]
        assert mine.mass == pytest.approx(model.body_mass[index], rel=MASS_TOLERANCE), link
        assert np.allclose(in_link.translation, model.body_ipos[index], atol=1e-12), link
        turn = np.zeros(9)
        mujoco.mju_quat2Mat(turn, model.body_iquat[index])
        theirs = turn.reshape(3, 3) @ np.diag(model.body_inertia[index]) @ turn.reshape(3, 3).T
        ours = in_link.rotation @ mine.inertia_matrix @ in_link.rotation.T  # in the link frame
        assert np.allclose(ours, theirs, rtol=0, atol=MASS_TOLERANCE * np.abs(theirs).max()), link
        assert np.allclose(mine.position, data.xipos[index], atol=POSE_TOLERANCE), link
        w, x, y, z = mine.orientation
        link_axes = Rotation.from_quat([x, y, z, w]).as_matrix() @ in_link.rotation.T
        assert np.allclose(link_axes, data.xmat[index].reshape(3, 3), atol=POSE_TOLERANCE), link
        velocity = np.zeros(6)  # angular, linear: of the centre of mass, world frame
        mujoco.mj_objectVelocity(model, data, mujoco.mjtObj.mjOBJ_BODY, index, velocity, 0)
        assert np.allclose(mine.angular_velocity, velocity[:3], atol=POSE_TOLERANCE), link
        assert np.allclose(mine.velocity, velocity[3:], atol=POSE_TOLERANCE), link


SMALL = """<mujoco>
  <default><joint damping="0.05"/></default>
  <worldbody>
    <body name="cart">
      <joint name="slider" type="slide" axis="1 0 0" range="-1 1"/>
      <geom type="box" size="0.1 0.1 0.1"/>
      <body name="pole">
        <joint name="hinge" axis="0 1 0"/>
        <geom type="capsule" fromto="0 0 0 0 0 0.6" size="0.045"/>
      </body>
    </body>
  </worldbody>
</mujoco>
"""
"""A cart and pole that loads; each case of ``BROKEN`` breaks one rule of the subset."""

POLE_JOINT = '<joint name="hinge" axis="0 1 0"/>'
POLE_GEOM = '<geom type="capsule" fromto="0 0 0 0 0 0.6" size="0.045"/>'

BROKEN = {
    "not MJCF": ("<robot/>", "expected a <mujoco> root"),
    "not XML": ("<mujoco", "cannot read"),
    "include": (SMALL.replace("<worldbody>", '<include file="more.xml"/><worldbody>'), "<include>"),
    "equality": (SMALL.replace("</mujoco>", "<equality/></mujoco>"), "<equality>"),
    "frame": (SMALL.replace(POLE_GEOM, f"<frame>{POLE_GEOM}</frame>"), "<frame> in body 'pole'"),
    "ball joint": (SMALL.replace(POLE_JOINT, '<joint name="hinge" type="ball"/>'), "'ball'"),
    "free joint inside": (
        SMALL.replace(POLE_JOINT, '<freejoint name="loose"/>'),
        "'free': inside the tree",
    ),
    "two joints": (
        SMALL.replace(POLE_JOINT, POLE_JOINT + '<joint name="twist" axis="0 0 1"/>'),
        "body 'pole' has 2 joints",
    ),
    "mesh mass": (
        SMALL.replace(POLE_GEOM, '<geom type="mesh" mesh="pole"/>'),
        "a mesh geom in body 'pole' would give it mass",
    ),
    "armature": (SMALL.replace('axis="0 1 0"', 'axis="0 1 0" armature="0.1"'), "armature=0.1"),
    "global coordinates": (
        SMALL.replace("<default>", '<compiler coordinate="global"/><default>'),
        "local only",
    ),
    "unknown class": (SMALL.replace('name="hinge"', 'name="hinge" class="stiff"'), "'stiff'"),
    "unnamed body": (SMALL.replace('<body name="pole">', "<body>"), "without a name"),
    "unnamed joint": (SMALL.replace(POLE_JOINT, '<joint axis="0 1 0"/>'), "has no name"),
    "empty range": (SMALL.replace('range="-1 1"', 'range="1 1"'), "lower < upper"),
    "massless moving body": (SMALL.replace(POLE_GEOM, ""), "'pole' has no mass but moves"),
    "free beside others": (
        SMALL.replace("</worldbody>", '<body name="ball"><freejoint/></body></worldbody>'),
        "free joint beside other top-level bodies",
    ),
    "missing mesh": (
        SMALL.replace("<worldbody>", '<asset><mesh file="pole.stl"/></asset><worldbody>'),
        "mesh 'pole.stl' not found",
    ),
}


@pytest.mark.parametrize("case", sorted(BROKEN))
def test_an_mjcf_outside_the_subset_is_one_line_at_file(tmp_path, case):
    text, what = BROKEN[case]
    (tmp_path / "small.xml").write_text(SMALL)
    load_scenario(write_scene(tmp_path, {"file": "small.xml"}))  # the unbroken file loads
    (tmp_path / "small.xml").write_text(text)
    assert_refused_at_file(tmp_path, "small.xml", what)


@pytest.mark.parametrize("unit, factor", [("degree", math.pi / 180), ("radian", 1.0)])
def test_a_hinges_range_is_in_the_compilers_angle_unit(tmp_path, unit, factor):
    text = SMALL.replace("<default>", f'<compiler angle="{unit}"/><default>')
    (tmp_path / "small.xml").write_text(
        text.replace(POLE_JOINT, POLE_JOINT[:-2] + ' range="-1 2"/>')
    )
    joints = load_scenario(write_scene(tmp_path, {"file": "small.xml"})).joints
    assert joints[0].limits == (-1.0, 1.0)  # the slide's range: metres in either unit
    assert joints[1].limits == pytest.approx((-factor, 2 * factor))


def test_a_free_base_needs_a_top_level_freejoint(tmp_path):
    (tmp_path / "small.xml").write_text(SMALL)
    with pytest.raises(ScenarioError) as raised:
        load_scenario(write_scene(tmp_path, {"file": "small.xml", "fixed_base": False}))
    (problem,) = raised.value.problems
    assert problem.path == "models[0].fixed_base" and "<freejoint/>" in problem.message


def test_the_one_top_level_body_with_a_freejoint_is_the_root(tmp_path):
    free = SMALL.replace('<body name="cart">', '<body name="cart"><freejoint name="base"/>')
    (tmp_path / "free.xml").write_text(free.replace('<joint name="slider"', '<site name="s"'))
    held = load_scenario(write_scene(tmp_path, {"file": "free.xml"}))
    assert [(j.name, j.parent) for j in held.joints] == [
        ("arm/fixed_base", "world"),
        ("arm/hinge", "arm/cart"),
    ]
    loose = load_scenario(write_scene(tmp_path, {"file": "free.xml", "fixed_base": False}))
    assert [j.name for j in loose.joints] == ["arm/hinge"]
    (layout,) = compile_scene(loose).models
    assert layout.root_link == "cart"


@pytest.mark.parametrize("engine", ENGINES)
def test_the_undamped_pendulum_runs_in_every_engine_with_joints_and_keeps_its_energy(
    tmp_path, engine
):
    if not_installed(engine):
        pytest.skip(not_installed(engine))
    text = model_path(PENDULUM, tmp_path / "x.yaml").read_text()
    (tmp_path / "pendulum.xml").write_text(text.replace('<joint damping="0.05"/>', ""))
    scenario = load_scenario(
        write_scene(
            tmp_path,
            {"file": "pendulum.xml", "joint_positions": {"arm/hinge": 0.3, "arm/hinge2": -0.2}},
        )
    )
    assert {j.damping for j in scenario.joints} == {0.0}
    assert_energy_kept(scenario, engine)
