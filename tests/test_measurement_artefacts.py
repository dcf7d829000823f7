"""Every number is the engine's, not the harness's: the measurement artefacts an audit found.

Each test runs a real engine on a small scene whose answer is known in closed form and checks
that the harness reads the engine's own motion: no motion invented by a carry-back, no drift
scale that moves with the origin, no error added between observed steps, and errors that keep
their sign.
"""

from __future__ import annotations

import math

import pytest
from scene_rows import rows

G = 9.81

ROUND_OFF = 1e-9
"""In the quantity's SI unit: what double-precision round-off leaves of a metre-sized, 1 s
scene (1e3 to 1e4 steps of about 1e-16 relative each, with margin); an artefact of the
harness is 1e-6 or more in every case below."""


def _sphere(name: str, **extra) -> dict:
    return {"name": name, "shape": {"type": "sphere", "radius": 0.1}, "mass": 1.0, **extra}


# --- 1. velocity after an impact: carried back with what acted on the body ------------------

STRUCK_BOX = {
    "name": "struck_box",
    "dt": 1.0e-3,
    "duration": 0.6,
    "ground": {"restitution": 0.0, "friction": 0.0},
    "bodies": [
        {
            "name": "box",
            "shape": {"type": "box", "half_extents": [0.1, 0.1, 0.1]},
            "mass": 2.0,
            "position": [0.0, 0.0, 0.1],
        },
        {**_sphere("ball", mass=0.5), "position": [-0.4, 0.0, 0.1], "velocity": [2.0, 0.0, 0.0]},
    ],
    "pairs": [
        {"a": "ball", "b": "box", "restitution": 0.5, "friction": 0.0},
        {"a": "ball", "b": "ground", "restitution": 0.0, "friction": 0.0},
        {"a": "box", "b": "ground", "restitution": 0.0, "friction": 0.0},
    ],
    # momentum and Newton's law, e = 0.5: v_box = (1 + e) m_ball v / (m_ball + m_box) = 0.6 m/s
    "expect": [{"kind": "velocity_after_impact", "body": "box", "value": [0.6, 0.0, 0.0]}],
}
"""A 2 kg box at rest on a frictionless floor, struck centrally and horizontally by a 0.5 kg
ball at 2 m/s: nothing moves vertically, before or after."""

SUPPORTED_VERTICAL_SPEED = 0.02
"""m/s, |v_z| of a struck body resting on the floor, truth 0. MuJoCo's soft contact (solref
20 ms) lets the box rock on the floor while the ball pushes it for 9 ms: its vertical speed
after the impact measured 1.3e-4 m/s; a rigid support (mini, PyBullet, MuJoCo's damper)
leaves round-off or MuJoCo's steady sinking g·dt²-scale creep (1.2e-5 m/s). The free-flight
carry-back this replaces read 0.68 m/s under MuJoCo's soft contact and 0.06 m/s under RK4."""

CASES = [
    (STRUCK_BOX, "box", "mujoco(restitution=soft)"),
    (STRUCK_BOX, "box", "mujoco(integrator=RK4)"),
]
"""The engines whose contact with the struck ball lasts several steps (so the carry-back
matters); mini, PyBullet and MuJoCo's damper resolve it within one step."""


@pytest.mark.parametrize(("scene", "body", "engine"), CASES, ids=lambda c: str(c)[:24])
def test_a_supported_body_struck_sideways_gets_no_vertical_velocity(scene, body, engine):
    row = rows(scene, engine)[f"velocity_after_impact.{body}"]
    vertical = abs(row["error_z"])
    assert vertical <= SUPPORTED_VERTICAL_SPEED, (
        f"{engine}: v_z after the impact {row['error_z']:.3g} m/s (truth 0); {row['message']}"
    )


# --- 2. energy drift: a scale that no choice of origin changes ---------------------------------


def _forced_spring_pair(offset: float) -> dict:
    """Two 1 kg spheres on a spring (k = 400 N/m), one pushed by a constant 2 N force along x,
    no gravity, placed ``offset`` m along x from the origin."""
    return {
        "name": "forced_spring_pair",
        "dt": 1.0e-3,
        "duration": 1.0,
        "gravity": [0.0, 0.0, 0.0],
        "bodies": [
            {**_sphere("a"), "position": [offset, 0.0, 0.0], "force": [2.0, 0.0, 0.0]},
            {**_sphere("b"), "position": [offset + 0.5, 0.0, 0.0], "velocity": [0.3, 0.0, 0.0]},
        ],
        "springs": [{"a": "a", "b": "b", "stiffness": 400.0, "rest_length": 0.45}],
    }


ORIGIN_INVARIANCE = 1e-6
"""Relative. The two placements run the same dynamics; at 1000 m from the origin each position
carries 1000 x 2.2e-16 = 2e-13 m of round-off, which moves a 1e-3 J energy error by far less
than this. The drift divided by |E(0)| differed 2000-fold between the placements."""


def test_energy_drift_does_not_depend_on_where_the_origin_is():
    near = rows(_forced_spring_pair(0.0), "mini")["energy_drift"]
    far = rows(_forced_spring_pair(1000.0), "mini")["energy_drift"]
    assert near["value"] > 1e-5, f"the scene must have an energy error to compare: {near}"
    ratio = far["value"] / near["value"]
    assert abs(ratio - 1.0) <= ORIGIN_INVARIANCE, (
        f"energy_drift {near['value']:.6g} near the origin, {far['value']:.6g} 1000 m away "
        f"(ratio {ratio:.6g}); {near['message']} / {far['message']}"
    )
    assert "J" in near["message"], f"the row keeps the error in J: {near['message']}"


def test_a_damped_spring_has_no_energy_drift_row():
    scene = _forced_spring_pair(0.0)
    scene["springs"][0]["damping"] = 1.0
    found = rows(scene, "mini")
    assert "energy_drift" not in found, "a damper dissipates: energy is not an invariant"


# --- 3, 4. values between observed steps --------------------------------------------------------

DT = 1.0e-3
MID_STEP = 0.9995
"""s: halfway between two observed steps of 1 ms, where a linear interpolation adds the most."""


def _projectile(time: float) -> dict:
    position = [3.0 * time, 0.0, 1.0 + 8.0 * time - 0.5 * G * time**2]
    velocity = [3.0, 0.0, 8.0 - G * time]
    return {
        "name": "projectile_between_steps",
        "dt": DT,
        "duration": 1.0,
        "bodies": [{**_sphere("ball"), "position": [0.0, 0.0, 1.0], "velocity": [3.0, 0.0, 8.0]}],
        "expect": [
            {"kind": "position_at", "body": "ball", "time": time, "value": position},
            {"kind": "velocity_at", "body": "ball", "time": time, "value": velocity},
        ],
    }


def test_rk4_is_exact_between_steps_on_a_projectile():
    """RK4 is exact for constant gravity, so any error between steps is the harness's: a linear
    interpolation read g·τ(dt - τ)/2 = 1.2e-6 m at mid-step."""
    found = rows(_projectile(MID_STEP), "mujoco(integrator=RK4)")
    for metric in ("position_at.ball", "velocity_at.ball"):
        assert found[metric]["error"] <= ROUND_OFF, f"{metric}: {found[metric]}"


SPIN = 5.0
"""rad/s about the body's z axis (a principal axis): the orientation is exp(ω t) exactly."""


def test_orientation_between_steps_is_interpolated_on_the_rotation_group():
    """A torque-free spin about a principal axis, read at mid-step: every engine's rotation is
    exact at the steps (mini's exponential map, MuJoCo RK4), so the error there is the harness's:
    the nearer step read |ω|·dt/2 = 2.5e-3 rad."""
    angle = SPIN * MID_STEP
    expected = [math.cos(angle / 2), 0.0, 0.0, math.sin(angle / 2)]
    scene = {
        "name": "spin_between_steps",
        "dt": DT,
        "duration": 1.0,
        "gravity": [0.0, 0.0, 0.0],
        "bodies": [
            {
                "name": "box",
                "shape": {"type": "box", "half_extents": [0.1, 0.2, 0.3]},
                "mass": 1.0,
                "angular_velocity": [0.0, 0.0, SPIN],
                "velocity": [1.0, 0.0, 0.0],
            }
        ],
        "expect": [{"kind": "orientation_at", "body": "box", "time": MID_STEP, "value": expected}],
    }
    for engine in ("mini", "mujoco(integrator=RK4)"):
        row = rows(scene, engine)["orientation_at.box"]
        assert row["error"] <= ROUND_OFF, f"{engine}: {row['error']:.3g} rad; {row['message']}"


# --- 6. errors keep their sign ------------------------------------------------------------------


def test_opposite_errors_of_one_size_differ_in_sign():
    """Explicit and semi-implicit Euler err by ±g·t·dt/2 on a projectile: the magnitudes are
    equal to round-off, the signed errors opposite (low for semi-implicit, high for explicit)."""
    scene = _projectile(1.0)
    semi = rows(scene, "mini")["position_at.ball"]
    explicit = rows(scene, "mini(integrator=explicit_euler)")["position_at.ball"]
    bound = 0.5 * G * 1.0 * DT
    assert semi["error"] == pytest.approx(explicit["error"], rel=1e-9)
    assert semi["error_z"] == pytest.approx(-bound, rel=1e-6), semi
    assert explicit["error_z"] == pytest.approx(bound, rel=1e-6), explicit
    assert semi["signed_error"] is None, "a vector's sign is in its components"
