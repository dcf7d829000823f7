"""The Rapier adapter, measured: boundary conventions (frames, quaternion order, body order),
the parity gate at float32, free flight against its closed form, restitution and the combine
rules, pair overrides, stepping, provenance (docs/engines-rapier.md for every number), and
the one line a user gets when rapier3d is not installed (that part runs without it)."""

from __future__ import annotations

import importlib.util
from pathlib import Path

import numpy as np
import pytest

from validation.engines.parity import PRECISION_TOLERANCE, compare
from validation.engines.reference import reference_report
from validation.reference.rotation import quat_multiply
from validation.scenario import Scenario, load_scenario, scenario_files
from validation.scenario.compiled import compile_scene
from validation.scenario.engine_spec import parse_engine_spec

RAPIER_MISSING = importlib.util.find_spec("rapier3d") is None
needs_rapier = pytest.mark.skipif(
    RAPIER_MISSING, reason='rapier3d is not installed (pip install "physval[rapier]")'
)

F32_EPSILON = float(np.finfo(np.float32).eps)
"""1.19e-7: Rapier's bindings hold every number in float32."""

F32_ROUND_OFF = 4 * F32_EPSILON
"""Relative: a value read back straight after it was set (a pose, a velocity) is its float32
rounding, and a quaternion or rotated vector a few such roundings (4 epsilons)."""

GRAVITY = 9.81
"""m/s², the scenes' |g|."""

SUBSTEPS = 4
"""Rapier's default ``num_solver_iterations``: each step is 4 symplectic Euler substeps of
dt/4 (engines-rapier.md 3)."""

FREE_FLIGHT_STEPS = 1000


def f32_accumulation(largest: float, additions: int) -> float:
    """The worst float32 drift of a coordinate that ``additions`` additions moved, never above
    ``largest`` in size: half an ulp per addition. A constant increment rounds the same way
    every time, so the bound is reached (measured: a body at 1 m/s drifts 2e-4 m in 2000
    substeps at |x| ≈ 3 m, the bound 2.4e-4 m)."""
    return additions * float(np.spacing(np.float32(largest))) / 2


RESTITUTION_TOLERANCE = 1e-6
"""Relative error of e. Measured: v+ = -e·v- to float32 rounding (|Δe| <= 6e-8) at every drop
height from 0.1 mm to 3 m; 1e-6 is 8 float32 epsilons."""

IMPULSE_JUMP = 0.05
"""m/s. A step whose velocity change differs from gravity's g·dt (0.0098 m/s at dt = 1e-3) by
more than this holds a contact impulse."""

SPIN_STEPS = 500
SPIN_TOLERANCE = 5e-5
"""Absolute, quaternion components. An isotropic body keeps a constant world ω, so
q(t) = exp(ω t / 2) ⊗ q0 exactly; Rapier integrates the rotation in float32: measured 1.4e-5
after 500 steps at |ω| = 3.7 rad/s with the gyroscopic term off (on, Rapier's gyroscopic
step moves an isotropic body's ω by 5e-4 rad/s in those 500 steps, engines-rapier.md 4,
which is the engine's and not the boundary's); a swapped quaternion order or a body-frame ω
is off by O(1)."""


def scene(**fields) -> Scenario:
    return Scenario.model_validate({"dt": 1e-3, "duration": 1.0, **fields})


def sphere(name="ball", **fields) -> dict:
    return {"name": name, "shape": {"type": "sphere", "radius": 0.1}, "mass": 1.0, **fields}


def adapter_for(text: str, scenario: Scenario):
    from validation.engines.rapier.adapter import RapierAdapter

    adapter = RapierAdapter(parse_engine_spec(text))
    adapter.load(compile_scene(scenario))
    return adapter


PROFILES = ("rapier", "rapier(profile=defaults)")

# --- 1. conventions -------------------------------------------------------------------------

TILTED = np.array([0.8, 0.3, -0.4, 0.33]) / np.linalg.norm([0.8, 0.3, -0.4, 0.33])
FULL_INERTIA = [[0.3, 0.02, -0.01], [0.02, 0.25, 0.03], [-0.01, 0.03, 0.1]]


def spinning_box(name="box", position=(1.0, -2.0, 3.0)) -> dict:
    return {
        "name": name,
        "shape": {"type": "box", "half_extents": [0.3, 0.2, 0.1]},
        "mass": 2.0,
        "inertia": FULL_INERTIA,
        "position": list(position),
        "orientation": TILTED.tolist(),
        "velocity": [0.5, -0.2, 0.3],
        "angular_velocity": [1.0, 2.0, -3.0],
    }


@needs_rapier
def test_observe_returns_every_body_in_scene_order_with_its_own_frame():
    """Three bodies, one with a full inertia (a rotated principal frame) and one fixed: each
    reads back its scene pose and velocities, quaternion w x y z, fixed body at rest."""
    scenario = scene(
        gravity=[0.0, 0.0, 0.0],
        bodies=[
            spinning_box(),
            sphere("post", position=[0.0, 5.0, 0.5], fixed=True),
            sphere("ball", position=[-3.0, 0.0, 1.0], velocity=[0.0, 1.0, 0.0]),
        ],
    )
    adapter = adapter_for("rapier", scenario)
    try:
        start = adapter.observe()
    finally:
        adapter.close()
    for k, body in enumerate(scenario.bodies):
        quat = np.asarray(body.orientation) * np.sign(np.dot(start.quat[k], body.orientation))
        errors = {
            "pos": np.abs(start.pos[k] - body.position).max()
            / max(1.0, np.abs(body.position).max()),
            "quat": np.abs(start.quat[k] - quat).max(),
            "vel": np.abs(start.vel[k] - body.velocity).max(),
            "ang_vel": np.abs(start.ang_vel[k] - body.angular_velocity).max() / 3.0,
        }
        assert max(errors.values()) <= F32_ROUND_OFF, (body.name, errors)


def axis_angle_quat(vector: np.ndarray) -> np.ndarray:
    """(4,) w x y z of the rotation by |vector| rad about vector."""
    angle = float(np.linalg.norm(vector))
    return np.concatenate([[np.cos(angle / 2)], np.sin(angle / 2) * vector / angle])


@needs_rapier
def test_a_spinning_translating_body_reads_back_its_closed_form_rotation():
    """An isotropic sphere, tilted, spinning about a world axis and translating: after n steps
    q = exp(ω t/2) ⊗ q0 (world ω) and x = x0 + v t, read through ``observe`` and through
    ``advance_observed`` alike. Gyroscopic term off: the boundary, not Rapier's gyroscopic
    step (``SPIN_TOLERANCE``)."""
    omega = np.array([1.0, -2.0, 3.0])
    velocity = np.array([0.5, -0.2, 0.3])
    scenario = scene(
        gravity=[0.0, 0.0, 0.0],
        bodies=[
            sphere(
                orientation=TILTED.tolist(),
                angular_velocity=omega.tolist(),
                velocity=velocity.tolist(),
                position=[1.0, 2.0, 3.0],
            )
        ],
    )
    adapter = adapter_for("rapier(gyroscopic=off)", scenario)
    try:
        observed = adapter.advance_observed(SPIN_STEPS)
        last = adapter.observe()
    finally:
        adapter.close()
    t = SPIN_STEPS * scenario.dt
    expected = quat_multiply(axis_angle_quat(omega * t)[None], TILTED[None])[0]
    got = last.quat[0] * np.sign(np.dot(last.quat[0], expected))
    assert np.abs(got - expected).max() <= SPIN_TOLERANCE, (got.tolist(), expected.tolist())
    assert np.array_equal(observed.quat[-1, 0], last.quat[0]), "advance_observed != observe"
    position = np.array([1.0, 2.0, 3.0]) + velocity * t
    bound = f32_accumulation(np.abs(position).max(), SPIN_STEPS * SUBSTEPS)
    assert np.abs(last.pos[0] - position).max() <= bound, (last.pos[0], bound)
    assert np.abs(last.ang_vel[0] - omega).max() <= F32_ROUND_OFF * 3, last.ang_vel[0]


@needs_rapier
def test_advance_n_equals_n_single_steps_and_a_rerun_is_bit_identical():
    scenario = scene(ground={"restitution": 0.5}, bodies=[spinning_box(position=(0, 0, 0.5))])
    runs = []
    for stepping in ("once", "singly", "once"):
        adapter = adapter_for("rapier", scenario)
        try:
            if stepping == "once":
                adapter.advance(300)
            else:
                for _ in range(300):
                    adapter.advance(1)
                    adapter.observe()
            runs.append(adapter.observe())
        finally:
            adapter.close()
    for field in ("pos", "quat", "vel", "ang_vel"):
        assert np.array_equal(getattr(runs[0], field), getattr(runs[1], field)), field
        assert np.array_equal(getattr(runs[0], field), getattr(runs[2], field)), field


# --- 2. parity ------------------------------------------------------------------------------

BUNDLED = scenario_files([Path(__file__).resolve().parent.parent / "scenarios"])


def mixed_scene() -> Scenario:
    """Every shape, a full inertia, a fixed body, springs, a constant load, a tilted ground."""
    return scene(
        bodies=[
            spinning_box(),
            {
                "name": "capsule",
                "shape": {"type": "capsule", "radius": 0.1, "half_length": 0.2},
                "mass": 1.5,
                "position": [0.0, 0.0, 1.0],
                "angular_velocity": [0.0, 1.0, 0.0],
                "force": [1.0, 0.0, 0.0],
            },
            sphere("post", position=[0.0, 1.0, 0.5], fixed=True),
        ],
        springs=[
            {"a": "box", "b": "capsule", "anchor_a": [0.1, 0, 0], "stiffness": 100.0},
            {"a": "capsule", "b": "world", "anchor_b": [0, 0, 3], "stiffness": 50.0},
        ],
        ground={"restitution": 0.2, "normal": [0.1, 0.0, 1.0], "point": [0.0, 0.0, -1.0]},
    )


FLOAT32_GATE_FINDINGS = {
    "spring_chain_between_steps": {"energy"},
    "stiff_spring_chain": {"energy"},
}
"""Library scenes whose initial state float32 cannot hold to the float32 gate's 1e-6: springs
of 1e6 N/m stretched 1 mm (0.5 J) or 0.1 mm (5 mJ), whose stretch moves by the float32
rounding of positions near 0.2 m (up to 7e-9 m), 7e-6 and 7.9e-6 of the energy (measured).
The gate reports them as ``model_mismatch``; a scene that leaves this list or joins it fails."""


@needs_rapier
@pytest.mark.parametrize("text", PROFILES)
@pytest.mark.parametrize(
    "source", ["mixed", *BUNDLED], ids=lambda p: p if p == "mixed" else f"{p.parent.name}/{p.stem}"
)
def test_parity_gate_passes_at_float32(source, text):
    """Every library scene but ``FLOAT32_GATE_FINDINGS``, whose mismatches are exactly those."""
    scenario = mixed_scene() if source == "mixed" else load_scenario(source)
    adapter = adapter_for(text, scenario)
    try:
        mismatches = compare(
            adapter.model_report(),
            reference_report(compile_scene(scenario)),
            PRECISION_TOLERANCE[adapter.precision],
        )
    finally:
        adapter.close()
    expected = FLOAT32_GATE_FINDINGS.get(getattr(source, "stem", source), set())
    assert {m.quantity for m in mismatches} == expected, [str(m) for m in mismatches]


@needs_rapier
def test_parity_gate_names_a_wrong_inertia(monkeypatch):
    from validation.engines.rapier.adapter import RapierAdapter

    right = RapierAdapter._inertia
    monkeypatch.setattr(RapierAdapter, "_inertia", lambda self, k: 1.01 * right(self, k))
    scenario = mixed_scene()
    adapter = adapter_for("rapier", scenario)
    try:
        mismatches = compare(
            adapter.model_report(),
            reference_report(compile_scene(scenario)),
            PRECISION_TOLERANCE["float32"],
        )
    finally:
        adapter.close()
    assert {m.quantity for m in mismatches} >= {"inertia_world"}, [str(m) for m in mismatches]


# --- 3. free flight -------------------------------------------------------------------------


@needs_rapier
@pytest.mark.parametrize("text", PROFILES)
def test_free_flight_is_symplectic_euler_in_substeps(text):
    """z(t) = z0 + vz t - g t²/2 - g t (dt/k)/2 after n steps of k substeps of v += g dt/k;
    x += v dt/k; horizontal velocity exactly constant (momentum conserved). The substeps'
    term g t (dt/k)/2 is 1.2 mm at t = 1 s; one full step of dt would give 4.9 mm, explicit
    Euler -4.9 mm: both far outside float32's accumulation bound (0.48 mm below 2.3 m)."""
    scenario = scene(bodies=[sphere(position=[0.0, 0.0, 1.0], velocity=[3.0, 0.0, 5.0])])
    dt = scenario.dt
    adapter = adapter_for(text, scenario)
    try:
        adapter.advance(FREE_FLIGHT_STEPS)
        state = adapter.observe()
    finally:
        adapter.close()
    t = FREE_FLIGHT_STEPS * dt
    z = 1.0 + 5.0 * t - 0.5 * GRAVITY * t**2 - GRAVITY * t * (dt / SUBSTEPS) / 2
    top = 1.0 + 5.0**2 / (2 * GRAVITY)
    bound = f32_accumulation(top, FREE_FLIGHT_STEPS * SUBSTEPS)
    assert abs(state.pos[0, 2] - z) <= bound, (
        f"z {state.pos[0, 2]:.9g} m, closed form {z:.9g} m, float32 bound {bound:.3g} m"
    )
    assert state.vel[0, 0] == pytest.approx(3.0, abs=0.0), state.vel[0]


# --- 4. restitution -------------------------------------------------------------------------


def drop(text: str, height: float, ball: dict, **fields) -> tuple[float, float]:
    """(approach speed, e) of the first impact of a frictionless sphere dropped with its COM
    at ``height`` onto the ground."""
    fields.setdefault("ground", {})
    scenario = scene(bodies=[sphere(position=[0, 0, height], **ball)], **fields)
    steps = round(1.0 / scenario.dt)
    adapter = adapter_for(text, scenario)
    try:
        vz = adapter.advance_observed(steps).vel[:, 0, 2]
    finally:
        adapter.close()
    jump = int(np.flatnonzero(np.abs(np.diff(vz) + GRAVITY * scenario.dt) > IMPULSE_JUMP)[0]) + 1
    return float(-vz[jump - 1]), float(vz[jump] / -vz[jump - 1])


@needs_rapier
@pytest.mark.parametrize("e", [0.5, 1.0])
@pytest.mark.parametrize("height", [0.15, 1.0])
def test_matched_profile_bounces_with_the_scene_e(e, height):
    """Ball e, ground 0: the scene's pair value is max(e, 0) = e (CoefficientCombineRule.MAX)."""
    speed, got = drop("rapier", height, {"restitution": e})
    assert abs(got - e) <= RESTITUTION_TOLERANCE * e, f"e = {got:.9g} at {speed:.4g} m/s"


@needs_rapier
def test_defaults_profile_averages_the_two_restitutions():
    """Rapier's own AVERAGE rule: ball 0.5, ground 0 -> 0.25, not the scene's max 0.5."""
    _, got = drop("rapier(profile=defaults)", 1.0, {"restitution": 0.5})
    assert abs(got - 0.25) <= RESTITUTION_TOLERANCE, f"e = {got:.9g}"


@needs_rapier
def test_a_pair_override_is_set_on_the_contact():
    """Ball and ground both e = 0, the scene's ``pairs:`` says 0.8: the hook sets it."""
    _, got = drop("rapier", 1.0, {}, pairs=[{"a": "ball", "b": "ground", "restitution": 0.8}])
    assert abs(got - 0.8) <= RESTITUTION_TOLERANCE, f"e = {got:.9g}"


# --- 5. provenance and the runner ------------------------------------------------------------


@needs_rapier
def test_provenance_says_float32_and_records_the_options():
    adapter = adapter_for("rapier(gyroscopic=off, solver_iterations=2)", mixed_scene())
    try:
        provenance = adapter.provenance()
        parameters = adapter.world.integration_parameters
        body = adapter.world.rigid_bodies[adapter.handles[0]]
        assert parameters.num_solver_iterations == 2
        assert body.gyroscopic_forces_enabled is False
    finally:
        adapter.close()
    assert provenance.settings["precision"] == "float32"
    assert provenance.settings["spec.gyroscopic"] == "off"
    assert provenance.settings["integration_parameters"]["num_solver_iterations"] == 2
    assert any(note.startswith("float32 engine") for note in provenance.notes), provenance.notes
    assert any(note.startswith("springs:") for note in provenance.notes), provenance.notes


@needs_rapier
def test_a_library_scene_runs_through_the_runner():
    from validation.measure.runner import run_engine

    scenario = load_scenario(
        Path(__file__).resolve().parent.parent / "scenarios/formulas/projectile.yaml"
    )
    run = run_engine(compile_scene(scenario), parse_engine_spec("rapier"))
    assert run.status == "ok", run.message
    assert run.provenance.engine == "rapier"
