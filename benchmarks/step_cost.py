"""Per-step cost of mini_engine, MuJoCo, PyBullet, Rapier and Drake on the same scenes, in one run, as ratios.

Scenes:

0. **sphere_on_plane**: one sphere (r = 0.05 m, 1 kg) resting on a ground plane, dt = 2e-3 s:
   the per-step fixed cost of each engine (target: mini <= 20x MuJoCo). Timed over
   ``SMALL_TIMED_STEPS`` per block, since one step of the reference engines takes microseconds.
1. **pile_N**: N spheres (r = 0.05 m, 1 kg) poured in layers of 100 into a 1.2 m walled box
   (ground and walls are planes), dt = 2e-3 s, frictionless, e = 0. Each engine first
   settles the pile for ``SETTLE_STEPS``, then its stepping alone is timed over
   ``TIMED_STEPS`` (median of ``REPEATS`` blocks). Target: mini <= 10 ms per step at N = 1000
   (MuJoCo with CG measured about 9.6 ms, engines.md 1.9). MuJoCo gets its cheapest
   collision setup: contype/conaffinity filtering and its own broad phase (no ``<pair>``
   list of N² candidates, which is what the matched adapter profile writes).
2. **tumbling_box_xK**: the Gazebo "complex" box (10 kg, 0.1 x 0.4 x 0.9 m, v0 = (-2, 2, 8),
   ω0 = (0.1, 5, 0.1), g = 9.8, dt = 1e-3), K = 1 and K = 1024 independent copies in one
   model (mini: one world each; MuJoCo and PyBullet: contacts off). Target: mini's 1024
   copies advance at least 10x faster per body-step than one copy.

Every engine runs with the settings of the adapters' matched profile that matter for speed
(MuJoCo Euler or implicitfast with CG for the pile; PyBullet maximal coordinates; Rapier
one worker thread, no sleeping, CCD on, its 4 substeps; Rapier only when
``rapier3d`` is installed: ``pip install "physval[rapier]"``; Drake's discrete plant at dt
with its default contact solver, as the adapter's discrete profile, only when ``pydrake`` is
installed: ``pip install "physval[drake]"``). Prints a
table and writes ``benchmarks/results/step_cost.csv``. Not a test: wall-clock numbers
depend on the machine; the ratios are what to compare.

    python benchmarks/step_cost.py [--spheres 1 10 100 1000] [--copies 1024] [--clock cpu]
"""

from __future__ import annotations

import argparse
import importlib
import importlib.metadata
import importlib.util
import statistics
import time
from collections.abc import Callable
from pathlib import Path

import mujoco
import numpy as np
import pandas as pd
import pybullet

from mini_engine import Body, Plane, Settings, Sphere, build_model, step
from mini_engine.scenes import GAZEBO_BOX_HALF_EXTENTS, sphere_pile, tumbling_box
from mini_engine.shapes import Box

rapier3d = (
    importlib.import_module("rapier3d")
    if importlib.util.find_spec("rapier3d") is not None
    else None
)
"""The optional Rapier engine (the ``rapier`` extra), or None: its rows are then left out."""

HAVE_DRAKE = importlib.util.find_spec("pydrake") is not None
"""Whether the optional Drake engine (the ``drake`` extra) is installed: else its rows are left
out (pydrake is imported inside its runners)."""

PILE_DT = 2e-3
"""s. engines.md 1.9 measured the reference engines at 2e-3 (1e-3 costs the same per step)."""

SETTLE_STEPS = 750
"""1.5 s of simulated time: the layers have landed and the pile is settling."""

TIMED_STEPS = 30
REPEATS = 7
"""Median of 7 blocks of 30 steps: on this shared 2-core machine single blocks of the same
pile vary from 9 to 15 ms, and the median of 7 is stable to about 10 %."""
SMALL_TIMED_STEPS = 2000
"""Steps per block of the one-sphere scene: MuJoCo steps it in ~2 µs, so 30 steps would be
shorter than the timer's resolution is useful for; 2000 steps are ~4 ms for MuJoCo."""

SPHERE_RADIUS = 0.05
"""m, the spheres of the pile and the one-sphere scene."""

RESULTS = Path(__file__).parent / "results" / "step_cost.csv"


CLOCKS = {"wall": time.perf_counter, "cpu": time.process_time}
"""``--clock``: wall time, or this process's CPU time. Every engine steps single-threaded
here, so on a shared machine (other jobs on the 2 cores) CPU time is the steadier measure
of the same work; wall time is what a user waits."""

clock = CLOCKS["wall"]


def seconds_per_step(advance: Callable[[int], None], steps: int = TIMED_STEPS) -> float:
    """Median over ``REPEATS`` blocks of ``steps`` steps of the time per step, s."""
    samples = []
    for _ in range(REPEATS):
        start = clock()
        advance(steps)
        samples.append((clock() - start) / steps)
    return statistics.median(samples)


def _mini_settled_cost(model, state, steps: int) -> tuple[float, int]:
    """mini_engine's seconds per step (blocks of ``steps``) after ``SETTLE_STEPS`` at
    ``PILE_DT``, and the contact count of the last step."""
    cfg = Settings(dt=PILE_DT)
    holder = {"state": state, "contacts": 0}

    def advance(steps: int) -> None:
        s = holder["state"]
        for _ in range(steps):
            s, report = step(model, s, cfg)
        holder["state"], holder["contacts"] = s, report.contacts.count

    advance(SETTLE_STEPS)
    return seconds_per_step(advance, steps), holder["contacts"]


def _pybullet_settled_cost(client: int, steps: int) -> tuple[float, int]:
    """PyBullet's seconds per step (blocks of ``steps``) after ``SETTLE_STEPS``, and its
    contact count then."""

    def advance(steps: int) -> None:
        for _ in range(steps):
            pybullet.stepSimulation(physicsClientId=client)

    advance(SETTLE_STEPS)
    cost = seconds_per_step(advance, steps)
    return cost, len(pybullet.getContactPoints(physicsClientId=client))


# --- one sphere resting on a plane: the fixed cost of a step -----------------------------


def mini_sphere() -> tuple[float, int]:
    model, state = build_model(
        [
            Body(Plane(), fixed=True),
            Body(Sphere(SPHERE_RADIUS), mass=1.0, position=(0.0, 0.0, SPHERE_RADIUS)),
        ]
    )
    return _mini_settled_cost(model, state, SMALL_TIMED_STEPS)


def mujoco_sphere() -> tuple[float, int]:
    xml = (
        f'<mujoco><option timestep="{PILE_DT}" integrator="implicitfast" solver="CG"/>'
        '<worldbody><geom type="plane" size="1 1 0.1" condim="1"/>'
        f'<body pos="0 0 {SPHERE_RADIUS}"><freejoint/>'
        f'<geom type="sphere" size="{SPHERE_RADIUS}" mass="1" condim="1"/></body>'
        "</worldbody></mujoco>"
    )
    model = mujoco.MjModel.from_xml_string(xml)
    data = mujoco.MjData(model)

    def advance(steps: int) -> None:
        mujoco.mj_step(model, data, nstep=steps)

    advance(SETTLE_STEPS)
    return seconds_per_step(advance, SMALL_TIMED_STEPS), int(data.ncon)


def pybullet_sphere() -> tuple[float, int]:
    client = pybullet.connect(pybullet.DIRECT)
    try:
        pybullet.setGravity(0, 0, -9.81, physicsClientId=client)
        pybullet.setPhysicsEngineParameter(fixedTimeStep=PILE_DT, physicsClientId=client)
        plane = pybullet.createCollisionShape(pybullet.GEOM_PLANE, physicsClientId=client)
        pybullet.createMultiBody(0, plane, physicsClientId=client)
        sphere = pybullet.createCollisionShape(
            pybullet.GEOM_SPHERE, radius=SPHERE_RADIUS, physicsClientId=client
        )
        body = pybullet.createMultiBody(
            1.0,
            sphere,
            basePosition=[0.0, 0.0, SPHERE_RADIUS],
            useMaximalCoordinates=True,
            physicsClientId=client,
        )
        pybullet.changeDynamics(body, -1, lateralFriction=0.0, physicsClientId=client)
        return _pybullet_settled_cost(client, SMALL_TIMED_STEPS)
    finally:
        pybullet.disconnect(client)


def _rapier_world(dt: float, gravity=(0.0, 0.0, -9.81)):
    """A Rapier world as the adapter's matched profile sets it up for speed: one worker
    thread, Rapier's simplified friction (``validation.engines.rapier``)."""
    world = rapier3d.PhysicsWorld(gravity=gravity)
    world.set_num_threads(1)
    world.integration_parameters.dt = dt
    return world


def _rapier_sphere(world, position) -> None:
    body = rapier3d.RigidBody.dynamic().translation(tuple(position)).can_sleep(False)
    collider = rapier3d.Collider.ball(SPHERE_RADIUS).mass(1.0).friction(0.0).restitution(0.0)
    world.add_body(body.ccd_enabled(True), [collider])


def _rapier_settled_cost(world, steps: int) -> tuple[float, int]:
    """Rapier's seconds per step (blocks of ``steps``) after ``SETTLE_STEPS``, and its
    number of touching collider pairs."""

    def advance(steps: int) -> None:
        for _ in range(steps):
            world.step()

    advance(SETTLE_STEPS)
    cost = seconds_per_step(advance, steps)
    touching = sum(1 for pair in world.narrow_phase.contact_pairs() if pair.has_any_active_contact)
    return cost, touching


def rapier_sphere() -> tuple[float, int]:
    world = _rapier_world(PILE_DT)
    world.add_body(rapier3d.RigidBody.fixed(), [rapier3d.Collider.halfspace((0.0, 0.0, 1.0))])
    _rapier_sphere(world, (0.0, 0.0, SPHERE_RADIUS))
    return _rapier_settled_cost(world, SMALL_TIMED_STEPS)


def _drake_plant(dt: float, gravity=(0.0, 0.0, -9.81)):
    """A discrete Drake plant and scene graph at ``dt``, Drake's default contact solver (the
    adapter's discrete profile), and a function that adds a frictionless sphere at a point."""
    from pydrake.multibody.plant import AddMultibodyPlantSceneGraph
    from pydrake.systems.framework import DiagramBuilder

    builder = DiagramBuilder()
    plant, _ = AddMultibodyPlantSceneGraph(builder, dt)
    plant.mutable_gravity_field().set_gravity_vector(np.asarray(gravity, dtype=float))
    return builder, plant


def _drake_sphere(plant, k: int) -> object:
    from pydrake.geometry import Sphere
    from pydrake.math import RigidTransform
    from pydrake.multibody.plant import CoulombFriction
    from pydrake.multibody.tree import SpatialInertia

    body = plant.AddRigidBody(f"sphere{k}", SpatialInertia.SolidSphereWithMass(1.0, SPHERE_RADIUS))
    plant.RegisterCollisionGeometry(
        body, RigidTransform(), Sphere(SPHERE_RADIUS), f"sphere{k}", CoulombFriction(0.0, 0.0)
    )
    return body


def _drake_planes(plant, planes) -> None:
    """Frictionless half-spaces on the world body at (point, inward normal)."""
    from pydrake.geometry import HalfSpace
    from pydrake.multibody.plant import CoulombFriction

    for k, (point, normal) in enumerate(planes):
        plant.RegisterCollisionGeometry(
            plant.world_body(),
            HalfSpace.MakePose(np.asarray(normal, dtype=float), np.asarray(point, dtype=float)),
            HalfSpace(),
            f"plane{k}",
            CoulombFriction(0.0, 0.0),
        )


def _drake_settled_cost(builder, plant, bodies, positions, steps: int) -> tuple[float, int]:
    """Drake's seconds per step (one ``AdvanceTo`` per block of ``steps``) after
    ``SETTLE_STEPS``, and its number of point contacts."""
    from pydrake.math import RigidTransform
    from pydrake.systems.analysis import Simulator

    plant.Finalize()
    diagram = builder.Build()
    simulator = Simulator(diagram)
    context = plant.GetMyMutableContextFromRoot(simulator.get_mutable_context())
    for body, position in zip(bodies, positions, strict=True):
        plant.SetFreeBodyPose(context, body, RigidTransform(np.asarray(position, dtype=float)))
    simulator.Initialize()
    dt = plant.time_step()
    taken = [0]

    def advance(count: int) -> None:
        taken[0] += count
        simulator.AdvanceTo(taken[0] * dt)

    advance(SETTLE_STEPS)
    cost = seconds_per_step(advance, steps)
    contacts = plant.get_contact_results_output_port().Eval(context).num_point_pair_contacts()
    return cost, int(contacts)


def drake_sphere() -> tuple[float, int]:
    builder, plant = _drake_plant(PILE_DT)
    _drake_planes(plant, [((0.0, 0.0, 0.0), (0.0, 0.0, 1.0))])
    body = _drake_sphere(plant, 0)
    return _drake_settled_cost(
        builder, plant, [body], [(0.0, 0.0, SPHERE_RADIUS)], SMALL_TIMED_STEPS
    )


SPHERE_ENGINES = {
    "mini": (mini_sphere, "defaults: semi-implicit Euler, 10 sweeps, warm start"),
    "mujoco": (mujoco_sphere, "implicitfast, CG, condim 1"),
    "pybullet": (pybullet_sphere, "maximal coordinates, 50 iterations"),
    **({"rapier": (rapier_sphere, "1 thread, 4 substeps, CCD")} if rapier3d else {}),
    **({"drake": (drake_sphere, "discrete, default solver (SAP, lagged)")} if HAVE_DRAKE else {}),
}
"""Engine -> (one-sphere runner, the settings it runs with, for the table)."""


# --- the pile in each engine -----------------------------------------------------------


def mini_pile(count: int) -> tuple[float, int]:
    model, state = sphere_pile(count)
    return _mini_settled_cost(model, state, TIMED_STEPS)


def _pile_positions(count: int) -> np.ndarray:
    model, state = sphere_pile(count)
    return state.pos[model.body_dynamic]


PLANE_NORMALS = [
    ((0, 0, 0), (0, 0, 1)),
    ((-0.6, 0, 0), (1, 0, 0)),
    ((0.6, 0, 0), (-1, 0, 0)),
    ((0, -0.6, 0), (0, 1, 0)),
    ((0, 0.6, 0), (0, -1, 0)),
]
"""The ground and the four walls of the 1.2 m box: (point, inward normal)."""


def mujoco_pile(count: int) -> tuple[float, int]:
    # contype/conaffinity filtering, no <pair> list: MuJoCo's broad phase finds the candidates.
    # The walls (contype 0) never test each other; spheres (contype 1) meet walls and spheres.
    planes = "".join(
        f'<geom type="plane" size="1 1 0.1" pos="{p[0]} {p[1]} {p[2]}" zaxis="{n[0]} {n[1]} {n[2]}"'
        ' contype="0" conaffinity="1" condim="1"/>'
        for p, n in PLANE_NORMALS
    )
    bodies = "".join(
        f'<body pos="{x} {y} {z}"><freejoint/><geom type="sphere" size="{SPHERE_RADIUS}" mass="1"'
        ' contype="1" conaffinity="1" condim="1"/></body>'
        for x, y, z in _pile_positions(count)
    )
    xml = (
        f'<mujoco><option timestep="{PILE_DT}" integrator="implicitfast" solver="CG"/>'
        f"<worldbody>{planes}{bodies}</worldbody></mujoco>"
    )
    model = mujoco.MjModel.from_xml_string(xml)
    assert model.npair == 0, "the pile must use contype filtering, not explicit pairs"
    data = mujoco.MjData(model)

    def advance(steps: int) -> None:
        mujoco.mj_step(model, data, nstep=steps)

    advance(SETTLE_STEPS)
    return seconds_per_step(advance), int(data.ncon)


def pybullet_pile(count: int) -> tuple[float, int]:
    client = pybullet.connect(pybullet.DIRECT)
    try:
        pybullet.setGravity(0, 0, -9.81, physicsClientId=client)
        pybullet.setPhysicsEngineParameter(fixedTimeStep=PILE_DT, physicsClientId=client)
        plane = pybullet.createCollisionShape(pybullet.GEOM_PLANE, physicsClientId=client)
        for point, normal in PLANE_NORMALS:
            axis = np.cross((0, 0, 1), normal)
            angle = np.arccos(np.clip(normal[2], -1, 1))
            quat = pybullet.getQuaternionFromAxisAngle(axis if np.any(axis) else (1, 0, 0), angle)
            pybullet.createMultiBody(
                0, plane, basePosition=point, baseOrientation=quat, physicsClientId=client
            )
        sphere = pybullet.createCollisionShape(
            pybullet.GEOM_SPHERE, radius=0.05, physicsClientId=client
        )
        for position in _pile_positions(count):
            body = pybullet.createMultiBody(
                1.0,
                sphere,
                basePosition=position.tolist(),
                useMaximalCoordinates=True,
                physicsClientId=client,
            )
            pybullet.changeDynamics(body, -1, lateralFriction=0.0, physicsClientId=client)
        return _pybullet_settled_cost(client, TIMED_STEPS)
    finally:
        pybullet.disconnect(client)


def rapier_pile(count: int) -> tuple[float, int]:
    world = _rapier_world(PILE_DT)
    for point, normal in PLANE_NORMALS:
        wall = rapier3d.RigidBody.fixed().translation(point)
        world.add_body(wall, [rapier3d.Collider.halfspace(normal).friction(0.0)])
    for position in _pile_positions(count):
        _rapier_sphere(world, position)
    return _rapier_settled_cost(world, TIMED_STEPS)


def drake_pile(count: int) -> tuple[float, int]:
    builder, plant = _drake_plant(PILE_DT)
    _drake_planes(plant, PLANE_NORMALS)
    positions = _pile_positions(count)
    bodies = [_drake_sphere(plant, k) for k in range(len(positions))]
    return _drake_settled_cost(builder, plant, bodies, positions, TIMED_STEPS)


PILE_ENGINES = {
    "mini": (mini_pile, "defaults: semi-implicit Euler, 10 sweeps, warm start"),
    "mujoco": (mujoco_pile, "implicitfast, CG, condim 1"),
    "pybullet": (pybullet_pile, "maximal coordinates, 50 iterations"),
    **({"rapier": (rapier_pile, "1 thread, 4 substeps, CCD")} if rapier3d else {}),
    **({"drake": (drake_pile, "discrete, default solver (SAP, lagged)")} if HAVE_DRAKE else {}),
}
"""Engine -> (pile runner, the settings it runs with, for the table)."""


# --- copies of the tumbling box ---------------------------------------------------------------

BOX_DT = 1e-3
BOX_MASS = 10.0
BOX_VELOCITY = (-2.0, 2.0, 8.0)
BOX_SPIN = (0.1, 5.0, 0.1)
BOX_GRAVITY = (0.0, 0.0, -9.8)


def _box_inertia() -> np.ndarray:
    """Principal moments (3,) kg·m² of the Gazebo box (body axes are principal)."""
    return np.diag(Box(GAZEBO_BOX_HALF_EXTENTS).unit_inertia()) * BOX_MASS


def mini_copies(copies: int) -> float:
    """Seconds per step of ``copies`` tumbling boxes in one model (gyroscopic explicit)."""
    model, state = tumbling_box(copies)
    cfg = Settings(dt=BOX_DT, gyroscopic="explicit")
    holder = {"state": state}

    def advance(steps: int) -> None:
        s = holder["state"]
        for _ in range(steps):
            s, _ = step(model, s, cfg)
        holder["state"] = s

    advance(10)
    return seconds_per_step(advance)


def mujoco_copies(copies: int) -> float:
    inertia = " ".join(repr(float(v)) for v in _box_inertia())
    size = " ".join(repr(v) for v in GAZEBO_BOX_HALF_EXTENTS)
    bodies = "".join(
        f'<body pos="{3.0 * k} 0 0"><freejoint/><inertial pos="0 0 0" mass="{BOX_MASS}"'
        f' diaginertia="{inertia}"/><geom type="box" size="{size}"/></body>'
        for k in range(copies)
    )
    xml = (
        f'<mujoco><option timestep="{BOX_DT}" integrator="Euler" gravity="0 0 -9.8">'
        f'<flag contact="disable"/></option><worldbody>{bodies}</worldbody></mujoco>'
    )
    model = mujoco.MjModel.from_xml_string(xml)
    data = mujoco.MjData(model)
    data.qvel[:] = np.tile([*BOX_VELOCITY, *BOX_SPIN], copies)  # identity pose: body ω = world ω

    def advance(steps: int) -> None:
        mujoco.mj_step(model, data, nstep=steps)

    advance(10)
    return seconds_per_step(advance)


def pybullet_copies(copies: int) -> float:
    client = pybullet.connect(pybullet.DIRECT)
    try:
        pybullet.setGravity(*BOX_GRAVITY, physicsClientId=client)
        pybullet.setPhysicsEngineParameter(fixedTimeStep=BOX_DT, physicsClientId=client)
        for k in range(copies):  # no collision shape: contacts cost nothing, as in MuJoCo's run
            body = pybullet.createMultiBody(
                BOX_MASS,
                -1,
                basePosition=[3.0 * k, 0, 0],
                useMaximalCoordinates=True,
                physicsClientId=client,
            )
            pybullet.changeDynamics(
                body,
                -1,
                mass=BOX_MASS,
                localInertiaDiagonal=_box_inertia().tolist(),
                linearDamping=0.0,
                angularDamping=0.0,
                physicsClientId=client,
            )
            pybullet.resetBaseVelocity(body, BOX_VELOCITY, BOX_SPIN, physicsClientId=client)

        def advance(steps: int) -> None:
            for _ in range(steps):
                pybullet.stepSimulation(physicsClientId=client)

        advance(10)
        return seconds_per_step(advance)
    finally:
        pybullet.disconnect(client)


def rapier_copies(copies: int) -> float:
    """Seconds per step of ``copies`` tumbling boxes in one world, no colliders (contacts cost
    nothing, as in MuJoCo's run), the box's mass properties set on the body."""
    world = _rapier_world(BOX_DT, BOX_GRAVITY)
    inertia = rapier3d.MassProperties(
        local_com=(0.0, 0.0, 0.0), mass=BOX_MASS, principal_inertia=tuple(_box_inertia())
    )
    for k in range(copies):
        body = (
            rapier3d.RigidBody.dynamic()
            .translation((3.0 * k, 0.0, 0.0))
            .linvel(BOX_VELOCITY)
            .angvel(BOX_SPIN)
            .can_sleep(False)
            .additional_mass_properties(inertia)
        )
        world.add_body(body)

    def advance(steps: int) -> None:
        for _ in range(steps):
            world.step()

    advance(10)
    return seconds_per_step(advance)


def drake_copies(copies: int) -> float:
    """Seconds per step of ``copies`` tumbling boxes in one discrete plant, no collision
    geometry (contacts cost nothing, as in MuJoCo's run)."""
    from pydrake.math import RigidTransform
    from pydrake.multibody.math import SpatialVelocity
    from pydrake.multibody.tree import RotationalInertia, SpatialInertia
    from pydrake.systems.analysis import Simulator

    builder, plant = _drake_plant(BOX_DT, BOX_GRAVITY)
    moments = _box_inertia()
    inertia = SpatialInertia.MakeFromCentralInertia(
        BOX_MASS, np.zeros(3), RotationalInertia(*(float(m) for m in moments))
    )
    bodies = [plant.AddRigidBody(f"box{k}", inertia) for k in range(copies)]
    plant.Finalize()
    simulator = Simulator(builder.Build())
    context = plant.GetMyMutableContextFromRoot(simulator.get_mutable_context())
    for k, body in enumerate(bodies):
        plant.SetFreeBodyPose(context, body, RigidTransform([3.0 * k, 0.0, 0.0]))
        plant.SetFreeBodySpatialVelocity(
            context, body, SpatialVelocity(np.array(BOX_SPIN), np.array(BOX_VELOCITY))
        )
    simulator.Initialize()
    taken = [0]

    def advance(steps: int) -> None:
        taken[0] += steps
        simulator.AdvanceTo(taken[0] * BOX_DT)

    advance(10)
    return seconds_per_step(advance)


COPY_ENGINES = {
    "mini": (mini_copies, "gyroscopic explicit, one world per copy"),
    "mujoco": (mujoco_copies, "Euler, contacts disabled"),
    "pybullet": (pybullet_copies, "maximal coordinates, no collision shapes"),
    **({"rapier": (rapier_copies, "1 thread, no colliders")} if rapier3d else {}),
    **({"drake": (drake_copies, "discrete, no collision geometry")} if HAVE_DRAKE else {}),
}
"""Engine -> (copies runner, the settings it runs with, for the table)."""


def _with_ratios(rows: list[dict]) -> None:
    """Add mini/MuJoCo and mini/PyBullet ratios to the rows of one scene."""
    cost = {row["engine"]: row["ms_per_step"] for row in rows}
    for row in rows:
        row["ratio_to_mujoco"] = row["ms_per_step"] / cost["mujoco"]
        row["ratio_to_pybullet"] = row["ms_per_step"] / cost["pybullet"]


def _row(scene: str, engine: str, seconds: float, settings: str, **extra: float) -> dict:
    return {
        "scene": scene,
        "engine": engine,
        "ms_per_step": seconds * 1e3,
        **extra,
        "settings": settings,
    }


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--spheres", type=int, nargs="*", default=[1, 10, 100, 1000])
    parser.add_argument("--copies", type=int, default=1024)
    parser.add_argument("--clock", choices=sorted(CLOCKS), default="wall")
    args = parser.parse_args()
    global clock
    clock = CLOCKS[args.clock]
    rows: list[dict] = []
    scene = []
    for name, (run, settings) in SPHERE_ENGINES.items():
        cost, contacts = run()
        scene.append(_row("sphere_on_plane", name, cost, settings, contacts=contacts))
    _with_ratios(scene)
    rows += scene
    for count in args.spheres:
        scene = []
        for name, (run, settings) in PILE_ENGINES.items():
            cost, contacts = run(count)
            scene.append(_row(f"pile_{count}", name, cost, settings, contacts=contacts))
        _with_ratios(scene)
        rows += scene
    single: dict[str, float] = {}
    for copies in (1, args.copies):
        scene = []
        for name, (run, settings) in COPY_ENGINES.items():
            cost = run(copies)
            single.setdefault(name, cost)
            speedup = single[name] * copies / cost
            scene.append(
                _row(f"tumbling_box_x{copies}", name, cost, settings, speedup_per_body_step=speedup)
            )
        _with_ratios(scene)
        rows += scene
    table = pd.DataFrame(rows)
    table["numpy_version"], table["mujoco_version"] = np.__version__, mujoco.__version__
    table["pybullet_api"] = pybullet.getAPIVersion()
    table["rapier3d_version"] = (
        importlib.metadata.version("rapier3d") if rapier3d is not None else "not installed"
    )
    table["drake_version"] = importlib.metadata.version("drake") if HAVE_DRAKE else "not installed"
    table["clock"] = args.clock
    RESULTS.parent.mkdir(parents=True, exist_ok=True)
    temporary = RESULTS.with_suffix(".tmp")
    table.to_csv(temporary, index=False)
    temporary.replace(RESULTS)
    with pd.option_context("display.width", 160, "display.max_columns", 20):
        print(
            table.drop(
                columns=[
                    "numpy_version",
                    "mujoco_version",
                    "pybullet_api",
                    "rapier3d_version",
                    "drake_version",
                    "settings",
                    "clock",
                ]
            ).to_string(index=False)
        )
    print(f"numpy {np.__version__}, mujoco {mujoco.__version__}; results in {RESULTS}")


if __name__ == "__main__":
    main()
