"""Placed shapes in MuJoCo, PyBullet, Drake and Rapier: a shape's ``offset`` and
``orientation`` in its body (``validation.scenario.schema``) put the engine's collision shape
there, on a free body and on a jointed link, with the body's stated inertia about its centre
of mass unchanged (the parity gate passes, so the run's status is ``ok``)."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from validation.measure.runner import run_engine
from validation.scenario.compiled import compile_scene
from validation.scenario.engine_spec import not_installed, parse_engine_spec
from validation.scenario.load import load_scenario

ENGINES = ("mujoco", "pybullet", "drake", "rapier")

OFFSET = 0.05
"""m, the shape's centre above the body's centre of mass (the task's 5 cm)."""

HALF = 0.1
"""m, the placed cube's half extent: its centre of mass rests at HALF - OFFSET = 0.05 m, where
a shape left at the centre of mass would rest at HALF = 0.1 m (50 mm away)."""

RESTING = 1.0e-3
"""m: how far a resting body's centre may sit from its touching height. Every engine's
contact depth under 1 kg is below 0.2 mm (measured on the placed cube 0.5 s after landing:
MuJoCo 0.18, Drake 0.02, Rapier 0.07, PyBullet 0.00 mm); a shape left at the centre of mass
or unturned is 50 mm or more away."""

CUBE_INERTIA = [2 * 1.0 * HALF**2 / 3] * 3
"""kg·m², a 1 kg solid cube of half extent HALF about its centre (m(2h)²/6), stated: a placed
shape needs its body's inertia."""

DT = 0.001
"""s, every scene's step."""

DURATION = 0.5
"""s: long enough to settle on the ground or swing well away (a free pendulum's bob falls
0.3 m in 0.5 s)."""


def outcome(engine: str, folder: Path, bodies: str, extra: str = ""):
    """The engine's run of a scene with the ground, ``bodies`` (YAML) and ``extra`` (YAML)."""
    if not_installed(engine):
        pytest.skip(not_installed(engine))
    path = folder / "placed.yaml"
    path.write_text(
        f"dt: {DT}\nduration: {DURATION}\nengines: [{engine}]\n"
        f"ground: {{friction: 0.5}}\nbodies:\n{bodies}{extra}"
    )
    run = run_engine(compile_scene(load_scenario(path)), parse_engine_spec(engine))
    assert run.status == "ok", (engine, run.status, run.message)
    return run.recording.trajectory


DROP = 0.005
"""m: bodies are released at rest this far above their touching height (a gentle landing)."""


def cube(offset: str, orientation: str = "[1, 0, 0, 0]") -> str:
    """A 1 kg cube whose shape sits at ``offset`` turned by ``orientation``, released at rest
    DROP above its touching height (HALF - OFFSET)."""
    return f"""  - name: cube
    shape: {{type: box, half_extents: [{HALF}, {HALF}, {HALF}], offset: {offset},
             orientation: {orientation}}}
    mass: 1.0
    inertia: {CUBE_INERTIA}
    position: [0, 0, {HALF - OFFSET + DROP}]
    friction: 0.5
"""


@pytest.mark.parametrize("engine", ENGINES)
def test_a_placed_box_rests_at_its_offset_pose_height(tmp_path, engine):
    trajectory = outcome(engine, tmp_path, cube(f"[0, 0, {OFFSET}]"))
    assert trajectory.pos[-1][0][2] == pytest.approx(HALF - OFFSET, abs=RESTING), engine


SLAB = (0.2, 0.1, 0.05)
"""m, a slab's half extents: laid flat it rests at 0.05 m; its shape turned a quarter about y
(its x onto the body's z) stands it on end, at 0.2 m."""

QUARTER_ABOUT_Y = "[0.7071067811865476, 0, 0.7071067811865476, 0]"


@pytest.mark.parametrize("engine", ENGINES)
def test_a_turned_shape_rests_on_its_turned_side(tmp_path, engine):
    hx, hy, hz = SLAB
    body = f"""  - name: slab
    shape: {{type: box, half_extents: [{hx}, {hy}, {hz}], orientation: {QUARTER_ABOUT_Y}}}
    mass: 1.0
    inertia: [0.01, 0.01, 0.01]
    position: [0, 0, {hx + DROP}]
    friction: 0.5
"""
    trajectory = outcome(engine, tmp_path, body)
    assert trajectory.pos[-1][0][2] == pytest.approx(hx, abs=RESTING), engine
    np.testing.assert_allclose(trajectory.quat[-1][0], [1, 0, 0, 0], atol=1e-3)


@pytest.mark.parametrize("engine", ENGINES)
def test_a_placed_shape_on_a_spinning_body_keeps_the_stated_inertia(tmp_path, engine):
    """In free flight (no ground reached) the parity gate compares the engine's mass, centre
    and inertia with the scene's: a shape placed 5 cm off the centre must move none of them
    (``outcome`` asserts the run's status ``ok``), and the centre flies the projectile's path."""
    body = f"""  - name: top
    shape: {{type: box, half_extents: [0.1, 0.05, 0.02], offset: [{OFFSET}, 0, 0],
             orientation: [0.9238795325112867, 0, 0, 0.3826834323650898]}}
    mass: 2.0
    inertia: [0.01, 0.02, 0.025]
    position: [0, 0, 5.0]
    orientation: [0.9238795325112867, 0.3826834323650898, 0, 0]
    angular_velocity: [0.3, 0.2, 4.0]
"""
    trajectory = outcome(engine, tmp_path, body)
    fallen = 5.0 - 0.5 * 9.81 * DURATION**2
    assert trajectory.pos[-1][0][2] == pytest.approx(fallen, abs=EULER_LEAD), engine
    np.testing.assert_allclose(trajectory.pos[-1][0][:2], [0.0, 0.0], atol=1e-6)


EULER_LEAD = 9.81 * DURATION * DT / 2 + 1e-5
"""m: semi-implicit Euler's fall leads the closed form by g·t·dt/2 (2.45 mm at 0.5 s; Rapier's
substeps lead less), plus 10 µm for float32."""


ARM = 0.3
"""m: the hinge to the link's centre of mass, along x."""

PIVOT = 0.5
"""m: the hinge's height (about y); the link's centre starts level with it."""

FOOT = 0.05
"""m: the radius of the link's sphere, placed PIVOT - FOOT below its centre of mass so that it
touches the ground at t = 0: the ground holds the link level (the normal force at the foot
balances gravity's moment, N = m g, no friction needed). A shape left at the centre of mass
is 0.45 m clear of the ground and the link swings down."""


@pytest.mark.parametrize("engine", ENGINES)
def test_a_placed_shape_on_a_hinged_link_props_it_on_the_ground(tmp_path, engine):
    body = f"""  - name: link
    shape: {{type: sphere, radius: {FOOT}, offset: [0, 0, {-(PIVOT - FOOT)}]}}
    mass: 1.0
    inertia: [0.001, 0.001, 0.001]
    position: [{ARM}, 0, {PIVOT}]
"""
    hinge = f"""joints:
  - {{name: pivot, type: hinge, parent: world, child: link, anchor: [0, 0, {PIVOT}],
     axis: [0, 1, 0]}}
"""
    trajectory = outcome(engine, tmp_path, body, hinge)
    np.testing.assert_allclose(trajectory.pos[-1][0], [ARM, 0.0, PIVOT], atol=RESTING)
