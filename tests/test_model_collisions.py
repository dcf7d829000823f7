"""A model's collision shapes (``collisions: true``, issue 36): each link's one collision
element becomes its body's shape, placed in the body frame (the link's inertial frame) by the
shape's ``offset`` and ``orientation``, with ``collides: true``; checked against the files'
own numbers, PyBullet's ``getCollisionShapeData`` poses (URDF) and MuJoCo's compiled geoms
(MJCF); every model the one-shape rule cannot take is refused at ``models[i].collisions``."""

from __future__ import annotations

from pathlib import Path

import mujoco
import numpy as np
import pybullet
import pytest
import yaml

from validation.reference.rotation import quat_to_matrix
from validation.scenario.load import load_scenario
from validation.scenario.problems import ScenarioError
from validation.scenario.schema import BodySpec, ModelSpec
from validation.scenario.urdf import PLACEHOLDER_RADIUS, expand_model, model_path

PENDULUM = "pkg:pybullet_data/pendulum5.urdf"
CARTPOLE = "pkg:pybullet_data/cartpole.urdf"
A1 = "pkg:pybullet_data/a1/a1.urdf"
DOUBLE_PENDULUM = "pkg:pybullet_data/mjcf/inverted_double_pendulum.xml"
BASE = [0.2, -0.1, 0.8]
BASE_TURN = [float(np.cos(0.3)), 0.0, 0.0, float(np.sin(0.3))]  # 0.6 rad about z

POSE_TOLERANCE = 1e-9
"""m and |Δ rotation matrix|: physval's placed shape against PyBullet's collision shape (its
inertial frame's pose times ``getCollisionShapeData``'s local frame) and MuJoCo's geom
(``geom_xpos``/``geom_xmat``). Both compose the file's transforms in double precision
(measured: centres 5.0e-16 m and axes 6.9e-16 on the A1, 0 m and 2.2e-16 on the double
pendulum); the URDF's π/2 written to 12 digits is the same number on each side."""

SIZE_TOLERANCE = 1e-12
"""m: the shape's sizes against the file's: a half of a decimal number as written."""


def scene(folder: Path, file: str, **fields):
    entry = {"name": "m", "file": file, "collisions": True, **fields}
    document = {"dt": 0.001, "duration": 0.1, "engines": ["mini"], "models": [entry]}
    path = folder / "scene.yaml"
    path.write_text(yaml.safe_dump(document, sort_keys=False))
    return load_scenario(path)


def shape_world(body) -> tuple[np.ndarray, np.ndarray]:
    """The body's shape's centre and axes in the world."""
    rotation = quat_to_matrix(np.array(body.orientation, dtype=float))
    turn = quat_to_matrix(np.array(body.shape.orientation, dtype=float))
    return np.asarray(body.position) + rotation @ np.asarray(body.shape.offset), rotation @ turn


def test_pendulum5s_spheres_and_cartpoles_boxes_are_their_bodies_shapes(tmp_path):
    pendulum = scene(tmp_path, PENDULUM)
    assert [b.shape.type for b in pendulum.bodies] == ["sphere"] * 5
    assert all(b.shape.radius == 0.05 and b.collides for b in pendulum.bodies)
    assert not any(b.shape.placed for b in pendulum.bodies)  # at each link's centre of mass
    cartpole = scene(tmp_path, CARTPOLE)
    shapes = {b.name: b.shape for b in cartpole.bodies}
    assert shapes["m/cart"].half_extents == pytest.approx((0.25, 0.25, 0.1), abs=SIZE_TOLERANCE)
    assert shapes["m/pole"].half_extents == pytest.approx((0.025, 0.025, 0.5), abs=SIZE_TOLERANCE)
    assert all(b.collides and b.friction == 0.0 and b.restitution == 0.0 for b in cartpole.bodies)


def _pybullet_shapes(file: Path, positions: dict[str, float]) -> dict[str, tuple]:
    """PyBullet's collision shape per link: (type, dimensions, world centre, world axes), the
    file's joints at ``positions`` (file joint name -> coordinate)."""
    client = pybullet.connect(pybullet.DIRECT)
    try:
        w, x, y, z = BASE_TURN
        body = pybullet.loadURDF(
            str(file), BASE, [x, y, z, w], useFixedBase=True,
            flags=pybullet.URDF_USE_INERTIA_FROM_FILE | pybullet.URDF_USE_IMPLICIT_CYLINDER,
            physicsClientId=client,
        )  # fmt: skip
        found = {}
        for link in range(-1, pybullet.getNumJoints(body, physicsClientId=client)):
            if link >= 0:
                info = pybullet.getJointInfo(body, link, physicsClientId=client)
                if info[3] >= 0:
                    start = positions[info[1].decode()]
                    pybullet.resetJointState(body, link, start, physicsClientId=client)
        for link in range(-1, pybullet.getNumJoints(body, physicsClientId=client)):
            if link < 0:
                name = pybullet.getBodyInfo(body, physicsClientId=client)[0].decode()
                where = pybullet.getBasePositionAndOrientation(body, physicsClientId=client)
            else:
                name = pybullet.getJointInfo(body, link, physicsClientId=client)[12].decode()
                where = pybullet.getLinkState(
                    body, link, computeForwardKinematics=1, physicsClientId=client
                )[:2]
            (data,) = pybullet.getCollisionShapeData(body, link, physicsClientId=client)
            frame = _pose(*where)
            local = _pose(data[5], data[6])
            centre = frame[0] + frame[1] @ local[0]
            found[name] = (data[2], data[3], centre, frame[1] @ local[1])
        return found
    finally:
        pybullet.disconnect(client)


def _pose(position, xyzw) -> tuple[np.ndarray, np.ndarray]:
    x, y, z, w = xyzw
    return np.asarray(position, dtype=float), quat_to_matrix(np.array([w, x, y, z], dtype=float))


PYBULLET_SIZES = {
    pybullet.GEOM_SPHERE: lambda s: (s.radius,),
    pybullet.GEOM_BOX: lambda s: tuple(2 * v for v in s.half_extents),
    pybullet.GEOM_CYLINDER: lambda s: (2 * s.half_length, s.radius),
}
"""PyBullet's geometry type -> a scene shape's numbers as ``getCollisionShapeData`` gives them
(a box's full extents; a cylinder's length, radius)."""

PYBULLET_TYPES = {
    pybullet.GEOM_SPHERE: "sphere",
    pybullet.GEOM_BOX: "box",
    pybullet.GEOM_CYLINDER: "cylinder",
}


A1_POSE = {
    f"{leg}_{joint}_joint": angle
    for leg in ("FR", "FL", "RR", "RL")
    for joint, angle in (("hip", 0.1), ("upper", 0.6), ("lower", -1.2))
}
"""rad: a stance inside every limit of the A1 (its knees' are [-2.70, -0.92])."""


def test_the_a1s_boxes_cylinders_and_spheres_sit_where_pybullet_puts_them(tmp_path):
    """The expansion itself (the scene check refuses the A1's cylinder-box pairs, which the
    reference does not measure yet: a finding of the check, not of the placement)."""
    model = ModelSpec(
        name="m",
        file=A1,
        position=BASE,
        orientation=BASE_TURN,
        joint_positions={f"m/{name}": angle for name, angle in A1_POSE.items()},
        collisions=True,
    )
    bodies = [BodySpec.model_validate(b) for b in expand_model(model, tmp_path / "s.yaml")[0]]
    found = _pybullet_shapes(model_path(A1, tmp_path), A1_POSE)
    kinds = {b.shape.type for b in bodies}
    assert kinds == {"box", "cylinder", "sphere"}
    assert sum(b.shape.placed for b in bodies) >= 12  # hips, thighs, calves, trunk
    for body in bodies:
        kind, dimensions, centre, axes = found[body.name.removeprefix("m/")]
        assert body.collides and PYBULLET_TYPES[kind] == body.shape.type, body.name
        wanted = PYBULLET_SIZES[kind](body.shape)
        assert dimensions[: len(wanted)] == pytest.approx(wanted, abs=SIZE_TOLERANCE), body.name
        ours_centre, ours_axes = shape_world(body)
        assert np.abs(ours_centre - centre).max() < POSE_TOLERANCE, body.name
        if body.shape.type == "cylinder":  # turned about its own axis it is the same shape
            ours_axes, axes = ours_axes[:, 2], axes[:, 2]
        assert np.abs(ours_axes - axes).max() < POSE_TOLERANCE, body.name


def test_the_inverted_double_pendulums_capsules_sit_where_mujoco_puts_them(tmp_path):
    scenario = scene(tmp_path, DOUBLE_PENDULUM, joint_positions={"m/hinge": 0.4})
    model = mujoco.MjModel.from_xml_path(str(model_path(DOUBLE_PENDULUM, tmp_path)))
    data = mujoco.MjData(model)
    data.qpos[model.jnt_qposadr[model.joint("hinge").id]] = 0.4
    mujoco.mj_forward(model, data)
    assert [b.shape.type for b in scenario.bodies] == ["capsule"] * 3
    for body in scenario.bodies:
        link = model.body(body.name.removeprefix("m/")).id
        (geom,) = np.flatnonzero(model.geom_bodyid == link)
        radius, half_length = model.geom_size[geom][:2]
        assert (body.shape.radius, body.shape.half_length) == pytest.approx(
            (radius, half_length), abs=SIZE_TOLERANCE
        )
        centre, axes = shape_world(body)
        assert np.abs(centre - data.geom_xpos[geom]).max() < POSE_TOLERANCE, body.name
        axis = data.geom_xmat[geom].reshape(3, 3)[:, 2]  # MuJoCo's fromto points its z to "from"
        apart = min(np.abs(axes[:, 2] - axis).max(), np.abs(axes[:, 2] + axis).max())
        assert apart < POSE_TOLERANCE, body.name  # end for end, a capsule is the same


ONE_LINK = """<robot name="one">
  <link name="base"/>
  <link name="arm">
    <inertial><origin xyz="0 0 -0.2" rpy="0.3 0 0"/><mass value="1"/>
      <inertia ixx="0.01" iyy="0.02" izz="0.03" ixy="0" ixz="0" iyz="0"/></inertial>
    {collisions}
  </link>
  <joint name="pin" type="continuous"><parent link="base"/><child link="arm"/>
    <axis xyz="0 1 0"/></joint>
</robot>
"""

SPHERE = (
    '<collision><origin xyz="0 0 -0.4"/><geometry><sphere radius="0.1"/></geometry></collision>'
)
MESH = '<collision><geometry><mesh filename="arm.obj"/></geometry></collision>'

REFUSALS = {
    "two elements": (SPHERE * 2, "link 'arm' has 2 collision elements"),
    "a mesh": (MESH, "link 'arm''s collision geometry is 'mesh'"),
}


@pytest.mark.parametrize("case", sorted(REFUSALS))
def test_a_link_the_one_shape_rule_cannot_take_is_one_line_at_collisions(tmp_path, case):
    collisions, message = REFUSALS[case]
    (tmp_path / "arm.obj").write_text("v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n")
    (tmp_path / "one.urdf").write_text(ONE_LINK.format(collisions=collisions))
    with pytest.raises(ScenarioError) as raised:
        scene(tmp_path, "one.urdf")
    (problem,) = raised.value.problems
    assert problem.path == "models[0].collisions" and message in problem.message, str(problem)


def test_a_placed_sphere_is_the_collision_origin_seen_from_the_inertial_frame(tmp_path):
    (tmp_path / "one.urdf").write_text(ONE_LINK.format(collisions=SPHERE))
    (body,) = scene(tmp_path, "one.urdf").bodies
    # the inertial frame: 0.2 m down, turned 0.3 rad about x; the sphere 0.4 m down
    turn = quat_to_matrix(np.array(body.shape.orientation))
    assert turn @ [1, 0, 0] == pytest.approx([1, 0, 0])
    assert turn @ [0, 1, 0] == pytest.approx([0, np.cos(0.3), -np.sin(0.3)])
    rotation = np.array([[1, 0, 0], [0, np.cos(0.3), -np.sin(0.3)], [0, np.sin(0.3), np.cos(0.3)]])
    assert body.shape.offset == pytest.approx(rotation.T @ [0, 0, -0.2], abs=1e-15)


def test_a_link_without_collision_keeps_the_placeholder_that_touches_nothing(tmp_path):
    (tmp_path / "one.urdf").write_text(ONE_LINK.format(collisions=""))
    (body,) = scene(tmp_path, "one.urdf").bodies
    assert (body.shape.type, body.shape.radius, body.collides) == (
        "sphere",
        PLACEHOLDER_RADIUS,
        False,
    )


# --- native loaders with collisions: true ----------------------------------------------------

SWING = 1.0
"""s: pendulum5 hung 0.6 m above the ground swings down through it within this (its 2.5 m
chain reaches 1.9 m below the ground without contact)."""

RESTING_DEPTH = 0.01
"""m: how far a link's centre may end below its sphere's radius above the ground: the
contact's penetration (measured: lowest centres 0.0470 m MuJoCo, 0.0500 PyBullet, 0.0486
Drake, 0.0471 mini for radius 0.05 m)."""

NATIVE = ("mujoco", "pybullet", "drake")


def _falling_pendulum(folder: Path, collisions: bool):
    from validation.scenario.compiled import compile_scene

    document = {
        "dt": 0.001,
        "duration": SWING,
        "engines": list(NATIVE),
        "ground": {"restitution": 0.0, "friction": 0.5},
        "models": [
            {"name": "p", "file": PENDULUM, "position": [0, 0, 0.6], "collisions": collisions}
        ],
    }
    path = folder / f"fall{collisions}.yaml"
    path.write_text(yaml.safe_dump(document, sort_keys=False))
    return compile_scene(load_scenario(path))


def _lowest(scene, engine: str) -> float:
    """m: the lowest model body centre over the swing (every 0.1 s) in ``engine``'s native
    loading."""
    from validation.engines.registry import create_adapter
    from validation.scenario.engine_spec import parse_engine_spec

    adapter = create_adapter(parse_engine_spec(engine))
    adapter.load(scene)
    lowest = np.inf
    try:
        for _ in range(round(SWING / 0.1)):
            adapter.advance(100)
            lowest = min(lowest, float(np.asarray(adapter.observe().pos)[..., 2].min()))
    finally:
        getattr(adapter, "close", lambda: None)()
    return lowest


@pytest.mark.parametrize("engine", NATIVE)
def test_a_native_loaders_model_meets_the_ground_only_with_collisions(tmp_path, engine):
    assert _lowest(_falling_pendulum(tmp_path, False), engine) < 0.0
    radius = 0.05  # pendulum5's spheres
    assert _lowest(_falling_pendulum(tmp_path, True), engine) > radius - RESTING_DEPTH


def test_mujocos_pairs_carry_the_scenes_values_not_the_files(tmp_path):
    """Each model geom pairs with the ground at the ground's own solref/solimp (the scene's
    restitution for a link of restitution 0) and condim 1 (friction √(0·μ) = 0)."""
    from validation.engines.mujoco.adapter import MujocoAdapter
    from validation.scenario.engine_spec import parse_engine_spec

    adapter = MujocoAdapter(parse_engine_spec("mujoco"))
    adapter.load(_falling_pendulum(tmp_path, True))
    model = adapter.model
    ground = model.geom("ground").id
    assert model.npair == 5 and ((model.pair_geom1 == ground) | (model.pair_geom2 == ground)).all()
    assert (model.pair_dim == 1).all()
    assert np.array_equal(model.pair_solref, np.repeat(model.geom_solref[[ground]], 5, axis=0))
    model_geoms = [g for g in range(model.ngeom) if g != ground]
    assert (
        not model.geom_contype[model_geoms].any() and not model.geom_conaffinity[model_geoms].any()
    )


def test_drakes_model_geometry_has_the_scenes_friction(tmp_path):
    from pydrake.geometry import Role

    from validation.engines.drake.adapter import DrakeAdapter
    from validation.engines.drake.models import FRICTION_PROPERTY
    from validation.scenario.engine_spec import parse_engine_spec
    from validation.scenario.urdf import LINK_CONTACT

    adapter = DrakeAdapter(parse_engine_spec("drake"))
    adapter.load(_falling_pendulum(tmp_path, True))
    inspector = adapter.diagram.GetSubsystemByName("scene_graph").model_inspector()
    (model,) = adapter.models
    assert len(model.geometry) == 5 and not model.idle
    for gid in model.geometry:
        friction = inspector.GetProximityProperties(gid).GetProperty(*FRICTION_PROPERTY)
        assert friction.static_friction() == LINK_CONTACT["friction"]
    assert set(model.geometry) <= set(inspector.GetAllGeometryIds(Role.kProximity))
