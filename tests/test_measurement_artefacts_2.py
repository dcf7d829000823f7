"""Measurement artefacts, round 2 (issue 34, items 1-5): every number is the engine's.

Each test builds a small scene whose truth is known (or whose two versions must read alike)
and checks that the harness reads the engine's own motion: no interpolant across an impact,
no expectation past the last observed state, every step in a metric's maximum, and drift
scales that neither a boost nor a momentum cancelling to round-off can move.
"""

from __future__ import annotations

import math

import numpy as np
import pytest
from scene_rows import rows

from validation.engines.registry import create_adapter
from validation.measure.metrics import METRICS, Context
from validation.measure.recording import record
from validation.scenario import Scenario
from validation.scenario.checks import step_count
from validation.scenario.compiled import compile_scene
from validation.scenario.engine_spec import parse_engine_spec
from validation.scenario.load import check_scenario

G = 9.81
DT = 1.0e-3

ROUND_OFF = 1e-9
"""In the quantity's SI unit: what double-precision round-off leaves of a metre-sized scene
of up to 1e4 steps (about 1e-16 relative per step, with margin); every artefact below is
1e-3 or more."""


def _sphere(name: str, **extra) -> dict:
    return {"name": name, "shape": {"type": "sphere", "radius": 0.1}, "mass": 1.0, **extra}


def _recorded(data: dict, sample_every: int = 1, engine: str = "mini"):
    """The compiled scene and its recording in ``engine``, every ``sample_every``-th state kept."""
    scene = compile_scene(Scenario.model_validate(data))
    adapter = create_adapter(parse_engine_spec(engine))
    adapter.load(scene)
    try:
        return scene, record(adapter, scene, sample_every=sample_every)
    finally:
        adapter.close()


# --- 1. no interpolant across an impact -----------------------------------------------------

BOUNCE = {
    "name": "bounce_between_steps",
    "dt": DT,
    "duration": 0.4,
    "ground": {"restitution": 0.5, "friction": 0.0},
    "bodies": [{**_sphere("ball"), "position": [0.0, 0.0, 0.3]}],
}
"""A ball dropped 0.2 m onto the ground (e = 0.5): it lands at about 2 m/s, leaves at about
1 m/s; mini resolves the impact within one step, so its velocity jumps by about 3 m/s over
the step into the first touching state."""


def _energy(states, k: int) -> float:
    """The ball's kinetic + gravitational energy (J) at observed state ``k`` (m = 1 kg)."""
    return 0.5 * float(states.vel[k, 0] @ states.vel[k, 0]) + G * float(states.pos[k, 0, 2])


def _bounce_reads(offsets: dict[str, float]) -> tuple[dict, object, int]:
    """The rows of BOUNCE with velocity_at and energy_at read at the first touching state's
    time plus each of ``offsets`` (in steps), the observed states, and the first touching
    state's index."""
    _, recording = _recorded(BOUNCE)
    states = recording.trajectory
    touch = int(np.flatnonzero(states.t == recording.impacts[0].time_start)[0])
    expect = []
    for label, offset in offsets.items():
        time = float(states.t[touch] + offset * DT)
        expect += [
            {
                "kind": "velocity_at",
                "name": f"v_{label}",
                "body": "ball",
                "time": time,
                "value": [0.0, 0.0, 0.0],
            },
            {"kind": "energy_at", "name": f"e_{label}", "body": "ball", "time": time, "value": 0.0},
        ]
    return rows({**BOUNCE, "expect": expect}, "mini"), states, touch


def test_a_value_between_steps_is_never_interpolated_across_an_impact():
    """mini finds the ball touching at state k and resolves the overlap over the step out of
    it (v jumps between k and k + 1; the ball is apart from k + 2): between k and k + 1, and
    between k + 1 and k + 2 (a step out of a change of contact), the value is the observed
    one at the step's end, and the message says so; between k + 3 and k + 4 the interpolant
    takes only the states from k + 3 on, exact for mini's free flight (v linear, E quadratic
    in t). The cubic through the four states around the time, some before the impact, read a
    fraction of the 3 m/s jump."""
    found, states, touch = _bounce_reads({"jump": 0.5, "leaving": 1.5, "flight": 3.5})
    assert touching(states, touch + 1) and not touching(states, touch + 2), "the scene's premise"
    for label, read in (("jump", touch + 1), ("leaving", touch + 2)):
        velocity, energy = found[f"v_{label}"], found[f"e_{label}"]
        assert np.allclose(measured(velocity), states.vel[read, 0], atol=ROUND_OFF, rtol=0.0), (
            velocity
        )
        assert abs(energy["value"] - _energy(states, read)) <= ROUND_OFF, energy
        assert "observed step after the contact" in velocity["message"], velocity["message"]
    first = touch + 3  # the first state whose steps on both sides are free flight
    mid_flight = 0.5 * (states.vel[first, 0] + states.vel[first + 1, 0])
    velocity, energy = found["v_flight"], found["e_flight"]
    assert np.allclose(measured(velocity), mid_flight, atol=ROUND_OFF, rtol=0.0), velocity
    nodes = [_energy(states, k) for k in (first, first + 1, first + 2)]
    quadratic = 0.375 * nodes[0] + 0.75 * nodes[1] - 0.125 * nodes[2]  # Lagrange at mid-step
    assert abs(energy["value"] - quadratic) <= ROUND_OFF, (energy, quadratic)
    assert "not across a contact change" in velocity["message"], velocity["message"]


def measured(row: dict) -> np.ndarray:
    """(3,) a vector row's signed error, here the measured vector (the expectation is 0)."""
    return np.array([row[f"error_{axis}"] for axis in "xyz"])


def touching(states, k: int) -> bool:
    """Whether the ball (radius 0.1 m) touches the ground at observed state ``k``."""
    return bool(states.pos[k, 0, 2] - 0.1 <= 1e-6)


def test_values_away_from_a_contact_are_still_interpolated_through_four_states():
    """Far from the impact (20 steps before it) the cubic through four states is kept."""
    found, _, _ = _bounce_reads({"before": -20.5})
    assert "interpolated between observations)" in found["v_before"]["message"]


# --- 2. a duration that is not a whole number of steps ----------------------------------------


def test_a_duration_that_is_not_a_whole_number_of_steps_is_refused_with_the_numbers(tmp_path):
    """0.6004 s at 1 ms would run 600 steps and end at 0.6 s: an expectation at 0.6003 s was
    accepted and then failed every engine with error inf."""
    path = tmp_path / "short.yaml"
    path.write_text(
        "name: short\ndt: 0.001\nduration: 0.6004\nbodies:\n"
        "  - {name: ball, shape: {type: sphere, radius: 0.1}, mass: 1.0}\n"
        "expect:\n  - {kind: position_at, body: ball, time: 0.6003, value: [0, 0, 0]}\n"
    )
    scenario, problems = check_scenario(path)
    errors = [p for p in problems if not p.warning]
    assert scenario is None and errors, problems
    text = " ".join(str(p) for p in errors)
    assert "600.4 steps" in text and "600 steps end at 0.6 s" in text, text
    assert "601 at 0.601 s" in text, text


@pytest.mark.parametrize(("duration", "dt"), [(0.6, 1e-3), (50.0, 1e-5), (0.7, 0.1), (1.0, 1e-3)])
def test_decimal_durations_of_whole_steps_are_accepted(duration, dt):
    """Decimal round-off (0.6 / 0.001 = 599.9999999999999) is not a fraction of a step."""
    scenario = Scenario.model_validate(
        {"name": "whole", "dt": dt, "duration": duration, "bodies": [_sphere("ball")]}
    )
    assert list(step_count(scenario)) == []


# --- 3. maxima over every step, whatever the series keeps ------------------------------------


def _spring_pair(duration: float, velocity: float = 0.0, gravity=(0.0, 0.0, 0.0)) -> dict:
    """Two 1 kg spheres on a stiff spring (k = 4000 N/m, 20 mm stretched), stepped at 10 ms
    (ω·dt = 0.9: semi-implicit Euler's energy swings by tens of percent each period), the
    pair moving at ``velocity`` m/s along y."""
    return {
        "name": "spring_pair",
        "dt": 0.01,
        "duration": duration,
        "gravity": list(gravity),
        "bodies": [
            {**_sphere("a"), "position": [0.0, 0.0, 0.0], "velocity": [0.0, velocity, 0.0]},
            {**_sphere("b"), "position": [0.52, 0.0, 0.0], "velocity": [0.0, velocity, 0.0]},
        ],
        "springs": [{"a": "a", "b": "b", "stiffness": 4000.0, "rest_length": 0.5}],
    }


ALIASED_STIFFNESS = 0.5 * (2.0 * math.sin(math.pi / 20.0) / 0.01) ** 2
"""N/m. Semi-implicit Euler turns a spring of reduced mass μ by θ per step with
cos θ = 1 - k dt²/(2μ): this k (μ = 0.5 kg, dt = 10 ms) makes θ = 2π/20 exactly, so the
pair's energy, which swings twice per period, repeats every 10 steps."""


def test_a_drift_is_the_maximum_over_every_step_whatever_the_series_keeps():
    """The same run kept whole and kept every 10th state reads the same drifts: a metric that
    is a maximum over time sees every step. Here the energy repeats every 10 steps, so the
    kept states all sit at one phase of its swing: read from them, a 15 % swing read 1e-14."""
    data = _spring_pair(6.0)
    data["springs"][0]["stiffness"] = ALIASED_STIFFNESS
    whole = _recorded(data, sample_every=1)
    thinned = _recorded(data, sample_every=10)
    assert len(thinned[1].series.t) < len(whole[1].series.t) / 9, "the series must be thinned"
    for metric in ("energy_drift", "linear_momentum_drift", "angular_momentum_drift"):
        found = [METRICS[metric](Context(*run)) for run in (whole, thinned)]
        assert found[0].value == found[1].value, (found[0], found[1])
        assert found[0].message == found[1].message
    assert METRICS["energy_drift"](Context(*whole)).value > 0.1, "the swing the test needs"


# --- 4. an energy scale a Galilean boost does not change -------------------------------------

BOOST_INVARIANCE = 1e-6
"""Relative. The boosted run carries 100 m/s, so its energies are 1e4 J and carry 1e-12 J of
round-off, against an energy error of 0.65 J; the old scale (with the centre of mass's
kinetic energy) read 6,900 times less in the boosted run."""


def test_energy_drift_does_not_change_under_a_galilean_boost():
    at_rest = rows(_spring_pair(1.0), "mini")["energy_drift"]
    moving = rows(_spring_pair(1.0, velocity=100.0), "mini")["energy_drift"]
    assert at_rest["value"] > 1e-2, at_rest
    ratio = moving["value"] / at_rest["value"]
    assert abs(ratio - 1.0) <= BOOST_INVARIANCE, (at_rest, moving)


# --- 5. a momentum scale that is not round-off ------------------------------------------------


def _cancelling_pair() -> dict:
    """Two bodies whose momenta cancel but for decimal round-off: 1300 kg at 8.2 m/s against
    1000 kg at -10.66 m/s (p(0) = -1.8e-12 kg·m/s), on a spring, no gravity."""
    data = _spring_pair(1.0)
    data["bodies"][0].update(mass=1300.0, velocity=[0.0, 8.2, 0.0])
    data["bodies"][1].update(mass=1000.0, velocity=[0.0, -10.66, 0.0])
    return data


MOMENTUM_ROUND_OFF = 1e-12
"""Relative. The bodies carry 21,320 kg·m/s; 100 steps of 1e-16 relative round-off on each
leave about 1e-14 of it. Divided by |p(0)|, the same round-off read 0.1 to 1."""


def test_linear_momentum_drift_is_not_divided_by_a_momentum_that_is_round_off():
    data = _cancelling_pair()
    p0 = 1300.0 * 8.2 - 1000.0 * 10.66
    assert 0.0 < abs(p0) < 1e-11, p0  # the scene is what the test needs
    row = rows(data, "mini")["linear_momentum_drift"]
    assert row["value"] <= MOMENTUM_ROUND_OFF, row
    assert "without cancellation 21320" in row["message"], row["message"]
