"""The closed-form scenes' numbers, recomputed here independently of the YAML and of every engine.

Each test derives a scene's expected values from its initial conditions (Coulomb impulse theory,
Jacobi elliptic functions cross-checked by DOP853, the bounce series, the friction stop) and fails
when the YAML's value differs, so a typo in a scene fails a test. Where a tolerance is derived from
a discrete map (the bounce's impact times), the map is evaluated here and the YAML's tolerance must
cover its worst case without being loose by more than ``LOOSE``.
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest
from scipy.integrate import solve_ivp
from scipy.special import ellipk, ellipkinc

from validation.scenario import load_scenario

SCENES = Path(__file__).resolve().parent.parent / "scenarios"

VALUE_TOLERANCE = 1e-9
"""Relative. The YAML values are written to 10 significant digits or more."""

ELLIPTIC_VS_DOP853 = 1e-8
"""s. DOP853 at rtol 1e-12 locates a sign change of ω_y to about 1e-11 s (measured 4e-11 s); the
elliptic solution near m = 1 is as good; 1e-8 s still catches any mistake in the phase τ0."""

LOOSE = 1.05
"""A derived tolerance may exceed the derived bound by at most 5 % (rounding it up)."""


def _expectation(scenario, kind: str, body: str):
    return next(e for e in scenario.expect if e.kind == kind and e.body == body)


def _pair(scenario, body: str):
    return next(p for p in scenario.pairs if body in (p.a, p.b) and "ground" in (p.a, p.b))


# --- oblique impacts with friction -----------------------------------------------------------


def coulomb_sphere_impact(
    velocity, angular_velocity, radius: float, e: float, mu: float
) -> tuple[str, np.ndarray, np.ndarray]:
    """Rigid Coulomb impulse theory for a solid sphere hitting the ground z = 0 (normal +z).

    Returns the regime and the velocity and angular velocity after the impact (world frame). The
    contact point's slip is u = v_t + ω × r (r = -radius·z); a tangential impulse J changes it by
    (1/m + r²/I) J = (7/2) J/m; sliding stops when (2/7)|u| <= μ(1+e)|v_n|.
    """
    v = np.asarray(velocity, dtype=float)
    w = np.asarray(angular_velocity, dtype=float)
    arm = np.array([0.0, 0.0, -radius])
    slip = v + np.cross(w, arm)
    slip[2] = 0.0
    normal_change = (1.0 + e) * abs(v[2])  # per unit mass
    speed = float(np.linalg.norm(slip))
    if 2.0 / 7.0 * speed <= mu * normal_change:
        regime, tangential = "sticking", -2.0 / 7.0 * slip
    else:
        regime, tangential = "sliding", -mu * normal_change * slip / speed
    inertia = 0.4 * radius**2  # per unit mass
    v_after = v + tangential + np.array([0.0, 0.0, normal_change])
    w_after = w + np.cross(arm, tangential) / inertia
    return regime, v_after, w_after


@pytest.mark.parametrize(
    "body, regime", [("sliding", "sliding"), ("sticking", "sticking"), ("backspin", "sticking")]
)
def test_oblique_impact_friction_values(body: str, regime: str) -> None:
    scenario = load_scenario(SCENES / "formulas" / "oblique_impact_friction.yaml")
    spec, pair = scenario.body(body), _pair(scenario, body)
    found, v_after, w_after = coulomb_sphere_impact(
        spec.velocity, spec.angular_velocity, spec.shape.radius, pair.restitution, pair.friction
    )
    written_v = np.array(_expectation(scenario, "velocity_after_impact", body).value)
    written_w = np.array(_expectation(scenario, "angular_velocity_after_impact", body).value)
    print(f"{body}: {found}, v' {v_after} (YAML {written_v}), ω' {w_after} (YAML {written_w})")
    assert found == regime
    assert np.allclose(written_v, v_after, rtol=VALUE_TOLERANCE, atol=1e-12)
    assert np.allclose(written_w, w_after, rtol=VALUE_TOLERANCE, atol=1e-12)
    # the touch is exact at a step start: the centre reaches z = r after a whole number of steps
    steps = (spec.position[2] - spec.shape.radius) / abs(spec.velocity[2]) / scenario.dt
    assert abs(steps - round(steps)) < 1e-9, steps


def test_backspin_ball_comes_back() -> None:
    """The backspin body is the finding-7 case: rigid theory sends it backwards."""
    scenario = load_scenario(SCENES / "formulas" / "oblique_impact_friction.yaml")
    spec = scenario.body("backspin")
    assert spec.velocity[0] > 0.0
    assert _expectation(scenario, "velocity_after_impact", "backspin").value[0] < 0.0


# --- Dzhanibekov flip times --------------------------------------------------------------------


def elliptic_flip_times(inertia, omega, duration: float) -> np.ndarray:
    """Sign changes of ω2 (body axis 2, the intermediate one) of a torque-free body, I1 < I2 < I3,
    from the Jacobi elliptic solution (Landau & Lifshitz §37, case M² > 2E·I2): ω1 = ω1m cn τ,
    ω2 = ω2m sn τ, ω3 = ω3m dn τ, τ = λt + τ0; sn vanishes at τ = 2jK."""
    i1, i2, i3 = inertia
    w1, w2, w3 = omega
    energy2 = i1 * w1**2 + i2 * w2**2 + i3 * w3**2
    momentum2 = (i1 * w1) ** 2 + (i2 * w2) ** 2 + (i3 * w3) ** 2
    assert i1 < i2 < i3 and momentum2 > energy2 * i2 and w3 > 0.0
    rate = math.sqrt((i3 - i2) * (momentum2 - energy2 * i1) / (i1 * i2 * i3))
    m = (i2 - i1) * (energy2 * i3 - momentum2) / ((i3 - i2) * (momentum2 - energy2 * i1))
    w1m = math.sqrt((energy2 * i3 - momentum2) / (i1 * (i3 - i1)))
    w2m = math.sqrt((energy2 * i3 - momentum2) / (i2 * (i3 - i2)))
    tau0 = float(ellipkinc(math.atan2(w2 / w2m, w1 / w1m), m))
    quarter = float(ellipk(m))
    count = int((rate * duration + tau0) // (2.0 * quarter))
    return np.array([(2.0 * j * quarter - tau0) / rate for j in range(1, count + 1)])


def dop853_flip_times(inertia, omega, duration: float) -> np.ndarray:
    """The same sign changes from Euler's equations integrated by DOP853 at rtol 1e-12."""
    i1, i2, i3 = inertia

    def euler(_t, w):
        return [
            (i2 - i3) * w[1] * w[2] / i1,
            (i3 - i1) * w[2] * w[0] / i2,
            (i1 - i2) * w[0] * w[1] / i3,
        ]

    def crossing(_t, w):
        return w[1]

    solution = solve_ivp(
        euler, (0.0, duration), omega, method="DOP853", rtol=1e-12, atol=1e-14, events=crossing
    )
    return solution.t_events[0]


def _box_inertia(half_extents, mass: float) -> tuple[float, float, float]:
    x, y, z = (2.0 * h for h in half_extents)
    return (mass * (y * y + z * z) / 12, mass * (x * x + z * z) / 12, mass * (x * x + y * y) / 12)


def test_dzhanibekov_flip_times_values() -> None:
    scenario = load_scenario(SCENES / "rotation" / "dzhanibekov_flip_times.yaml")
    box = scenario.body("box")
    assert box.orientation == (1.0, 0.0, 0.0, 0.0)  # world ω = body ω at t = 0
    inertia = _box_inertia(box.shape.half_extents, box.mass)
    exact = elliptic_flip_times(inertia, box.angular_velocity, scenario.duration)
    reference = dop853_flip_times(inertia, box.angular_velocity, scenario.duration)
    written = np.array(_expectation(scenario, "flip_times", "box").value)
    print(f"elliptic {exact}, DOP853 {reference}, YAML {written}")
    assert exact.size == reference.size == written.size
    assert np.max(np.abs(exact - reference)) < ELLIPTIC_VS_DOP853
    assert np.allclose(written, exact, rtol=VALUE_TOLERANCE, atol=0.0)
    assert _expectation(scenario, "flips", "box").value == exact.size


def test_dzhanibekov_first_order_tolerance() -> None:
    """The first-order tolerance is t·σ·dt/2 at the last flip (the escape rate from the unstable
    axis is σ(1 ∓ σ·dt/2) for one explicit/implicit step)."""
    scenario = load_scenario(SCENES / "rotation" / "dzhanibekov_flip_times.yaml")
    box = scenario.body("box")
    i1, i2, i3 = _box_inertia(box.shape.half_extents, box.mass)
    sigma = box.angular_velocity[1] * math.sqrt((i2 - i1) * (i3 - i2) / (i1 * i3))
    last = max(_expectation(scenario, "flip_times", "box").value)
    bound = last * sigma * scenario.dt / 2.0
    tolerance = scenario.tolerance("flip_times.box", "mujoco")
    print(f"σ = {sigma:.6g} rad/s, bound {bound:.6g} s, YAML {tolerance}")
    assert bound <= tolerance <= LOOSE * bound


# --- bounce impact times -----------------------------------------------------------------------


def bounce_impact_times(fall: float, e: float, g: float, count: int) -> np.ndarray:
    """t_k = t_0 + Σ_{i=1..k} 2 e^i v_0/g with t_0 = sqrt(2 fall/g), v_0 = sqrt(2 g fall)."""
    t0, v0 = math.sqrt(2.0 * fall / g), math.sqrt(2.0 * g * fall)
    flights = [2.0 * e**i * v0 / g for i in range(1, count)]
    return t0 + np.concatenate([[0.0], np.cumsum(flights)])


def discrete_impact_times(
    fall: float, e: float, g: float, dt: float, count: int, after_gravity: bool, lift: float
) -> np.ndarray:
    """The exact discrete map of a bounce: semi-implicit Euler in free flight; a contact found at
    the start of a step (centre at or below touching, within 1 µm) is resolved in that step, the
    rebound e·|v| on the approach speed after this step's gravity (``after_gravity``, mini) or
    before it; ``lift`` of the penetration is undone in that step (a split-impulse pseudo-velocity);
    the impact counts at the end of its step."""
    z, v, step, times = fall, 0.0, 0, []
    while len(times) < count:
        if z <= 1e-6 and v < 0.0:
            v = e * ((g * dt - v) if after_gravity else -v)
            z -= lift * min(z, 0.0)
            z += v * dt
            step += 1
            times.append(step * dt)
        else:
            v -= g * dt
            z += v * dt
            step += 1
    return np.array(times)


BOUNCE_CONVENTIONS = {
    "mini": (True, 0.0),
    "mujoco": (False, 0.0),
    "pybullet": (False, 0.2),
}
"""Engine -> (e after this step's gravity, split-impulse lift): engines.md 4 (conventions) and
2.1 (Bullet's erp 0.2)."""


def test_bounce_impact_times_values() -> None:
    scenario = load_scenario(SCENES / "formulas" / "bounce_impact_times.yaml")
    ball = scenario.body("ball")
    fall = ball.position[2] - ball.shape.radius
    written = np.array(_expectation(scenario, "impact_times", "ball").value)
    exact = bounce_impact_times(
        fall, _pair(scenario, "ball").restitution, -scenario.gravity[2], written.size
    )
    print(f"closed form {exact}, YAML {written}")
    assert np.allclose(written, exact, rtol=VALUE_TOLERANCE, atol=0.0)


@pytest.mark.parametrize("engine", sorted(BOUNCE_CONVENTIONS))
def test_bounce_impact_time_tolerances(engine: str) -> None:
    """Each engine's tolerance covers the worst case of its discrete map over every phase of the
    drop within one step, and is not looser than ``LOOSE`` times it."""
    scenario = load_scenario(SCENES / "formulas" / "bounce_impact_times.yaml")
    ball = scenario.body("ball")
    e, g, dt = _pair(scenario, "ball").restitution, -scenario.gravity[2], scenario.dt
    count = len(_expectation(scenario, "impact_times", "ball").value)
    fall = ball.position[2] - ball.shape.radius
    after_gravity, lift = BOUNCE_CONVENTIONS[engine]
    worst = 0.0
    for phase in np.linspace(0.0, 1.0, 201):
        drop = fall + phase * math.sqrt(2.0 * g * fall) * dt
        errors = discrete_impact_times(drop, e, g, dt, count, after_gravity, lift)
        worst = max(worst, float(np.max(np.abs(errors - bounce_impact_times(drop, e, g, count)))))
    tolerance = scenario.tolerance("impact_times.ball", engine)
    print(f"{engine}: worst {worst:.6g} s = {worst / dt:.4g} dt, YAML {tolerance}")
    assert worst <= tolerance <= LOOSE * worst


def test_bounce_map_is_mini() -> None:
    """The discrete map with mini's convention at the scene's own drop gives mini's measured
    times (engines-independent: the map is the scheme; mini measured 0.453, 1.178, 1.759,
    2.226, 2.601 s)."""
    scenario = load_scenario(SCENES / "formulas" / "bounce_impact_times.yaml")
    ball = scenario.body("ball")
    times = discrete_impact_times(
        ball.position[2] - ball.shape.radius, 0.8, 9.81, scenario.dt, 5, True, 0.0
    )
    print(times)
    assert np.allclose(times, [0.453, 1.178, 1.759, 2.226, 2.601], atol=1e-9)


# --- a box sliding to a stop -------------------------------------------------------------------


def test_box_slide_values() -> None:
    scenario = load_scenario(SCENES / "contact" / "box_slide_stop.yaml")
    box = scenario.body("box")
    v0, mu, g = box.velocity[0], _pair(scenario, "box").friction, -scenario.gravity[2]
    a = mu * g
    stop_time, stop_distance = v0 / a, v0**2 / (2.0 * a)
    assert scenario.duration > stop_time
    half = box.shape.half_extents
    assert mu * half[2] < half[0]  # the normal force's centre stays inside the face: no tipping
    for kind, name in (("position_at", "position_at.box"), ("velocity_at", "velocity_at.box")):
        item = next(e for e in scenario.expect if e.metric == name)
        t = item.time
        assert t < stop_time
        x = v0 * t - a * t * t / 2.0 if kind == "position_at" else v0 - a * t
        print(f"{name} at {t} s: {x} (YAML {item.value[0]})")
        assert math.isclose(item.value[0], x, rel_tol=VALUE_TOLERANCE)
    stopped = next(e for e in scenario.expect if e.metric == "position_at.box.stopped")
    print(f"stop distance {stop_distance} (YAML {stopped.value[0]})")
    assert math.isclose(stopped.value[0], stop_distance, rel_tol=VALUE_TOLERANCE)
    # mini's derived bounds: a·t·dt/2 mid-slide, v0·dt/2 at the stop
    mid = next(e for e in scenario.expect if e.metric == "position_at.box")
    assert scenario.tolerance("position_at.box", "mini") >= a * mid.time * scenario.dt / 2.0
    assert scenario.tolerance("position_at.box.stopped", "mini") >= v0 * scenario.dt / 2.0


# --- boxes sliding in an oblique direction (isotropic friction) ---------------------------------


def _slide(scenario, name: str):
    """A box sliding on the scene's ground under gravity and Coulomb friction: its start, unit
    slip direction, signed acceleration along it (m/s²) and launch speed (m/s)."""
    body = scenario.body(name)
    normal = np.asarray(scenario.ground.normal, dtype=float)
    normal /= np.linalg.norm(normal)
    gravity = np.asarray(scenario.gravity, dtype=float)
    along_slope = gravity - (gravity @ normal) * normal
    velocity = np.asarray(body.velocity, dtype=float)
    speed = float(np.linalg.norm(velocity))
    direction = velocity / speed if speed else along_slope / np.linalg.norm(along_slope)
    # the launch and the slope's pull are one line: the slip keeps its direction
    assert np.linalg.norm(np.cross(direction, along_slope)) <= 1e-12 * max(
        1.0, float(np.linalg.norm(along_slope))
    )
    mu = _pair(scenario, name).friction
    acceleration = float(along_slope @ direction) - mu * abs(float(gravity @ normal))
    if speed == 0.0:
        assert acceleration > 0.0  # released at rest, it must slide
    return np.asarray(body.position, dtype=float), direction, acceleration, speed


@pytest.mark.parametrize(
    ("scene", "bodies"),
    [("box_slide_oblique", ("box",)), ("box_incline_oblique", ("slowing", "speeding"))],
)
def test_oblique_slide_values(scene: str, bodies: tuple[str, ...]) -> None:
    scenario = load_scenario(SCENES / "contact" / f"{scene}.yaml")
    dt = scenario.dt
    for name in bodies:
        start, direction, a, v0 = _slide(scenario, name)
        stop_time = v0 / -a if a < 0.0 else math.inf
        half = scenario.body(name).shape.half_extents
        mu = _pair(scenario, name).friction
        assert mu * half[2] < min(half[0], half[1])  # no tipping in any direction
        if stop_time < math.inf:  # it sticks once stopped: μ g_n holds the slope's pull
            assert scenario.duration > stop_time
        for item in (e for e in scenario.expect if e.body == name):
            t = min(item.time, stop_time)
            if item.kind == "position_at":
                expected = start + (v0 * t + a * t * t / 2.0) * direction
            elif item.kind == "velocity_at":
                expected = (v0 + a * t) * direction
            else:
                expected = np.zeros(3)  # angular_velocity_at: it never turns
            print(f"{item.metric} at {item.time} s: {expected} (YAML {item.value})")
            assert np.allclose(item.value, expected, rtol=0.0, atol=VALUE_TOLERANCE)
            if item.kind != "position_at":
                continue
            # mini's derived bounds: |a|·t·dt/2 while sliding, v0·dt/2 (less) at the stop
            bound = v0 * dt / 2.0 if item.time > stop_time else abs(a) * item.time * dt / 2.0
            assert scenario.tolerance(item.metric, "mini") >= bound * (1.0 - 1e-9)
            assert scenario.tolerance(item.metric, "mini") <= bound * LOOSE
