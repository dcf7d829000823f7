"""Cylinders in MuJoCo, PyBullet, Drake and Rapier: each engine builds the scene's solid
cylinder (radius, half_length, along the shape's z) with the scene's mass and inertia, rests
it on its flat end and on its side, and rolls it down an incline at the closed form's rate;
the matched profile's per-pair restitution holds for a cylinder as for the other shapes."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from validation.engines.registry import create_adapter
from validation.measure.runner import run_engine
from validation.reference.rotation import quat_to_matrix
from validation.scenario.compiled import compile_scene
from validation.scenario.engine_spec import not_installed, parse_engine_spec
from validation.scenario.load import load_scenario

ENGINES = ("mujoco", "pybullet", "drake", "rapier")

RADIUS = 0.1
"""m."""

HALF_LENGTH = 0.2
"""m: twice the radius, so resting on an end (0.2 m) and on the side (0.1 m) differ by 0.1 m,
and a cylinder built along another axis rests at the wrong one."""

MASS = 1.0
"""kg."""

DT = 0.001
"""s, every scene's step."""

RESTING = 1.0e-3
"""m: how far a resting cylinder's centre may sit from its touching height. Every engine's
contact depth under 1 kg is below 0.2 mm (measured on this cylinder 0.5 s after landing, on
its end / its side: MuJoCo 0.19 / 0.19, Drake 0.02 / 0.02, PyBullet 0.00 / 0.00, Rapier 0.03 /
0.12 mm); an axis mistaken, or the cylinder stood on the wrong end, is 0.1 m away."""

DROP = 0.005
"""m: cylinders are released at rest this far above their touching height."""

SIDE_DOWN = [0.7071067811865476, 0.7071067811865476, 0.0, 0.0]
"""w x y z: a quarter turn about x, laying the cylinder's axis along world -y."""


def cylinder_body(
    position, orientation=(1.0, 0.0, 0.0, 0.0), extra: str = "", name: str = "can"
) -> str:
    """A solid cylinder body as YAML (its inertia the scene's solid cylinder's)."""
    return f"""  - name: {name}
    shape: {{type: cylinder, radius: {RADIUS}, half_length: {HALF_LENGTH}}}
    mass: {MASS}
    position: {[float(v) for v in position]}
    orientation: {[float(v) for v in orientation]}
{extra}"""


def write(folder: Path, engine: str, bodies: str, head: str = "", duration: float = 0.5) -> Path:
    path = folder / "cylinder.yaml"
    path.write_text(f"dt: {DT}\nduration: {duration}\nengines: [{engine}]\n{head}bodies:\n{bodies}")
    return path


def run(engine: str, path: Path):
    """The engine's run of the scene at ``path``; its status must be ``ok`` (the parity gate
    passed: mass, centre, inertia and energy as the scene states them)."""
    if not_installed(engine):
        pytest.skip(not_installed(engine))
    outcome = run_engine(compile_scene(load_scenario(path)), parse_engine_spec(engine))
    assert outcome.status == "ok", (engine, outcome.status, outcome.message)
    return outcome.recording.trajectory


# --- resting ------------------------------------------------------------------------------


@pytest.mark.parametrize("engine", ENGINES)
def test_a_cylinder_stands_on_its_flat_end_at_half_length(tmp_path, engine):
    body = cylinder_body([0, 0, HALF_LENGTH + DROP], extra="    friction: 0.5\n")
    trajectory = run(engine, write(tmp_path, engine, body, "ground: {friction: 0.5}\n"))
    assert trajectory.pos[-1][0][2] == pytest.approx(HALF_LENGTH, abs=RESTING), engine


@pytest.mark.parametrize("engine", ENGINES)
def test_a_cylinder_lies_on_its_side_at_its_radius(tmp_path, engine):
    body = cylinder_body([0, 0, RADIUS + DROP], SIDE_DOWN, "    friction: 0.5\n")
    trajectory = run(engine, write(tmp_path, engine, body, "ground: {friction: 0.5}\n"))
    assert trajectory.pos[-1][0][2] == pytest.approx(RADIUS, abs=RESTING), engine
    axis = quat_to_matrix(trajectory.quat[-1][0][None])[0][:, 2]
    assert abs(axis[2]) < 1e-2, (engine, "the cylinder stood up or tipped", axis)


# --- the parity gate: mass and the solid cylinder's inertia -------------------------------

TURNED = np.array([0.8, 0.3, -0.4, 0.33]) / np.linalg.norm([0.8, 0.3, -0.4, 0.33])
"""w x y z: a turn about no axis of the world, so every inertia component is exercised."""

GATE_TOLERANCE = 1e-5
"""Relative. Every engine is given the scene's inertia (none computes its own here): MuJoCo and
Drake hold it in float64, Rapier in float32 (eps 1.2e-7 on each of its principal moments and
its principal frame's quaternion, a few 1e-7 after the turn); a capsule's or a transposed
cylinder's inertia is 10 % or more off."""


def solid_cylinder_inertia(radius: float, half_length: float, mass: float) -> np.ndarray:
    """The closed form, body frame: m r²/2 about the axis (z), m(3r² + ℓ²)/12 across
    (ℓ = 2h)."""
    across = mass * (3 * radius**2 + (2 * half_length) ** 2) / 12
    return np.diag([across, across, mass * radius**2 / 2])


@pytest.mark.parametrize("engine", ENGINES)
def test_a_turned_spinning_cylinder_reads_back_the_solid_inertia(tmp_path, engine):
    """A cylinder turned off every world axis and spinning in free flight: the engine's own
    mass and world inertia (``model_report``) are the closed form's, and the run passes the
    parity gate."""
    spin = "    angular_velocity: [1.0, -2.0, 3.0]\n    velocity: [0.5, 0.0, 1.0]\n"
    path = write(tmp_path, engine, cylinder_body([1.0, -2.0, 3.0], TURNED, spin))
    run(engine, path)
    adapter = create_adapter(parse_engine_spec(engine))
    try:
        adapter.load(compile_scene(load_scenario(path)))
        report = adapter.model_report()
    finally:
        adapter.close()
    rot = quat_to_matrix(TURNED[None])[0]
    expected = rot @ solid_cylinder_inertia(RADIUS, HALF_LENGTH, MASS) @ rot.T
    assert report.mass[0] == pytest.approx(MASS, rel=GATE_TOLERANCE)
    np.testing.assert_allclose(
        report.inertia_world[0], expected, atol=GATE_TOLERANCE * np.abs(expected).max()
    )


# --- rolling: a = (2/3) g sin θ -------------------------------------------------------------

SLOPE = np.radians(20.0)
"""The ground's tilt about y (descending along +x); rolling needs μ >= tan θ / 3 = 0.121."""

ROLL_TIME = 0.8
"""s."""

ROLLING = 5e-3
"""m/s at ROLL_TIME, the speed's distance from (2/3) g sin θ t = 1.78945 m/s. Measured: MuJoCo
1.3e-4, Drake 1.0e-4, Rapier 8e-5, PyBullet 3.9e-3 (its cylinder's contact manifold on the
box ground, scenarios/contact/cylinder_rolls_down_incline.yaml); a solid sphere's (5/7) g sin θ
is 0.128 off, sliding without friction 0.89 off, a hollow tube's (1/2) g sin θ 0.45 off."""


@pytest.mark.parametrize("engine", ENGINES)
def test_a_cylinder_rolls_down_an_incline_at_two_thirds_g_sin_theta(tmp_path, engine):
    normal = np.array([np.sin(SLOPE), 0.0, np.cos(SLOPE)])
    downhill = np.array([np.cos(SLOPE), 0.0, -np.sin(SLOPE)])
    axis_along_y = [np.sqrt(0.5), -np.sqrt(0.5), 0.0, 0.0]
    body = cylinder_body((RADIUS * normal).tolist(), axis_along_y, "    friction: 0.5\n")
    head = f"ground: {{normal: {normal.tolist()}, friction: 0.5}}\n"
    trajectory = run(engine, write(tmp_path, engine, body, head, duration=ROLL_TIME))
    speed = trajectory.vel[-1][0] @ downhill
    assert trajectory.t[-1] == pytest.approx(ROLL_TIME)
    assert speed == pytest.approx(2 / 3 * 9.81 * np.sin(SLOPE) * ROLL_TIME, abs=ROLLING), engine


# --- the matched profile's restitution per pair ------------------------------------------

BOUNCE = {"mujoco": 0.05, "pybullet": 0.05, "rapier": 0.2}
"""Absolute, on the measured e, per engine with restitution (Drake's contact has none,
docs/engines-drake.md). Measured on this cylinder landing on its side: MuJoCo 0.516, PyBullet
0.512. Rapier 0.354: its two-point impact turns the cylinder (1.6 rad/s; a capsule on its side
0.45 and 0.6 rad/s, the same solver effect), so its band is wider; without the pair's value
e is 0 in all three (no bounce)."""

RESTITUTION = 0.5
"""The pair's e: the cylinder's own and the ground's are 0, so only the pair's value bounces."""

IMPACT_SPEED = 2.0
"""m/s, downward, the cylinder released just above the ground on its side."""


@pytest.mark.parametrize("engine", BOUNCE)
def test_a_cylinder_bounces_with_its_pair_restitution(tmp_path, engine):
    body = cylinder_body(
        [0, 0, RADIUS + 0.01], SIDE_DOWN, f"    velocity: [0, 0, {-IMPACT_SPEED}]\n"
    )
    pairs = f"pairs:\n  - {{a: can, b: ground, restitution: {RESTITUTION}}}\n"
    trajectory = run(engine, write(tmp_path, engine, body + pairs, "ground: {}\n", duration=0.06))
    rebound = trajectory.vel[:, 0, 2].max()
    assert rebound / IMPACT_SPEED == pytest.approx(RESTITUTION, abs=BOUNCE[engine]), engine
