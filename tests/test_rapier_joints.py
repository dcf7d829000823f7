"""Rapier's joints (validation/engines/rapier/joints.py), multibody and impulse: every joint
type follows the reference's joint-space motion, a joint's two bodies never touch while other
pairs do, a joint's damping decays at its exponential rate and its limits stop it, a jointed
body's velocity read back is the one that moved it (a multibody link's rigid body carries the
previous substep's), reading never moves the run, and the joints Rapier built are the scene's
(the parity gate's joint report). One engine finding is asserted at its measured size: a
multibody ball joint's link drifts off its point.

The compound and double pendulums against closed forms are in tests/test_joint_scenes.py
(``rapier`` and ``rapier(joints=impulse)`` in its parametrization); the numbers here are
docs/engines-rapier.md section 9.
"""

from __future__ import annotations

import importlib.util
from pathlib import Path

import numpy as np
import pytest
from test_joint_scenes import off_the_reference, recorded

from validation.engines.base import Snapshot, Trajectory
from validation.engines.joint_parity import compare_joints, expected_report
from validation.engines.parity import PRECISION_TOLERANCE
from validation.engines.registry import create_adapter
from validation.measure.resolution import FLOAT32_UNIT_ROUNDOFF
from validation.reference.articulated import joint_coordinates, joint_violations
from validation.reference.rotation import quat_to_matrix
from validation.scenario import Scenario, load_scenario
from validation.scenario.compiled import compile_scene
from validation.scenario.engine_spec import parse_engine_spec

pytestmark = pytest.mark.skipif(
    importlib.util.find_spec("rapier3d") is None,
    reason='needs rapier3d: pip install "physval[rapier]"',
)

KINDS = ("rapier", "rapier(joints=impulse)")
"""Rapier's two joint sets (``declaration.JOINT_KINDS``), multibody the default."""

DT = 1e-3
SUBSTEPS = 4
"""Rapier's state updates per step (engines-rapier.md 3), each rounding to float32."""


# --- every joint type against the reference ------------------------------------------------

RAIL = np.array([0.6, 0.0, -0.8])
CARRIAGE = np.array([0.0, 0.0, 2.0])
BOB = np.array([0.3, 0.1, 1.6])
FIN = BOB + np.array([0.15, 0.0, 0.0])
SPIN = np.array([1.0, 0.0, 2.0])


def slider_ball_weld(engine: str) -> Scenario:
    """A carriage sliding down a tilted rail (slider), a bob hung from it by a ball joint,
    spinning, and a fin welded to the bob (fixed): each body's stated velocity the one the
    joints allow (the carriage at 0.5 m/s along the rail)."""
    carriage_velocity = 0.5 * RAIL
    bob_velocity = carriage_velocity + np.cross(SPIN, BOB - CARRIAGE)
    fin_velocity = bob_velocity + np.cross(SPIN, FIN - BOB)
    return Scenario.model_validate(
        {
            "name": "slider_ball_weld",
            "dt": DT,
            "duration": 1.0,
            "engines": [engine],
            "bodies": [
                {"name": "carriage", "shape": {"type": "box", "half_extents": [0.1, 0.1, 0.05]},
                 "mass": 2.0, "position": CARRIAGE.tolist(),
                 "velocity": carriage_velocity.tolist()},
                {"name": "bob", "shape": {"type": "sphere", "radius": 0.05}, "mass": 1.0,
                 "position": BOB.tolist(), "velocity": bob_velocity.tolist(),
                 "angular_velocity": SPIN.tolist()},
                {"name": "fin", "shape": {"type": "box", "half_extents": [0.1, 0.02, 0.03]},
                 "mass": 0.5, "position": FIN.tolist(), "velocity": fin_velocity.tolist(),
                 "angular_velocity": SPIN.tolist()},
            ],
            "joints": [
                {"name": "rail", "type": "slider", "parent": "world", "child": "carriage",
                 "anchor": CARRIAGE.tolist(), "axis": RAIL.tolist()},
                {"name": "socket", "type": "ball", "parent": "carriage", "child": "bob",
                 "anchor": CARRIAGE.tolist()},
                {"name": "weld", "type": "fixed", "parent": "bob", "child": "fin",
                 "anchor": BOB.tolist()},
            ],
        }
    )  # fmt: skip


FLOAT32_POSITION_FLOOR = round(1.0 / DT) * SUBSTEPS * FLOAT32_UNIT_ROUNDOFF * 2.0
"""m, 4.8e-4: what float32 can resolve of a position up to 2 m carried over 1 s of 4
substeps a step (validation/measure/resolution.py's floor for a carried value)."""

REFERENCE_TOLERANCE = 5e-3 + FLOAT32_POSITION_FLOOR
"""m over 1 s against the reference's DOP853: a first-order scheme's O(dt)·|a|·t (the bound
tests/test_joint_scenes.py gives MuJoCo and mini, which measure 3.2e-3 and 1.1e-2 on this
scene) plus the float32 floor. Measured: 1.3e-3 m (multibody), 1.0e-3 m (impulse)."""

VIOLATION_BOUND = {"rapier": 5e-5, "rapier(joints=impulse)": 1e-4}
"""m, the largest separation of a joint's two anchors over 1 s, measured with a margin of 3:
the multibody's ball joint 1.5e-5 m (Rapier's ball-jointed link drifts off its joint point,
``test_a_multibody_ball_joint_drifts_off_its_point``), the impulse joints' 4.1e-5 m (the
ball, a constraint solved once per substep)."""


@pytest.mark.parametrize("engine", KINDS)
def test_a_slider_a_ball_and_a_weld_follow_the_joint_space_reference(engine):
    scenario = slider_ball_weld(engine)
    scene, trajectory = recorded(engine, scenario)
    difference = off_the_reference(scenario, scene, trajectory)
    assert difference < REFERENCE_TOLERANCE, (engine, difference)
    separation, _, _ = joint_violations(
        scene.joint_tree, trajectory.pos, quat_to_matrix(trajectory.quat)
    )
    assert separation.max() < VIOLATION_BOUND[engine], (engine, separation.max(axis=0))


def pendulum(engine: str, kind: str) -> Scenario:
    """A 1 kg ball 1 m from a hinge (about y) or a ball joint at (0, 0, 3) m, 30° off the
    vertical, released from rest: it swings in the x-z plane."""
    joint = {
        "name": "pivot",
        "type": kind,
        "parent": "world",
        "child": "bob",
        "anchor": [0.0, 0.0, 3.0],
    }
    if kind == "hinge":
        joint["axis"] = [0.0, 1.0, 0.0]
    return Scenario.model_validate(
        {
            "name": f"{kind}_pendulum",
            "dt": DT,
            "duration": 1.0,
            "engines": [engine],
            "bodies": [{"name": "bob", "shape": {"type": "sphere", "radius": 0.05},
                        "mass": 1.0, "position": [0.5, 0.0, 3.0 - 0.75**0.5]}],
            "joints": [joint],
        }
    )  # fmt: skip


HELD = 1e-6
"""m: a joint held to float32 (positions near 3 m, an ulp 2.4e-7): a multibody hinge measures
3.1e-7 m over 1 s, impulse joints 4.9e-7 (hinge) and 4.4e-7 (ball)."""

BALL_DRIFT = (3e-5, 3e-4)
"""m, where Rapier's multibody ball joint's drift over 1 s lies (an engine finding, measured
8.3e-5 m here, 1.4e-4 on the library's conical pendulum): its link's rotation is the joint's,
its position drifts off the joint point (engines-rapier.md 9). Leaving this range is news."""


def pendulum_separation(engine: str, kind: str) -> float:
    scene, trajectory = recorded(engine, pendulum(engine, kind))
    separation, _, _ = joint_violations(
        scene.joint_tree, trajectory.pos, quat_to_matrix(trajectory.quat)
    )
    return float(separation.max())


def test_a_multibody_ball_joint_drifts_off_its_point():
    """The finding, asserted at its measured size: the same swing holds a multibody hinge, and
    an impulse ball joint, to float32; Rapier's multibody ball joint drifts."""
    assert pendulum_separation("rapier", "hinge") < HELD
    assert pendulum_separation("rapier(joints=impulse)", "ball") < HELD
    drift = pendulum_separation("rapier", "ball")
    assert BALL_DRIFT[0] < drift < BALL_DRIFT[1], drift


# --- contacts -----------------------------------------------------------------------------


def overlapping_chain(engine: str) -> Scenario:
    """Three balls of r = 0.4 m in a chain (hinge, hinge, ball) whose every two overlap: a-b
    and b-c are joints' pairs, a-c (grandparent and grandchild) is not."""
    ball = lambda name, position: {  # noqa: E731
        "name": name,
        "shape": {"type": "sphere", "radius": 0.4},
        "mass": 1.0,
        "position": position,
    }
    return Scenario.model_validate(
        {
            "name": "overlapping_chain",
            "dt": DT,
            "duration": 10 * DT,
            "engines": [engine],
            "gravity": [0.0, 0.0, 0.0],
            "bodies": [ball("a", [0.6, 0.0, 2.0]), ball("b", [0.6, 0.6, 2.0]),
                       ball("c", [0.6, 0.2, 2.0])],
            "joints": [
                {"name": "j1", "type": "hinge", "parent": "world", "child": "a",
                 "anchor": [0.0, 0.0, 2.0], "axis": [0.0, 1.0, 0.0]},
                {"name": "j2", "type": "hinge", "parent": "a", "child": "b",
                 "anchor": [0.6, 0.0, 2.0], "axis": [1.0, 0.0, 0.0]},
                {"name": "j3", "type": "ball", "parent": "b", "child": "c",
                 "anchor": [0.6, 0.6, 2.0]},
            ],
        }
    )  # fmt: skip


@pytest.mark.parametrize("engine", KINDS)
def test_a_joints_two_bodies_never_touch_in_rapier_while_other_pairs_do(engine):
    adapter = create_adapter(parse_engine_spec(engine))
    adapter.load(compile_scene(overlapping_chain(engine)))
    adapter.advance(1)
    world = adapter.world
    colliders = [world.rigid_bodies[h].colliders[0] for h in adapter.handles]

    def touching(i: int, j: int) -> bool:
        pair = world.narrow_phase.contact_pair(colliders[i], colliders[j])
        return pair is not None and pair.has_any_active_contact

    assert not touching(0, 1) and not touching(1, 2), engine
    assert touching(0, 2), engine  # a multibody's other pairs keep their contacts
    adapter.close()


# --- damping and limits -------------------------------------------------------------------

WHEEL_MASS = 2.0
WHEEL_HALF = (0.3, 0.1, 0.05)
WHEEL_INERTIA = WHEEL_MASS * (4 * WHEEL_HALF[0] ** 2 + 4 * WHEEL_HALF[1] ** 2) / 12
"""kg·m², the box's moment about z through its centre (the hinge)."""
DAMPING = 0.05
"""N·m·s/rad: ω(t) = ω0 exp(-c t / I), 0.945 ω0 left at 1 s."""
SPIN_RATE = 2.0

DAMPED_STEPS = round(1.0 / DT)
DAMPING_TOLERANCE = DAMPED_STEPS * (
    (DAMPING * DT / WHEEL_INERTIA) ** 2 / 2 + SUBSTEPS * FLOAT32_UNIT_ROUNDOFF
)
"""Relative, 5.2e-4: a first-order damping step's error over n steps of dt, n h²/2 with
h = c dt / I (2.8e-4, the bound the library's damped_hinge gives first-order schemes), plus
the float32 floor of ω carried over n steps of 4 substeps (2.4e-4). Measured: 7.1e-5
(multibody: a first-order step per substep, n h²/(2k): 2.8e-4, 7.1e-5, 1.8e-5 with 1, 4, 16
substeps) and 4.8e-4 (impulse, the force-based velocity motor; 1.4e-3 with 16 substeps),
engines-rapier.md 9."""


def damped_wheel(engine: str) -> Scenario:
    """A box spinning about a damped hinge through its centre, without gravity."""
    return Scenario.model_validate(
        {
            "name": "damped_wheel",
            "dt": DT,
            "duration": DAMPED_STEPS * DT,
            "engines": [engine],
            "gravity": [0.0, 0.0, 0.0],
            "bodies": [
                {"name": "wheel", "shape": {"type": "box", "half_extents": list(WHEEL_HALF)},
                 "mass": WHEEL_MASS, "position": [0.0, 0.0, 1.0],
                 "angular_velocity": [0.0, 0.0, SPIN_RATE]},
            ],
            "joints": [
                {"name": "axle", "type": "hinge", "parent": "world", "child": "wheel",
                 "anchor": [0.0, 0.0, 1.0], "axis": [0.0, 0.0, 1.0], "damping": DAMPING},
            ],
        }
    )  # fmt: skip


@pytest.mark.parametrize("engine", KINDS)
def test_a_damped_hinge_decays_at_its_exponential_rate(engine):
    _, trajectory = recorded(engine, damped_wheel(engine))
    exact = SPIN_RATE * np.exp(-DAMPING * trajectory.t / WHEEL_INERTIA)
    error = np.abs(trajectory.ang_vel[:, 0, 2] / exact - 1.0).max()
    assert error < DAMPING_TOLERANCE, (engine, error)


LIMITS = (-0.3, 0.25)
"""rad from the release (horizontal): the bob falls onto one of them and rests there."""

LIMIT_TOLERANCE = 1e-5
"""rad past a limit or short of it at rest, measured with a margin of 5: a 0.3 m pendulum
falling onto these limits rests within 1.9e-6 rad of one (impulse; 1.9e-8 multibody) and goes
at most 2.3e-7 rad further in the fall; onto a limit of 0.2 rad both rest 2.0e-6 rad past.
Float32 resolves an angle to 1e-7."""


def limited_pendulum(engine: str, axis: list[float]) -> Scenario:
    """A 1 kg ball 0.3 m out along x on a hinge at the origin, released from rest: about +y it
    falls towards positive angles (the upper limit), about -y towards the lower one."""
    return Scenario.model_validate(
        {
            "name": "limited_pendulum",
            "dt": DT,
            "duration": 1.0,
            "engines": [engine],
            "bodies": [{"name": "bob", "shape": {"type": "sphere", "radius": 0.05}, "mass": 1.0,
                        "position": [0.3, 0.0, 0.0]}],
            "joints": [{"name": "pivot", "type": "hinge", "parent": "world", "child": "bob",
                        "anchor": [0.0, 0.0, 0.0], "axis": axis, "limits": list(LIMITS)}],
        }
    )  # fmt: skip


@pytest.mark.parametrize("engine", KINDS)
@pytest.mark.parametrize(("axis", "limit"), [([0.0, 1.0, 0.0], 1), ([0.0, -1.0, 0.0], 0)])
def test_a_hinge_falls_onto_its_limit_and_rests_there(engine, axis, limit):
    scene, trajectory = recorded(engine, limited_pendulum(engine, axis))
    angle = joint_coordinates(scene.joint_tree, trajectory.pos, quat_to_matrix(trajectory.quat))
    swing = angle["pivot"]
    assert swing.min() > LIMITS[0] - LIMIT_TOLERANCE, (engine, swing.min())
    assert swing.max() < LIMITS[1] + LIMIT_TOLERANCE, (engine, swing.max())
    assert abs(swing[-1] - LIMITS[limit]) < LIMIT_TOLERANCE, (engine, swing[-1])


# --- reading a jointed scene back ---------------------------------------------------------

ONE_SUBSTEP = ("rapier(solver_iterations=1)", "rapier(joints=impulse,solver_iterations=1)")
"""One substep a step: Rapier's step is then one semi-implicit Euler step of dt."""

SLIDE_STEPS = 200


def sliding_and_falling(engine: str) -> Scenario:
    """A box on a slider down a rail tilted 53° from the vertical through the origin (it
    accelerates at g·0.8 along the rail, 0.16 m in 0.2 s), and a free ball falling with a
    second one hung from it by a ball joint (a floating root and its link)."""
    ball = lambda name, position: {  # noqa: E731
        "name": name,
        "shape": {"type": "sphere", "radius": 0.05},
        "mass": 1.0,
        "position": position,
        "velocity": [0.0, 0.5, 0.0],
    }
    return Scenario.model_validate(
        {
            "name": "sliding_and_falling",
            "dt": DT,
            "duration": SLIDE_STEPS * DT,
            "engines": [engine],
            "bodies": [{"name": "block", "shape": {"type": "box", "half_extents": [0.1, 0.1, 0.1]},
                        "mass": 1.0, "position": [0.0, 0.0, 0.0]},
                       ball("root", [0.5, 0.0, 0.0]), ball("tail", [0.5, 0.3, 0.0])],
            "joints": [{"name": "rail", "type": "slider", "parent": "world", "child": "block",
                        "anchor": [0.0, 0.0, 0.0], "axis": RAIL.tolist()},
                       {"name": "socket", "type": "ball", "parent": "root", "child": "tail",
                        "anchor": [0.5, 0.15, 0.0]}],
        }
    )  # fmt: skip


@pytest.mark.parametrize("engine", ONE_SUBSTEP)
def test_a_jointed_bodys_velocity_is_the_one_that_moved_it(engine):
    """Semi-implicit Euler moves a body by its new velocity, x(n+1) = x(n) + v(n+1) dt: the
    velocity read with a position is the one that moved it there. A multibody link's rigid
    body, a floating root's included, carries the velocity of the substep before (g·0.8·dt =
    7.8e-3 m/s and g·dt = 9.8e-3 m/s off here); the adapter reads the multibody's own."""
    _, trajectory = recorded(engine, sliding_and_falling(engine))
    moved = np.diff(trajectory.pos, axis=0) / DT
    resolution = 4 * FLOAT32_UNIT_ROUNDOFF * np.abs(trajectory.pos).max() / DT
    # m/s, 1.2e-4: two float32 positions rounded (an ulp each at the largest, 0.5 m) over dt
    error = np.abs(moved - trajectory.vel[1:]).max()
    assert error < resolution, (engine, error, resolution)


FIELDS = ("pos", "quat", "vel", "ang_vel")

READINGS = {
    "at the end": lambda adapter: adapter.advance(SLIDE_STEPS) or adapter.observe(),
    "after every step": lambda adapter: [
        adapter.advance(1) or adapter.observe() for _ in range(SLIDE_STEPS)
    ][-1],
    "as a trajectory": lambda adapter: adapter.advance_observed(SLIDE_STEPS),
}
"""Three ways to run a scene SLIDE_STEPS steps and read it; each returns the last state read
(a ``Snapshot``, or a ``Trajectory`` whose last sample it is)."""


def last_state(read: Snapshot | Trajectory) -> list[np.ndarray]:
    if isinstance(read, Trajectory):
        return [getattr(read, f)[-1] for f in FIELDS]
    return [getattr(read, f) for f in FIELDS]


@pytest.mark.parametrize("engine", KINDS)
def test_reading_a_jointed_scene_never_moves_it(engine):
    """The three readings end in the same state bit for bit (reading a multibody's link
    velocities recomputes its kinematics: that must change nothing)."""
    scene = compile_scene(slider_ball_weld(engine))
    ends = {}
    for name, reading in READINGS.items():
        adapter = create_adapter(parse_engine_spec(engine))
        adapter.load(scene)
        ends[name] = last_state(reading(adapter))
        adapter.close()
    first, *others = ends.values()
    for name, other in zip(list(ends)[1:], others, strict=True):
        for field, a, b in zip(FIELDS, first, other, strict=True):
            assert np.array_equal(a, b), (engine, name, field, a, b)


# --- the joints Rapier built (the parity gate's joint report) ---------------------------------

JOINT_SCENES = sorted((Path(__file__).resolve().parents[1] / "scenarios" / "joints").glob("*.yaml"))

MASS_MATRIX_ROUND_OFF = 8 * FLOAT32_UNIT_ROUNDOFF
"""Relative to M's largest entry, 4.8e-7: each entry sums products of a float32 mass or
inertia and two Jacobian entries (float32 lever arms and axes) over a few links, none
cancelling: a few float32 roundings. Measured at most 7.6e-8 on the library's joint scenes
(1.5e-6 on the six-link chain when a y axis's joint frame was the 90° turn from x, whose
quaternion float32 rounds, engines-rapier.md 9)."""


@pytest.mark.parametrize("engine", KINDS)
@pytest.mark.parametrize("path", JOINT_SCENES, ids=lambda p: p.stem)
def test_the_joints_rapier_built_are_the_scenes(engine, path):
    """Types, anchors and axes read back from Rapier's joints pass the float32 parity gate;
    a multibody's M(q0) from Rapier's Jacobians and masses is the reference's composite-rigid-
    body one to float32 round-off (impulse joints have no coordinates: no M)."""
    scene = compile_scene(load_scenario(path))
    adapter = create_adapter(parse_engine_spec(engine))
    adapter.load(scene)
    try:
        assert compare_joints(adapter, scene, PRECISION_TOLERANCE["float32"]) == []
        got, want = adapter.joint_report(), expected_report(scene)
    finally:
        adapter.close()
    if engine == "rapier(joints=impulse)":
        assert got.mass_matrix is None
        return
    error = np.abs(got.mass_matrix - want.mass_matrix).max() / np.abs(want.mass_matrix).max()
    assert error < MASS_MATRIX_ROUND_OFF, (path.stem, error)
