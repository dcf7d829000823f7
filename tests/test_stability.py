"""Stability taxonomy and the largest stable step, on the canonical stiff case."""

from __future__ import annotations

import math

import numpy as np
import pytest

from validation.cli import BUNDLED_SCENARIOS
from validation.jobs.stability_search import BISECTION_RATIO, largest_stable_dt, stability_limit
from validation.measure.runner import run_engine
from validation.measure.stability import KINDS, StabilityChecks
from validation.measure.states import Trajectory
from validation.scenario import Scenario, load_scenario
from validation.scenario.compiled import compile_scene
from validation.scenario.engine_spec import parse_engine_spec

STIFFNESS, MASS = 1.0e6, 1.0
OMEGA = math.sqrt(STIFFNESS / MASS)


def oscillator(dt: float = 1e-3, duration: float = 2.0) -> Scenario:
    """An undamped k = 1e6 N/m oscillator (ω = 1000 rad/s), released 1 cm out, no gravity."""
    return Scenario.model_validate(
        {
            "name": "stiff_oscillator",
            "dt": dt,
            "duration": duration,
            "gravity": [0, 0, 0],
            "bodies": [
                {
                    "name": "m",
                    "shape": {"type": "sphere", "radius": 0.01},
                    "mass": MASS,
                    "position": [0.01, 0, 0],
                }
            ],
            "springs": [{"a": "m", "b": "world", "stiffness": STIFFNESS, "rest_length": 0.0}],
        }
    )


def test_bisection_finds_the_semi_implicit_limit_two_over_omega():
    """Semi-implicit Euler is stable exactly while ω·dt < 2: the bracket must hold 2/ω and be
    one bisection step wide."""
    limit = stability_limit(oscillator(), parse_engine_spec("mini"))
    exact = 2.0 / OMEGA
    assert limit.stable_dt is not None and limit.unstable_dt is not None, limit
    assert limit.stable_dt <= exact * (1 + 1e-3) and limit.unstable_dt >= exact * (1 - 1e-3), limit
    assert limit.unstable_dt / limit.stable_dt <= BISECTION_RATIO, limit
    assert "unstable above dt" in limit.sentence(), limit.sentence()


def test_explicit_euler_is_unstable_at_every_dt_tried():
    limit = stability_limit(oscillator(), parse_engine_spec("mini(integrator=explicit_euler)"))
    assert limit.stable_dt is None, limit
    assert limit.unstable_dt <= oscillator().dt / 16 * (1 + 1e-9), limit
    assert limit.reason.split(":")[0] in ("energy_blow_up", "non_finite", "speed_limit"), (
        limit.reason
    )


def test_bracketing_and_bisection_on_a_known_threshold():
    calls = []

    def threshold(dt: float) -> tuple[bool, str]:
        calls.append(dt)
        return dt < 0.0123, "above"

    stable, unstable, reason = largest_stable_dt(threshold, 1e-3, 1e-6, 1.0)
    assert (
        stable < 0.0123 <= unstable and unstable / stable <= BISECTION_RATIO and reason == "above"
    )
    assert len(calls) < 20, calls


def test_checks_name_each_kind_at_the_first_failing_state():
    scene = compile_scene(oscillator())

    def states(pos=(0.01, 0, 0), quat=(1.0, 0, 0, 0), vel=(0, 0, 0)) -> Trajectory:
        """Two states: the oscillator at rest, then the given one."""
        rows = [((0.01, 0, 0), (1.0, 0, 0, 0), (0, 0, 0)), (pos, quat, vel)]
        return Trajectory(
            np.array([0.0, 0.5]),
            np.array([[r[0]] for r in rows], float),
            np.array([[r[1]] for r in rows], float),
            np.array([[r[2]] for r in rows], float),
            np.zeros((2, 1, 3)),
        )

    def first(batch, deepest=None, radius=None):
        found = StabilityChecks(scene).first_failure(batch, deepest, radius)
        return found if found is None else (found[0], found[1].split(":")[0])

    assert first(states()) is None
    assert first(states(pos=(np.nan, 0, 0))) == (1, "non_finite")
    assert first(states(quat=(1.1, 0, 0, 0))) == (1, "quaternion_drift")
    assert first(states(vel=(1.0e9, 0, 0))) == (1, "energy_blow_up")  # energy judged before speed
    overlap = np.array([0.0, 0.05]), np.array([np.inf, 0.01])
    assert first(states(), *overlap) == (1, "deep_penetration")
    assert first(states(), np.array([0.0, 0.001]), np.array([np.inf, 0.01])) is None


EXPLODING_DT = 5e-3
"""s: ω·dt = 5 on the k = 1e6 N/m oscillator, beyond semi-implicit Euler's limit of 2 (the
integrator of all three engines here), so the amplitude grows ~23x per step."""

EXPLOSION_KIND = {"mini": "speed_limit", "mujoco": "speed_limit", "pybullet": "speed_limit"}
"""What each engine's explosion trips first: the speed passes 100x the scene's speed scale
(1.1e3 m/s) at the second step (t = 0.01 s), before the energy passes a million times its
scale and long before anything overflows (measured: 1.15e3 m/s in all three)."""


@pytest.mark.parametrize("engine", sorted(EXPLOSION_KIND))
def test_an_exploding_oscillator_is_unstable_in_every_engine(engine):
    """The run stops at the first failed check, its status is ``unstable`` and the message
    starts with the kind (one of ``KINDS``)."""
    scene = oscillator(dt=EXPLODING_DT, duration=1.0)
    run = run_engine(compile_scene(scene), parse_engine_spec(engine))
    kind = run.message.split(":")[0]
    assert run.status == "unstable", (run.status, run.message)
    assert kind in KINDS and kind == EXPLOSION_KIND[engine], run.message
    recorded = run.recording.trajectory.t
    assert recorded[-1] < scene.duration / 10, f"the run went on to t = {recorded[-1]} s"


def test_mujoco_adapter_reads_its_own_instability_warning():
    """ω·dt = 5: MuJoCo's Euler explodes, finds a huge qacc and resets; the adapter reads it."""
    from validation.engines.registry import create_adapter

    adapter = create_adapter(parse_engine_spec("mujoco"))
    adapter.load(compile_scene(oscillator(dt=EXPLODING_DT, duration=1.0)))
    adapter.advance(200)
    warnings = adapter.instability_warnings()
    adapter.close()
    assert any(w.startswith("MuJoCo mjWARN_BADQACC x") for w in warnings), warnings


def reset_by_mujoco() -> Scenario:
    """k = 2e15 N/m from its rest length at 0.1 m/s, dt = 1e-4: after one step the spring's
    qacc is 2e15·1e-5 = 2e10 m/s², beyond MuJoCo's 1e10 bound, so MuJoCo resets the state to
    the model's (at rest at the start) and goes on quietly. The stored energy after that one
    step is 1e5 J, below the energy blow-up bound, so only MuJoCo's warning tells."""
    return Scenario.model_validate(
        {
            **oscillator(dt=1e-4, duration=0.01).model_dump(),
            "springs": [{"a": "m", "b": "world", "stiffness": 2.0e15}],
            "bodies": [
                {
                    "name": "m",
                    "shape": {"type": "sphere", "radius": 0.01},
                    "mass": MASS,
                    "position": [0.01, 0, 0],
                    "velocity": [0.1, 0, 0],
                }
            ],
        }
    )


def test_a_state_mujoco_reset_is_an_engine_warning():
    """The state MuJoCo leaves looks fine (at rest, bounded): the run's only sign of the
    breakdown is MuJoCo's warning, which makes the run ``unstable`` with ``engine_warning``."""
    run = run_engine(compile_scene(reset_by_mujoco()), parse_engine_spec("mujoco"))
    last = run.recording.trajectory
    assert np.abs(last.pos[-1]).max() < 1.0 and np.abs(last.vel[-1]).max() < 1.0, last.pos[-1]
    assert run.status == "unstable", (run.status, run.message)
    assert run.message.startswith("engine_warning: MuJoCo mjWARN_BADQACC x"), run.message


def test_a_stable_spring_with_a_large_stored_energy_is_not_flagged():
    """15 cm out on k = 1e6 N/m is 11 kJ released at 150 m/s: stable at ω·dt = 0.1."""
    scene = Scenario.model_validate(
        {
            **oscillator(dt=1e-4, duration=0.05).model_dump(),
            "bodies": [
                {
                    "name": "m",
                    "shape": {"type": "sphere", "radius": 0.01},
                    "mass": 1.0,
                    "position": [0.15, 0, 0],
                }
            ],
        }
    )
    run = run_engine(compile_scene(scene), parse_engine_spec("mini"), 10)
    assert run.status == "ok", run.message


def test_a_model_mismatch_is_reported_as_not_run(monkeypatch):
    from validation.engines.mujoco import mjcf as mujoco_engine

    right = mujoco_engine.body_inertia
    monkeypatch.setattr(mujoco_engine, "body_inertia", lambda body: right(body) * 1.01)
    limit = stability_limit(oscillator(duration=0.1), parse_engine_spec("mujoco"))
    assert limit.stable_dt is None and limit.unstable_dt is None, limit
    assert "was not run" in limit.sentence() and "model_mismatch" in limit.reason


SYMPLECTIC_LIMIT = 2.0 / 1000.0
"""s: semi-implicit Euler on ω = 1000 rad/s is stable for ω·dt < 2 (its amplification matrix
has unit eigenvalues up to there)."""

RK4_LIMIT = 2.0 * np.sqrt(2.0) / 1000.0
"""s: RK4's stability interval on the imaginary axis ends at ω·dt = 2√2 (|R(iωdt)| = 1)."""

SYMPLECTIC_BAND, RK4_BAND = 0.01, 0.02
"""Relative: how close the bisection must come to each limit."""

LIBRARY_OSCILLATOR = BUNDLED_SCENARIOS / "stiff" / "stiff_spring_oscillator.yaml"
DURATIONS = (0.2, 2.0)
"""s: the bundled oscillator's own duration, and ten times it (the limit must not move)."""


@pytest.mark.parametrize("duration", DURATIONS)
@pytest.mark.parametrize(
    ("engine", "limit", "band"),
    [("mini", SYMPLECTIC_LIMIT, SYMPLECTIC_BAND), ("mujoco(integrator=RK4)", RK4_LIMIT, RK4_BAND)],
    ids=["symplectic_euler", "rk4"],
)
def test_the_stability_limit_does_not_depend_on_the_horizon(engine, limit, band, duration):
    """Growth of the energy error's envelope, not only a blow-up within the run: RK4 was
    reported stable up to 2.93e-3 s on the 0.2 s scene (3.5 % above its limit)."""
    scenario = load_scenario(LIBRARY_OSCILLATOR)
    scenario = Scenario.model_validate(
        {**scenario.model_dump(), "duration": duration, "source": scenario.source}
    )
    found = stability_limit(scenario, parse_engine_spec(engine))
    assert found.stable_dt is not None and found.unstable_dt is not None, found.sentence()
    assert found.stable_dt <= limit * (1 + band) and found.unstable_dt >= limit * (1 - band), (
        found.sentence(),
        limit,
    )
