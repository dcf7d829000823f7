"""The PyBullet adapter, measured: boundary conventions, the parity gate, free fall, the
restitution recipe against PyBullet's defaults, torque-free tumbling, and the process-wide
contact breaking threshold (docs/engines.md section 2 for every number)."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pybullet
import pytest

from mini_engine.rotation import quat_to_matrix
from validation.engines.parity import compare
from validation.engines.pybullet import adapter as pybullet_engine
from validation.engines.pybullet.adapter import PybulletAdapter
from validation.engines.reference import reference_report
from validation.measure.runner import loader_of, model_owned, run_engine
from validation.scenario import Scenario, load_scenario, scenario_files
from validation.scenario.compiled import compile_scene
from validation.scenario.engine_spec import parse_engine_spec

ROUND_OFF = 1e-12
"""Absolute, in the quantity's SI unit: the boundary converts frames with a few double
products (quaternion products, x y z w <-> w x y z), nothing more."""

FREE_FALL_TOLERANCE = 1e-9
"""m. engines.md 1.6: PyBullet's free fall equals semi-implicit Euler's closed form
"exactly"; 1000 steps of round-off in z ~ 10 m stay far below this."""

RESTITUTION_TOLERANCE = 0.01
"""Relative error of e. engines.md 2.4: the matched recipe (maximal + split impulse +
contactBreakingThreshold 1e-6) measured e = 0.4967–0.5001 and 1.0000–1.0003 over 25
drop heights, within 0.7 %; rounded up to 1 %."""

IMPULSE_JUMP = 0.05
"""m/s. A step whose velocity change differs from gravity's g·dt by more than this holds a
contact impulse. Below it: resting contact (g·dt = 0.0098 m/s at dt = 1e-3) and PyBullet's
default multibody damping (< 1e-3 m/s per step at 5 m/s, engines.md 2.2)."""

MIN_IMPACT_SPEED = 0.5
"""m/s. Slower impacts are left out: gravity's share of the step (g·dt/v ≥ 2 %) is then
comparable with the tolerance."""

GRAVITY = 9.81
"""m/s², the scenes' |g|."""

DZHANIBEKOV_FLIPS = 3
"""engines.md 1.8: RK4 at dt = 1e-5 flips 3 times in 10 s, and so does every engine."""

BODY_MODES = ("pybullet", "pybullet(bodies=multibody)")
ALL_PROFILES = (*BODY_MODES, "pybullet(profile=defaults)")


def adapter_for(text: str, scenario: Scenario) -> PybulletAdapter:
    adapter = PybulletAdapter(parse_engine_spec(text))
    adapter.load(compile_scene(scenario))
    return adapter


def scene(**fields) -> Scenario:
    return Scenario.model_validate({"dt": 1e-3, "duration": 1.0, **fields})


def sphere(name="ball", **fields) -> dict:
    return {"name": name, "shape": {"type": "sphere", "radius": 0.1}, "mass": 1.0, **fields}


# --- 1. conventions -------------------------------------------------------------------------

TILTED = np.array([0.8, 0.3, -0.4, 0.33]) / np.linalg.norm([0.8, 0.3, -0.4, 0.33])
FULL_INERTIA = [[0.3, 0.02, -0.01], [0.02, 0.25, 0.03], [-0.01, 0.03, 0.1]]


def spinning_box() -> Scenario:
    return scene(
        gravity=[0.0, 0.0, 0.0],
        bodies=[
            {
                "name": "box",
                "shape": {"type": "box", "half_extents": [0.3, 0.2, 0.1]},
                "mass": 2.0,
                "inertia": FULL_INERTIA,
                "position": [1.0, -2.0, 3.0],
                "orientation": TILTED.tolist(),
                "velocity": [0.5, -0.2, 0.3],
                "angular_velocity": [1.0, 2.0, -3.0],
            }
        ],
    )


@pytest.mark.parametrize("text", BODY_MODES)
def test_observe_returns_the_scene_state_and_moves_the_com_by_v_dt(text):
    scenario = spinning_box()
    body = scenario.bodies[0]
    with adapter_for(text, scenario) as adapter:
        _, inertial = pybullet.getBasePositionAndOrientation(
            adapter.ids[0], physicsClientId=adapter.client
        )
        tilt = np.abs(pybullet_engine.from_xyzw(inertial) - TILTED).max()
        assert tilt > 0.01, "the principal-axes conversion was not exercised"
        start = adapter.observe()
        errors = {
            "pos": np.abs(start.pos[0] - body.position).max(),
            "quat": min(np.abs(start.quat[0] - TILTED).max(), np.abs(start.quat[0] + TILTED).max()),
            "vel": np.abs(start.vel[0] - body.velocity).max(),
            "ang_vel": np.abs(start.ang_vel[0] - body.angular_velocity).max(),
        }
        assert max(errors.values()) <= ROUND_OFF, errors
        adapter.advance(1)
        moved = adapter.observe().pos[0] - start.pos[0]
        drift = np.abs(moved - np.asarray(body.velocity) * scenario.dt).max()
        assert drift <= ROUND_OFF, (
            f"COM moved {moved}, v·dt = {np.asarray(body.velocity) * scenario.dt}"
        )


# --- 2. parity ------------------------------------------------------------------------------

BUNDLED = scenario_files([Path(__file__).resolve().parent.parent / "scenarios"])


def mixed_scene() -> Scenario:
    """Every shape, a full inertia, a fixed body, springs to a body, the world and a fixed body."""
    return scene(
        bodies=[
            spinning_box().bodies[0].model_dump(),
            {
                "name": "capsule",
                "shape": {"type": "capsule", "radius": 0.1, "half_length": 0.2},
                "mass": 1.5,
                "position": [0.0, 0.0, 1.0],
                "angular_velocity": [0.0, 1.0, 0.0],
            },
            sphere("post", position=[0.0, 1.0, 0.5], fixed=True),
        ],
        springs=[
            {
                "a": "box",
                "b": "capsule",
                "anchor_a": [0.1, 0, 0],
                "stiffness": 100.0,
                "rest_length": 0.5,
            },
            {
                "a": "capsule",
                "b": "world",
                "anchor_b": [0, 0, 3],
                "stiffness": 50.0,
                "damping": 1.0,
            },
            {"a": "box", "b": "post", "stiffness": 10.0},
        ],
        ground={"restitution": 0.2},
    )


@pytest.mark.parametrize("text", ALL_PROFILES)
@pytest.mark.parametrize(
    "source", ["mixed", *BUNDLED], ids=lambda p: p if p == "mixed" else f"{p.parent.name}/{p.stem}"
)
def test_parity_gate_passes(source, text):
    scenario = mixed_scene() if source == "mixed" else load_scenario(source)
    compiled = compile_scene(scenario)
    with adapter_for(text, scenario) as adapter:
        mismatches = compare(adapter.model_report(), reference_report(compiled))
        if compiled.models and loader_of(adapter, parse_engine_spec(text)) == "native":
            mismatches = model_owned(compiled, mismatches)[1]  # the models' own are tier 1's
    assert mismatches == [], [str(m) for m in mismatches]


def test_parity_gate_names_a_wrong_inertia(monkeypatch):
    right = pybullet_engine.body_inertia
    monkeypatch.setattr(pybullet_engine, "body_inertia", lambda spec: 1.01 * right(spec))
    scenario = mixed_scene()
    with adapter_for("pybullet", scenario) as adapter:
        mismatches = compare(adapter.model_report(), reference_report(compile_scene(scenario)))
    assert {m.quantity for m in mismatches} >= {"inertia_world"}, [str(m) for m in mismatches]


# --- 3. free fall ---------------------------------------------------------------------------


@pytest.mark.parametrize("text", ALL_PROFILES)
def test_free_fall_is_semi_implicit_euler(text):
    """z(t) = z0 − g t²/2 − g t dt/2 after n steps of v += g dt; x += v dt (engines.md 1.6).
    The defaults profile's multibody damping is quadratic in v, so only matched is exact."""
    scenario = scene(bodies=[sphere(position=[0.0, 0.0, 10.0])])
    steps, dt = 1000, scenario.dt
    with adapter_for(text, scenario) as adapter:
        adapter.advance(steps)
        z = adapter.observe().pos[0, 2]
    t = steps * dt
    error = z - (10.0 - 0.5 * GRAVITY * t**2)
    expected = -GRAVITY * t * dt / 2
    if "defaults" in text:
        assert abs(error - expected) > 1e-3, f"damping left no trace: z error {error:.6g} m"
    else:
        assert abs(error - expected) <= FREE_FALL_TOLERANCE, (
            f"z error {error:.12g} m, closed form {expected:.12g} m"
        )


# --- 4. restitution -------------------------------------------------------------------------


def impact_restitutions(vz: np.ndarray, dt: float) -> list[tuple[float, float]]:
    """(approach speed, e) per impact from sampled vertical velocities: an impact is a run of
    steps with a contact impulse (``IMPULSE_JUMP``); e = velocity after the run / speed
    before it (the observed velocities just before and after)."""
    jumps = np.flatnonzero(np.abs(np.diff(vz) + GRAVITY * dt) > IMPULSE_JUMP) + 1
    impacts, k = [], 0
    while k < len(jumps):
        end = k
        while end + 1 < len(jumps) and jumps[end + 1] == jumps[end] + 1:
            end += 1
        before, after = -vz[jumps[k] - 1], vz[jumps[end]]
        if before > MIN_IMPACT_SPEED:
            impacts.append((float(before), float(after / before)))
        k = end + 1
    return impacts


def drop(text: str, e: float, height: float, duration: float) -> list[tuple[float, float]]:
    """A frictionless 1 kg sphere (r = 0.1 m) dropped with its COM at ``height`` onto a
    ground of restitution 0 (the scene's pair value is max(e, 0) = e)."""
    scenario = scene(
        duration=duration, ground={}, bodies=[sphere(restitution=e, position=[0, 0, height])]
    )
    vz = np.zeros(round(duration / scenario.dt) + 1)
    with adapter_for(text, scenario) as adapter:
        for k in range(1, len(vz)):
            adapter.advance(1)
            vz[k] = adapter.observe().vel[0, 2]
    return impact_restitutions(vz, scenario.dt)


@pytest.mark.parametrize("text", BODY_MODES)
@pytest.mark.parametrize("e", [0.5, 1.0])
def test_matched_profile_bounces_with_the_requested_e(text, e):
    """Maximal bodies: v+ = e·v− exactly. btMultiBody applies Newton's law to the velocity
    after this step's gravity (engines.md 2.4), so there v+ = e·(v− + g·dt)."""
    impacts = drop(text, e, height=1.1, duration=2.5)
    assert len(impacts) >= 2, impacts
    gravity_share = "multibody" in text
    for speed, measured in impacts:
        expected = e * (1 + GRAVITY * 1e-3 / speed) if gravity_share else e
        assert abs(measured - expected) <= RESTITUTION_TOLERANCE * expected, (
            f"e {measured:.5f} at {speed:.3f} m/s, expected {expected:.5f}: {impacts}"
        )


def test_defaults_profile_misses_e_at_small_dt():
    """engines.md 2.4: at dt = 1e-3 Bullet's speculative contacts brake the sphere before it
    touches (22 of 25 heights bad). Shown here so the report can state what defaults cost."""
    heights = (0.5, 0.7, 0.9, 1.1, 1.3)
    first = {h: drop("pybullet(profile=defaults)", 0.5, h, duration=0.75)[0][1] for h in heights}
    worst = max(abs(m - 0.5) / 0.5 for m in first.values())
    assert worst > RESTITUTION_TOLERANCE, f"defaults e per height: {first}"


# --- 5. torque-free tumbling ----------------------------------------------------------------


@pytest.mark.parametrize("text", BODY_MODES)
def test_dzhanibekov_box_flips_three_times(text):
    scenario = Scenario.model_validate(
        {
            "dt": 1e-3,
            "duration": 10.0,
            "gravity": [0.0, 0.0, 0.0],
            "bodies": [
                {
                    "name": "box",
                    "shape": {"type": "box", "half_extents": [0.1, 0.1, 0.1]},
                    "mass": 1.0,
                    "inertia": [0.016667, 0.033333, 0.043333],
                    "angular_velocity": [0.05, 10.0, 0.05],
                }
            ],
        }
    )
    sample = 5  # steps between observations; a flip takes ~0.5 s
    signs = []
    with adapter_for(text, scenario) as adapter:
        for _ in range(scenario.steps // sample):
            adapter.advance(sample)
            state = adapter.observe()
            omega_body = quat_to_matrix(state.quat)[0].T @ state.ang_vel[0]
            signs.append(np.sign(omega_body[1]))
    flips = int(np.sum(np.diff(signs) != 0))
    assert flips == DZHANIBEKOV_FLIPS, f"{flips} flips"


# --- 6. process-wide contact breaking threshold ---------------------------------------------


def hovering_sphere() -> Scenario:
    """A sphere 2 mm above the ground at rest without gravity: Bullet's default threshold
    (0.02 × bounding radius ≈ 3.5 mm, engines.md 2.4) makes a contact point, 1e-6 none."""
    return scene(gravity=[0, 0, 0], ground={}, bodies=[sphere(position=[0, 0, 0.102])])


def contact_count(adapter: PybulletAdapter) -> int:
    adapter.advance(1)
    return len(pybullet.getContactPoints(physicsClientId=adapter.client))


def test_contact_breaking_threshold_does_not_leak_between_adapters():
    with adapter_for("pybullet", hovering_sphere()) as matched:
        assert contact_count(matched) == 0
    with adapter_for("pybullet(profile=defaults)", hovering_sphere()) as defaults:
        assert contact_count(defaults) > 0, "the matched threshold leaked into defaults"
    # interleaved: each adapter's advance reasserts its own value of the C global
    with (
        adapter_for("pybullet", hovering_sphere()) as matched,
        adapter_for("pybullet(profile=defaults)", hovering_sphere()) as defaults,
    ):
        counts = (contact_count(matched), contact_count(defaults))
    assert counts[0] == 0 and counts[1] > 0, counts


# --- contact values as products ------------------------------------------------------------


def test_body_ground_pairs_get_their_values_as_products():
    scenario = scene(
        ground={"restitution": 0.0, "friction": 0.5},
        bodies=[
            sphere("a", restitution=0.3, friction=0.2, position=[0, 0, 1]),
            sphere("b", restitution=0.3, friction=0.8, position=[2, 0, 1]),
        ],
    )
    with adapter_for("pybullet", scenario) as adapter:
        values = adapter.provenance().settings["contact_values"]
        assert not adapter.contact_misses, adapter.contact_misses
    e, mu = np.array(values["restitution"]), np.array(values["friction"])
    products = {
        "e_a": e[0] * e[2],
        "e_ab": e[0] * e[1],
        "mu_a": mu[0] * mu[2],
        "mu_ab": mu[0] * mu[1],
    }
    wanted = {"e_a": 0.3, "e_ab": 0.3, "mu_a": np.sqrt(0.1), "mu_ab": 0.4}
    assert all(abs(products[k] - wanted[k]) <= ROUND_OFF for k in wanted), (products, wanted)


def test_inexpressible_pairs_are_named_in_the_notes():
    """Ground e = 0 and balls e = 0.1, 0.9, 0.5: exact ground pairs need x_i = e_i / x_g, so
    ball pairs get e_i e_j / x_g², and max(e_i, e_j) asks x_g² = 0.1, 0.1 and 0.5 at once.
    The ground pairs stay exact and the notes name the ball pairs with both values."""
    scenario = scene(
        ground={},
        bodies=[
            sphere("a", restitution=0.1),
            sphere("b", restitution=0.9, position=[0.5, 0, 0]),
            sphere("c", restitution=0.5, position=[1.0, 0, 0]),
        ],
    )
    with adapter_for("pybullet", scenario) as adapter:
        e = adapter.contact_values["restitution"]
        notes = "\n".join(adapter.provenance().notes)
    ground_pairs = [e[i] * e[3] for i in range(3)]
    assert np.allclose(ground_pairs, [0.1, 0.9, 0.5], rtol=0, atol=ROUND_OFF), ground_pairs
    assert "restitution b–c (between moving bodies" in notes and "scene 0.9" in notes, notes


def test_provenance_records_version_parameters_and_springs():
    with adapter_for("pybullet(bodies=multibody, solver_iterations=20)", mixed_scene()) as adapter:
        record = adapter.provenance()
    settings = record.settings
    assert record.version == "3.2.7" and settings["api_version"] == pybullet.getAPIVersion()
    assert settings["engine_parameters"]["numSolverIterations"] == 20, settings
    assert settings["set_world_parameters"]["contactERP"] == pybullet_engine.MULTIBODY_CONTACT_ERP
    assert any("explicit in time" in note for note in record.notes), record.notes


TOUCHING_IMPACT_SPEEDS = (0.03, 1.0)
"""m/s: a slow and a fast impact that start their step exactly touching the ground."""

SLOP_STEPS = (2e-3, 1e-3, 5e-4)
"""s: Bullet's default contactSlop (1e-5 m) cost slop/dt of rebound at each: 5, 10, 20 mm/s."""

REBOUND_TOLERANCE = 1e-9
"""m/s: with no slop, no gravity and e = 0.5 the matched rebound is e·v to round-off."""


@pytest.mark.parametrize("dt", SLOP_STEPS)
def test_a_touching_impact_keeps_its_whole_rebound(dt):
    """Issue-10 finding 8: the matched profile lost (1e-5 m)/dt of rebound when an impact
    step started exactly touching."""
    for speed in TOUCHING_IMPACT_SPEEDS:
        scenario = Scenario.model_validate(
            {
                "name": "touching",
                "dt": dt,
                "duration": 0.05,
                "gravity": [0, 0, 0],
                "ground": {"restitution": 0.5},
                "bodies": [
                    {
                        "name": "b",
                        "shape": {"type": "sphere", "radius": 0.1},
                        "mass": 1.0,
                        "position": [0, 0, 0.1],
                        "velocity": [0, 0, -speed],
                        "restitution": 0.5,
                    }
                ],
            }
        )
        run = run_engine(compile_scene(scenario), parse_engine_spec("pybullet"), 1)
        rebound = float(run.recording.trajectory.vel[:, 0, 2].max())
        assert abs(rebound - 0.5 * speed) <= REBOUND_TOLERANCE, (dt, speed, rebound)


# --- boxes resting and sliding on the ground ------------------------------------------------

SLIDE_FRICTION = 0.2
SLIDE_SPEED = 1.0
"""m/s. box_slide_stop's launch: the box decelerates at μg = 1.962 m/s² and stops at 0.51 s."""

SLIDE_DURATION = 0.45
"""s: the whole slide before the stop (the stop itself is a static-friction transient)."""

SLIDING_BOX_TOLERANCE = 1e-9
"""m/s, the largest velocity error of any point of the box. With 4 contact points a step and a
solver that runs all its iterations (adapter ``GROUND_BOX_HALF_THICKNESS``,
``MATCHED_SOLVER_RESIDUAL_THRESHOLD``) PyBullet's slide is semi-implicit Euler's
v_n = v0 − μg·n·dt: measured 7e-15 m/s (both body modes) from the second step on. On the
GEOM_PLANE ground (main before this test) it measured 0.084 m/s (maximal) and 0.105 m/s
(multibody): the box rocks on 1–2 points. 1e-9 is round-off headroom over 450 steps."""

STACK_REST_SPEED_TOLERANCE = 5e-3
"""m/s, the largest speed of any box of box_stack.yaml in its second second. Five cubes solved
by 50 sequential-impulse iterations do not converge exactly: measured 1.9 mm/s (maximal) and
2.4 mm/s (multibody) on the box ground, 57 and 31 mm/s on GEOM_PLANE. Half the scene's own
0.01 m/s allowance for soft contacts, so a regression shows here before it fails the scene."""


def trajectory_of(scenario: Scenario, text: str):
    """Every observed state of ``scenario`` run in the engine spec ``text``."""
    return run_engine(compile_scene(scenario), parse_engine_spec(text), 1).recording.trajectory


def sliding_box_velocity_error(text: str) -> float:
    """box_slide_stop's box (1 kg, 0.4 x 0.4 x 0.1 m, exactly touching, 1 m/s, μ = 0.2) for
    ``SLIDE_DURATION``: the largest |v − (v0 − μg·t, 0, 0)| + |ω|·r over the steps from the
    second on (r the box's half-diagonal: every point's velocity error is at most this). The
    first step is left out: box–box contacts only report overlap, so a box that starts exactly
    touching falls g·dt² before its first contact (adapter ``GROUND_BOX_HALF_THICKNESS``)."""
    half = np.array([0.2, 0.2, 0.05])
    scenario = scene(
        duration=SLIDE_DURATION,
        ground={},
        bodies=[
            {
                "name": "box",
                "shape": {"type": "box", "half_extents": half.tolist()},
                "mass": 1.0,
                "position": [0.0, 0.0, half[2]],
                "velocity": [SLIDE_SPEED, 0.0, 0.0],
            }
        ],
        pairs=[{"a": "box", "b": "ground", "friction": SLIDE_FRICTION}],
    )
    trajectory = trajectory_of(scenario, text)
    later = trajectory.t >= 2 * scenario.dt - ROUND_OFF
    wanted = np.zeros((int(later.sum()), 3))
    wanted[:, 0] = SLIDE_SPEED - SLIDE_FRICTION * GRAVITY * trajectory.t[later]
    velocity = np.linalg.norm(trajectory.vel[later, 0] - wanted, axis=-1)
    spin = np.linalg.norm(trajectory.ang_vel[later, 0], axis=-1) * np.linalg.norm(half)
    return float((velocity + spin).max())


@pytest.mark.parametrize("text", BODY_MODES)
def test_a_sliding_box_decelerates_at_mu_g_without_rocking(text):
    error = sliding_box_velocity_error(text)
    assert error <= SLIDING_BOX_TOLERANCE, (
        f"{text}: sliding box velocity error {error:.3g} m/s (tolerance {SLIDING_BOX_TOLERANCE})"
    )


def stack_rest_speed(text: str) -> float:
    """The largest speed (m/s) of any cube of box_stack.yaml between t = 1 s and 2 s."""
    stack = next(path for path in BUNDLED if path.name == "box_stack.yaml")
    trajectory = trajectory_of(load_scenario(stack), text)
    late = trajectory.t >= 1.0
    return float(np.linalg.norm(trajectory.vel[late], axis=-1).max())


@pytest.mark.parametrize("text", BODY_MODES)
def test_a_box_stack_rests(text):
    speed = stack_rest_speed(text)
    assert speed <= STACK_REST_SPEED_TOLERANCE, (
        f"{text}: a stacked box moves at {speed:.3g} m/s (tolerance {STACK_REST_SPEED_TOLERANCE})"
    )


def test_only_the_matched_profile_replaces_the_plane():
    scenario = scene(ground={}, bodies=[sphere(position=[0, 0, 1])])
    shapes = {}
    for text in ALL_PROFILES:
        with adapter_for(text, scenario) as adapter:
            shapes[text] = adapter.provenance().settings["ground"]["shape"]
    assert shapes == {
        "pybullet": "GEOM_BOX",
        "pybullet(bodies=multibody)": "GEOM_BOX",
        "pybullet(profile=defaults)": "GEOM_PLANE",
    }, shapes
