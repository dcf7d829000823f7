"""Format v1 additions: a tilted ground and constant applied loads,
in all three engines, in the invariants and in the independent reference."""

from __future__ import annotations

import math

import numpy as np
import pytest
from scene_rows import rows

from mini_engine.rotation import quat_to_matrix
from validation.reference.newton_euler import reference_motion
from validation.scenario import Scenario, ScenarioError, load_scenario
from validation.scenario.compiled import compile_scene
from validation.scenario.engine_spec import parse_engine_spec
from validation.scenario.physics import ground_pose

G = 9.81
ENGINES = ("mini", "mujoco", "pybullet")

TILT = math.radians(30.0)
"""The incline of the sliding test: steep enough that a sign or axis mistake in the plane's
pose moves the sphere by metres, not millimetres."""

NORMAL = (math.sin(TILT), 0.0, math.cos(TILT))
DOWNHILL = np.array([math.cos(TILT), 0.0, -math.sin(TILT)])

SLIDE_TIME = 0.5
"""s: the frictionless sphere's speed along the slope is read here."""

SOFT_CONTACT_SPEED = 1e-3
"""Relative error of the sliding speed g·sin θ·t allowed to every engine: MuJoCo's soft normal
constraint measured 2e-5 relative on a 20° incline (scenarios/contact/incline_roll_and_slide);
a rigid contact (mini, PyBullet) is exact to round-off. A plane at the wrong angle gives
|Δ sin θ| ≥ 1e-2 for a one-degree mistake."""

ROUND_OFF = 1e-9
"""Relative: quantities every scheme keeps exactly under constant loads (v = F t / m, ω = τ t / I,
L = τ t, p = F t)."""

DOP853_AGREEMENT = 1e-9
"""Relative: SciPy DOP853 at rtol 1e-12 against the closed form of a constant-load spin-up."""


def incline_scene() -> dict:
    radius = 0.1
    return {
        "name": "slide",
        "dt": 1e-3,
        "duration": 0.6,
        "ground": {"normal": list(NORMAL), "point": [0.0, 0.0, 0.25]},
        "bodies": [
            {
                "name": "ball",
                "shape": {"type": "sphere", "radius": radius},
                "mass": 1.0,
                "position": (np.array([0.0, 0.0, 0.25]) + radius * np.array(NORMAL)).tolist(),
            }
        ],
        "expect": [
            {
                "kind": "velocity_at",
                "body": "ball",
                "time": SLIDE_TIME,
                "value": (G * math.sin(TILT) * SLIDE_TIME * DOWNHILL).tolist(),
            }
        ],
    }


@pytest.mark.parametrize("engine", ENGINES)
def test_a_frictionless_sphere_slides_down_a_tilted_ground_at_g_sin_theta(engine):
    found = rows(incline_scene(), engine)["velocity_at.ball"]
    speed = G * math.sin(TILT) * SLIDE_TIME
    assert found["status"] == "ok", found
    assert found["error"] <= SOFT_CONTACT_SPEED * speed, (
        f"{engine}: |v - g sin θ t d| = {found['error']:.3g} m/s at {speed:.4g} m/s "
        f"({found['message']})"
    )


def test_the_ground_pose_turns_plus_z_onto_the_normal():
    for normal in [(0, 0, 1), (0, 0, -1), (1, 0, 0), (0, -2, 1), NORMAL]:
        ground = {"normal": list(normal), "point": [1.0, -2.0, 0.5]}
        scene = Scenario.model_validate({**incline_scene(), "ground": ground})
        point, quat = ground_pose(scene.ground)
        assert point.tolist() == ground["point"], point
        axis = quat_to_matrix(quat[None])[0][:, 2]
        expected = np.asarray(normal, dtype=float) / np.linalg.norm(normal)
        assert np.allclose(axis, expected, atol=1e-15), (normal, axis)


def spin_up_scene() -> dict:
    return {
        "name": "spin_up",
        "dt": 1e-3,
        "duration": 0.5,
        "gravity": [0.0, 0.0, -9.81],
        "bodies": [
            {
                "name": "box",
                "shape": {"type": "box", "half_extents": [0.2, 0.1, 0.05]},
                "mass": 2.0,
                # a tilted body frame: the torque is along its body x axis, given in world frame
                "orientation": [math.cos(0.3), 0.0, math.sin(0.3), 0.0],
                "force": [3.0, -1.0, 12.0],
                "torque": (
                    0.02 * quat_to_matrix(np.array([[math.cos(0.3), 0, math.sin(0.3), 0]]))[0][:, 0]
                ).tolist(),
            }
        ],
    }


def spin_up_closed_form(t: float) -> tuple[np.ndarray, np.ndarray]:
    """(v, ω) at ``t``: a = g + F/m; ω = τ t / I_xx about the body x axis (a principal axis, so
    no gyroscopic term)."""
    data = spin_up_scene()["bodies"][0]
    mass = data["mass"]
    inertia_xx = mass * (0.1**2 + 0.05**2) / 3.0
    acceleration = np.array([0.0, 0.0, -G]) + np.array(data["force"]) / mass
    return acceleration * t, np.array(data["torque"]) * t / inertia_xx


@pytest.mark.parametrize("engine", ENGINES)
def test_constant_force_and_torque_act_in_every_engine(engine):
    t = 0.4
    velocity, spin = spin_up_closed_form(t)
    data = {
        **spin_up_scene(),
        "expect": [
            {"kind": "velocity_at", "body": "box", "time": t, "value": velocity.tolist()},
            {"kind": "angular_velocity_at", "body": "box", "time": t, "value": spin.tolist()},
        ],
    }
    found = rows(data, engine)
    for metric, scale in (("velocity_at.box", velocity), ("angular_velocity_at.box", spin)):
        error = found[metric]["error"]
        assert error <= ROUND_OFF * np.linalg.norm(scale), f"{engine} {metric}: {error:.3g}"
    # L = τ t and p = (M g + F) t exactly; energy is not an invariant under a torque: no row
    assert found["angular_momentum_drift"]["error"] <= ROUND_OFF, found["angular_momentum_drift"]
    assert found["linear_momentum_drift"]["error"] <= ROUND_OFF, found["linear_momentum_drift"]
    assert "energy_drift" not in found


def test_a_constant_force_is_counted_in_the_energy():
    """A force without a torque is conservative: E includes -F·x, and a thrust along x at
    semi-implicit Euler drifts by the scheme's ½ m a² t dt only, over E_scale = the largest
    kinetic energy ½ m (a t)² plus the force over the box's bounding radius, |F|·r."""
    data = spin_up_scene()
    body = data["bodies"][0]
    data["bodies"] = [{**body, "torque": [0.0, 0.0, 0.0], "force": [4.0, 0.0, 0.0]}]
    data["gravity"] = [0.0, 0.0, 0.0]
    found = rows(data, "mini")["energy_drift"]
    a, t_end, dt, mass = 2.0, 0.5, 1e-3, 2.0
    scheme = 0.5 * mass * a**2 * t_end * dt  # E_k - E_0 = ½ m a² dt² k: v exact, x ahead
    scale = 0.5 * mass * (a * t_end) ** 2 + mass * a * math.sqrt(0.2**2 + 0.1**2 + 0.05**2)
    assert found["value"] == pytest.approx(scheme / scale, rel=1e-6), found
    assert f"{scheme:.6g} J" in found["message"], found["message"]


def test_the_dop853_reference_integrates_the_applied_loads():
    scene = compile_scene(Scenario.model_validate(spin_up_scene()))
    times = np.linspace(0.0, 0.5, 11)
    reference = reference_motion(scene, times)
    velocity, spin = spin_up_closed_form(0.5)
    assert np.allclose(reference.vel[-1, 0], velocity, rtol=DOP853_AGREEMENT, atol=0)
    error = np.linalg.norm(reference.ang_vel[-1, 0] - spin) / np.linalg.norm(spin)
    assert error <= DOP853_AGREEMENT, f"|ω - τ t / I| / |ω| = {error:.3g}"


BAD_INPUTS = {
    "ground: {normal: [0, 0, 0]}\nbodies:\n  - {name: b, shape: {type: sphere, radius: 0.1}, mass: 1}\n": (
        "ground.normal",
        "non-zero direction",
    ),
    "bodies:\n  - {name: b, shape: {type: sphere, radius: 0.1}, mass: 1, fixed: true, torque: [0, 0, 1]}\n": (
        "bodies[0].torque",
        "fixed body",
    ),
}


@pytest.mark.parametrize("body", BAD_INPUTS, ids=["zero_normal", "load_on_fixed_body"])
def test_bad_ground_and_loads_are_refused_with_the_field(tmp_path, body):
    bad = tmp_path / "bad.yaml"
    bad.write_text("dt: 0.001\nduration: 0.1\n" + body)
    with pytest.raises(ScenarioError) as error:
        load_scenario(bad)
    field, words = BAD_INPUTS[body]
    assert field in str(error.value) and words in str(error.value), str(error.value)


def test_a_sweep_at_round_off_reports_no_order():
    """RK4 integrates constant loads exactly: its sweep errors are round-off, and a slope fitted
    through them (measured -1.3 before) is not an order."""
    from validation.jobs.sweep import AT_ROUND_OFF, sweep_scene

    scenario = Scenario.model_validate({**spin_up_scene(), "duration": 0.2})
    rows_ = sweep_scene((scenario, parse_engine_spec("mujoco(integrator=RK4)"), [4e-3, 2e-3, 1e-3]))
    orders = [r for r in rows_ if r["metric"] == "convergence_order"]
    assert len(orders) == 2 and all(r["message"].startswith(AT_ROUND_OFF) for r in orders), orders
    assert all(r["status"] == "unsupported" and math.isnan(r["value"]) for r in orders), orders
