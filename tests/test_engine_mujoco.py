"""The MuJoCo adapter: state conventions, the parity gate, integrators, restitution, springs.

Every test measures something the adapter could get wrong and prints the measured values
when it fails. Numbers quoted from engines.md are MuJoCo 4.0.0 measurements.
"""

from __future__ import annotations

import numpy as np
import pytest

from mini_engine.rotation import quat_to_matrix
from validation.cli import BUNDLED_SCENARIOS
from validation.engines.mujoco import mjcf as mujoco_engine
from validation.engines.parity import compare
from validation.engines.reference import reference_report
from validation.engines.registry import create_adapter
from validation.scenario import Scenario, load_scenario, scenario_files
from validation.scenario.compiled import compile_scene
from validation.scenario.engine_spec import parse_engine_spec

ROUNDOFF = 1e-12
"""Relative/absolute (SI units). A state written to qpos/qvel and read back passes through
R and Rᵀ (a few flops on numbers of order 1): anything above round-off is a convention bug."""

SAME_SCHEME = 1e-12
"""MuJoCo Euler and mini(gyroscopic=explicit) are the same scheme (explicit gyroscopic term,
semi-implicit velocity, exponential-map orientation); measured 5e-19 (quaternion) and
9e-16 rad/s (ω) apart after one step."""

FREE_FALL_TOLERANCE = 1e-9
"""m. Free fall closed forms (engines.md 1.6) hold to round-off: measured 1.3e-14 m after 1 s."""

RESTITUTION_TOLERANCE = 0.01
"""Absolute on e. engines.md 1.7: the damper calibration gives e within 1 % of the request;
measured here 0.49990–0.49999 (e = 0.5) and 0.99999 (e = 1)."""

MIN_IMPACT_SPEED = 0.3
"""m/s. Impacts slower than this are left out: gravity's g·dt during the contact step is then
over 3 % of the speed (the ratio v+/v- carries it), not restitution."""

PERIOD_TOLERANCE = 1e-4
"""Relative. Semi-implicit Euler lengthens an oscillator's period by ≈ (ω dt)²/24 = 8e-6 at
ω = 14 rad/s, dt = 1e-3; zero-crossing interpolation adds O(dt³)."""

ENERGY_PARITY = 1e-9
"""Relative, the parity gate's tolerance (validation.engines.parity.PARITY_TOLERANCE)."""

ROTATED_OFFSET_SPINNING = {
    "dt": 0.001,
    "duration": 0.01,
    "gravity": [0, 0, 0],
    "bodies": [
        {
            "name": "box",
            "shape": {"type": "box", "half_extents": [0.1, 0.2, 0.3]},
            "mass": 2.0,
            "inertia": [[0.3, 0.02, 0.0], [0.02, 0.25, 0.0], [0.0, 0.0, 0.1]],
            "position": [1.0, -2.0, 3.0],
            "orientation": [0.8775826, 0.4794255, 0.0, 0.0],  # 1 rad about x
            "velocity": [0.5, -0.25, 1.0],
            "angular_velocity": [1.0, 2.0, -3.0],  # not along a principal axis
        },
        {
            "name": "post",
            "shape": {"type": "sphere", "radius": 0.1},
            "mass": 1.0,
            "fixed": True,
            "position": [5, 5, 5],
        },
    ],
}

MIXED_SCENE = {
    "dt": 0.001,
    "duration": 0.01,
    "ground": {"restitution": 0.3, "friction": 0.5},
    "bodies": [
        {
            **ROTATED_OFFSET_SPINNING["bodies"][0],
            "restitution": 0.5,
            "friction": 0.2,
        },
        {
            "name": "capsule",
            "shape": {"type": "capsule", "radius": 0.1, "half_length": 0.2},
            "mass": 1.5,
            "position": [0, 0, 2],
            "orientation": [0.5, 0.5, 0.5, 0.5],
            "velocity": [1, 0, 0],
            "angular_velocity": [0, 3, 1],
        },
        {
            "name": "ball",
            "shape": {"type": "sphere", "radius": 0.05},
            "mass": 0.3,
            "position": [0.5, 0.5, 0.5],
        },
        ROTATED_OFFSET_SPINNING["bodies"][1],
    ],
    "springs": [
        {
            "a": "box",
            "b": "world",
            "anchor_a": [0.1, 0, 0],
            "anchor_b": [1, -2, 4],
            "stiffness": 100,
        },
        {"a": "box", "b": "capsule", "stiffness": 10, "damping": 0.1, "rest_length": 1.0},
        {"a": "ball", "b": "post", "anchor_b": [0, 0.1, 0], "stiffness": 5},
    ],
    "pairs": [{"a": "ball", "b": "ground", "restitution": 0.9}],
}
"""Every shape, a fixed body, all three spring kinds, friction and a pair override."""


def scenario_from(data: dict, **changes) -> Scenario:
    return Scenario.model_validate({"name": "test", **data, **changes})


def mujoco(data: dict | Scenario, spec: str = "mujoco"):
    adapter = create_adapter(parse_engine_spec(spec))
    adapter.load(compile_scene(data if isinstance(data, Scenario) else scenario_from(data)))
    return adapter


def sphere_drop(height: float, restitution: float, dt: float = 1e-3, **body) -> dict:
    return {
        "dt": dt,
        "duration": 1.0,
        "ground": {"restitution": restitution},
        "bodies": [
            {
                "name": "ball",
                "shape": {"type": "sphere", "radius": 0.1},
                "mass": 1.0,
                "position": [0, 0, height],
                "restitution": restitution,
                **body,
            }
        ],
    }


# --- 1. conventions -----------------------------------------------------------------------


def test_observe_returns_the_scenario_state_of_a_rotated_offset_spinning_body():
    scenario = scenario_from(ROTATED_OFFSET_SPINNING)
    snap = mujoco(scenario).observe()
    for i, body in enumerate(scenario.bodies):
        expected = {
            "pos": body.position,
            "vel": (0, 0, 0) if body.fixed else body.velocity,
            "ang_vel": (0, 0, 0) if body.fixed else body.angular_velocity,
        }
        for name, want in expected.items():
            got = getattr(snap, name)[i]
            assert np.allclose(got, want, rtol=ROUNDOFF, atol=ROUNDOFF), (body.name, name, got)
        sign = np.sign(np.dot(snap.quat[i], body.orientation))
        assert np.allclose(sign * snap.quat[i], body.orientation, atol=ROUNDOFF), snap.quat[i]
    assert snap.pos.shape == (2, 3) and snap.time == 0.0


def test_one_step_moves_by_v_dt_and_rotates_by_the_world_angular_velocity():
    scenario = scenario_from(ROTATED_OFFSET_SPINNING)
    engine = mujoco(scenario)
    mini = create_adapter(parse_engine_spec("mini(gyroscopic=explicit)"))
    mini.load(compile_scene(scenario))
    engine.advance(1)
    mini.advance(1)
    got, want = engine.observe(), mini.observe()
    box = scenario.bodies[0]
    moved = got.pos[0] - np.asarray(box.position)
    assert np.allclose(moved, np.asarray(box.velocity) * scenario.dt, atol=ROUNDOFF), moved
    quat_gap = min(np.abs(got.quat - want.quat).max(), np.abs(got.quat + want.quat).max())
    omega_gap = np.abs(got.ang_vel - want.ang_vel).max()
    assert quat_gap < SAME_SCHEME and omega_gap < SAME_SCHEME, (quat_gap, omega_gap)
    # and the rotation really is about the world ω (the body-frame reading would differ at O(1))
    turned = quat_to_matrix(got.quat[:1])[0] @ quat_to_matrix(np.array([box.orientation]))[0].T
    angle_axis = (
        np.array(
            [turned[2, 1] - turned[1, 2], turned[0, 2] - turned[2, 0], turned[1, 0] - turned[0, 1]]
        )
        / 2
    )
    expected = np.asarray(box.angular_velocity) * scenario.dt
    assert np.allclose(angle_axis, expected, rtol=0.0, atol=1e-2 * np.linalg.norm(expected)), (
        angle_axis,
        expected,
    )


# --- 2. parity gate -----------------------------------------------------------------------

LOCAL_SCENES = {"rotated_offset_spinning": ROTATED_OFFSET_SPINNING, "mixed": MIXED_SCENE}
BUNDLED = scenario_files([BUNDLED_SCENARIOS])


@pytest.mark.parametrize(
    "source",
    [*BUNDLED, *LOCAL_SCENES],
    ids=lambda s: f"{s.parent.name}/{s.stem}" if hasattr(s, "stem") else f"local/{s}",
)
def test_parity_gate_passes(source):
    scenario = (
        load_scenario(source) if hasattr(source, "stem") else scenario_from(LOCAL_SCENES[source])
    )
    for profile in ("matched", "defaults"):
        adapter = mujoco(scenario, f"mujoco(profile={profile})")
        mismatches = compare(adapter.model_report(), reference_report(compile_scene(scenario)))
        assert mismatches == [], (profile, [str(m) for m in mismatches])


def test_parity_gate_names_a_wrong_inertia(monkeypatch):
    scenario = scenario_from(MIXED_SCENE)
    right = mujoco_engine.body_inertia
    monkeypatch.setattr(
        mujoco_engine, "body_inertia", lambda body: right(body) * (1.0 + 1e-6)
    )  # a millionth: far below anything a plot would show
    mismatches = compare(mujoco(scenario).model_report(), reference_report(compile_scene(scenario)))
    quantities = {m.quantity for m in mismatches}
    assert "inertia_world" in quantities, [str(m) for m in mismatches]


def test_spring_energy_is_in_the_report_and_contacts_are_off_without_pairs():
    scene = {
        "dt": 1e-3,
        "duration": 1.0,
        "gravity": [0, 0, 0],
        "bodies": [{"name": "b", "shape": {"type": "sphere", "radius": 0.05}, "mass": 0.5}],
        "springs": [
            {"a": "b", "b": "world", "anchor_b": [0.1, 0, 0], "stiffness": 100, "rest_length": 0.0}
        ],
    }
    adapter = mujoco(scene)
    energy = adapter.model_report().energy
    spring = 0.5 * 100 * 0.1**2  # ½ k x², x = 0.1 m
    assert abs(energy - spring) <= ENERGY_PARITY * spring, (energy, spring)
    settings = adapter.provenance().settings
    assert "mjDSBL_CONTACT" in settings["disableflags_names"], settings["disableflags_names"]


def test_provenance_records_every_option_and_the_calibration():
    adapter = mujoco(sphere_drop(1.0, 0.5))
    record = adapter.provenance()
    wanted = {"timestep", "integrator", "solver", "iterations", "tolerance", "gravity", "cone"}
    wanted |= {"disableflags", "enableflags", "spec.profile", "spec.restitution"}
    assert wanted <= set(record.settings), wanted - set(record.settings)
    assert (
        record.settings["timestep"] == 1e-3 and record.settings["integrator_name"] == "mjINT_EULER"
    )
    assert record.version and any("calibration" in note for note in record.notes), record.notes


# --- 3. free fall -------------------------------------------------------------------------

FREE_FALL = {
    "dt": 2e-3,
    "duration": 1.0,
    "bodies": [
        {
            "name": "ball",
            "shape": {"type": "sphere", "radius": 0.1},
            "mass": 1.0,
            "position": [0, 0, 10],
            "velocity": [0.3, 0, 2],
        }
    ],
}

FREE_FALL_ERRORS = {
    "Euler": lambda g, t, dt: -g * t * dt / 2,  # engines.md 1.6: semi-implicit Euler
    "implicitfast": lambda g, t, dt: -g * t * dt / 2,  # the same for a free body (1.6)
    "RK4": lambda g, t, dt: 0.0,  # exact for constant gravity (1.6)
}


@pytest.mark.parametrize("integrator", FREE_FALL_ERRORS)
def test_free_fall_matches_the_closed_form_of_the_integrator(integrator):
    scenario = scenario_from(FREE_FALL)
    adapter = mujoco(scenario, f"mujoco(integrator={integrator})")
    adapter.advance(scenario.steps)
    snap = adapter.observe()
    t, g, z0, vz0 = snap.time, 9.81, 10.0, 2.0
    parabola = z0 + vz0 * t - 0.5 * g * t**2
    error = snap.pos[0, 2] - parabola
    expected = FREE_FALL_ERRORS[integrator](g, t, scenario.dt)
    assert abs(t - 1.0) < ROUNDOFF, t
    assert abs(error - expected) < FREE_FALL_TOLERANCE, (integrator, error, expected)
    assert abs(snap.pos[0, 0] - 0.3 * t) < FREE_FALL_TOLERANCE, snap.pos[0]


# --- 4. restitution -----------------------------------------------------------------------


def measured_restitutions(adapter, steps: int) -> list[tuple[float, float]]:
    """(impact speed m/s, e = v+/|v-|) per impact, from the vertical velocity every step."""
    vz = []
    for _ in range(steps):
        adapter.advance(1)
        vz.append(adapter.observe().vel[0, 2])
    vz = np.array(vz)
    jumps = np.flatnonzero(np.diff(vz) > 0.0)  # free flight only ever decreases vz
    impacts, start = [], None
    for k, j in enumerate(jumps):
        start = j if start is None else start
        if k + 1 == len(jumps) or jumps[k + 1] != j + 1:  # end of one contact interval
            before, after = vz[start], vz[j + 1]
            if -before > MIN_IMPACT_SPEED:
                impacts.append((-before, after / -before))
            start = None
    return impacts


@pytest.mark.parametrize("restitution", [0.5, 1.0])
@pytest.mark.parametrize("height", [0.5, 1.5])
def test_sphere_bounces_with_the_requested_restitution(restitution, height):
    adapter = mujoco(sphere_drop(height, restitution))
    impacts = measured_restitutions(adapter, steps=4000)  # 4 s: three bounces from 1.5 m at e = 1
    assert len(impacts) >= 3, impacts
    errors = [abs(e - restitution) for _, e in impacts[:4]]
    assert max(errors) < RESTITUTION_TOLERANCE, impacts[:4]


# --- 5. torque-free tumbling --------------------------------------------------------------

DZHANIBEKOV = {
    "dt": 1e-3,
    "duration": 10.0,
    "gravity": [0, 0, 0],
    "bodies": [
        {
            "name": "box",
            # half extents giving I = (0.016667, 0.033333, 0.043333) kg·m² at 1 kg (engines.md 1.8)
            "shape": {"type": "box", "half_extents": [0.3, 0.2, 0.1]},
            "mass": 1.0,
            "angular_velocity": [0.05, 10.0, 0.05],  # identity orientation: body = world
        }
    ],
}
EXPECTED_FLIPS = 3
"""engines.md 1.8: RK4 on Euler's equations at dt = 1e-5 flips 3 times in 10 s."""

SAMPLE_STEPS = 10
"""Observe every 10 ms: a flip takes ~0.3 s, so no sign change is missed."""


@pytest.mark.parametrize("integrator", ["Euler", "implicitfast", "RK4"])
def test_dzhanibekov_box_flips_three_times(integrator):
    scenario = scenario_from(DZHANIBEKOV)
    adapter = mujoco(scenario, f"mujoco(integrator={integrator})")
    body_y = []
    for _ in range(scenario.steps // SAMPLE_STEPS):
        adapter.advance(SAMPLE_STEPS)
        snap = adapter.observe()
        body_y.append((quat_to_matrix(snap.quat)[0].T @ snap.ang_vel[0])[1])
    flips = int(np.count_nonzero(np.diff(np.sign(body_y)) != 0))
    assert flips == EXPECTED_FLIPS, (integrator, flips)


# --- 6. spring ----------------------------------------------------------------------------


@pytest.mark.parametrize("integrator", ["Euler", "RK4"])
def test_spring_oscillates_with_the_closed_form_period(integrator):
    mass, stiffness, amplitude = 0.5, 100.0, 0.1
    scene = {
        "dt": 1e-3,
        "duration": 3.0,
        "gravity": [0, 0, 0],
        "bodies": [
            {
                "name": "bob",
                "shape": {"type": "sphere", "radius": 0.05},
                "mass": mass,
                "position": [amplitude, 0, 1],
            }
        ],
        "springs": [
            {
                "a": "bob",
                "b": "world",
                "anchor_b": [0, 0, 1],
                "stiffness": stiffness,
                "rest_length": 0.0,
            }
        ],
    }
    scenario = scenario_from(scene)
    adapter = mujoco(scenario, f"mujoco(integrator={integrator})")
    report = adapter.model_report()
    spring_energy = 0.5 * stiffness * amplitude**2
    assert abs(report.energy - spring_energy) <= ENERGY_PARITY * spring_energy, report.energy
    assert compare(report, reference_report(compile_scene(scenario))) == []
    x = []
    for _ in range(scenario.steps):
        adapter.advance(1)
        x.append(adapter.observe().pos[0, 0])
    x = np.array(x)
    t = scenario.dt * np.arange(1, len(x) + 1)
    up = np.flatnonzero((x[:-1] < 0) & (x[1:] >= 0))
    crossings = t[up] + scenario.dt * -x[up] / (x[up + 1] - x[up])
    periods = np.diff(crossings)
    expected = 2 * np.pi * np.sqrt(mass / stiffness)
    assert len(periods) >= 4, crossings
    worst = np.abs(periods / expected - 1).max()
    assert worst < PERIOD_TOLERANCE, (integrator, periods, expected)


def test_unused_gravity_and_contacts_are_switched_off():
    """A lone body in zero gravity: MuJoCo is told to skip both phases (pay only for what the
    scene uses); with a ground and gravity, neither flag is set."""

    def flags(data: dict) -> list[str]:
        adapter = create_adapter(parse_engine_spec("mujoco"))
        adapter.load(
            compile_scene(
                Scenario.model_validate({"name": "flags", "dt": 0.001, "duration": 0.01, **data})
            )
        )
        settings = adapter.provenance().settings
        adapter.close()
        return settings.get("option", settings)["disableflags_names"]

    ball = [{"name": "b", "shape": {"type": "sphere", "radius": 0.1}, "mass": 1.0}]
    lone = flags({"gravity": [0, 0, 0], "bodies": ball})
    assert {"mjDSBL_CONTACT", "mjDSBL_GRAVITY"} <= set(lone), lone
    grounded = flags({"ground": {}, "bodies": ball})
    assert not {"mjDSBL_CONTACT", "mjDSBL_GRAVITY"} & set(grounded), grounded


def exploding_oscillator() -> Scenario:
    """k = 1e6 N/m, 1 kg, dt = 5e-3 (ω·dt = 5): MuJoCo's Euler explodes within a few steps,
    finds a huge qacc, resets the state and warns (mjWARN_BADQACC)."""
    return Scenario.model_validate(
        {
            "name": "exploding_oscillator",
            "dt": 5e-3,
            "duration": 1.0,
            "gravity": [0, 0, 0],
            "bodies": [
                {
                    "name": "m",
                    "shape": {"type": "sphere", "radius": 0.01},
                    "mass": 1.0,
                    "position": [0.01, 0, 0],
                }
            ],
            "springs": [{"a": "m", "b": "world", "stiffness": 1.0e6, "rest_length": 0.0}],
        }
    )


def test_a_mujoco_warning_is_collected_and_leaves_no_log_in_the_working_folder(
    tmp_path, monkeypatch, capfd
):
    """Without a handler MuJoCo prints the warning and appends it to MUJOCO_LOG.TXT in the
    current directory; the adapter collects it instead and restores the previous handler."""
    import mujoco as mujoco_library

    monkeypatch.chdir(tmp_path)
    before = mujoco_library.get_mju_user_warning()
    adapter = mujoco(exploding_oscillator())
    adapter.advance(200)
    warnings = adapter.instability_warnings()
    adapter.close()
    assert any(w.startswith("MuJoCo mjWARN_BADQACC x") for w in warnings), warnings
    assert list(tmp_path.iterdir()) == [], sorted(p.name for p in tmp_path.iterdir())
    printed = capfd.readouterr()
    assert "WARNING" not in printed.out + printed.err, printed
    assert any("QACC" in w and "unstable" in w for w in warnings), warnings
    after = mujoco_library.get_mju_user_warning()
    assert after == before, (after, before)


def test_the_damper_names_its_friction_limit_wherever_a_pair_has_friction():
    """Issue-10 finding 7: no MuJoCo setting honours both e and friction in a one-step impact;
    the provenance of a frictional scene under the damper says so, with the measurements."""
    from validation.engines.mujoco.adapter import FRICTION_IN_IMPACTS

    scene = sphere_drop(0.5, 0.5, friction=0.3)
    scene["ground"]["friction"] = 0.3
    frictional = mujoco(scene)
    notes = frictional.provenance().notes
    frictional.close()
    assert FRICTION_IN_IMPACTS in notes, notes
    frictionless = mujoco(sphere_drop(0.5, 0.5))
    assert FRICTION_IN_IMPACTS not in frictionless.provenance().notes
    frictionless.close()
